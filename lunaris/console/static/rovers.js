// What the console knows of every rover from the rover files it was given (`GET /api/rovers`):
// each radio's site and footprint, each switchable rail and its loads. Several views read it
// (the map, the PDM, the inputs): it is none of theirs.

import {query} from "./api.js";
import {changed} from "./state.js";

/** @typedef {{x_m: number, y_m: number}} XY */

/**
 * A radio as `GET /api/rovers` gives it (from the rover file).
 * @typedef {{name: string, follows_drive: boolean | null, why: string, site?: XY | null, a_m?: number,
 *   b_m?: number, offset_x_m?: number, offset_y_m?: number}} RadioInfo
 * A switchable rail as `GET /api/rovers` gives it (from the rover file).
 * @typedef {{name: string, essential: boolean, loads: string[]}} RailInfo
 * @typedef {{id: string, live: boolean, drives: boolean | null, drives_why: string, radios: RadioInfo[],
 *   rails: RailInfo[]}} RoverInfo
 */

/** `GET /api/rovers`, as last asked. */
let described = /** @type {Record<string, RoverInfo>} */ ({});

/** @returns {Promise<void>} what the console knows of every rover's radios and rails (rover files) */
export async function loadRovers() {
  const res = await query("/api/rovers");
  if (res.ok) {
    described = Object.fromEntries(/** @type {{rovers: RoverInfo[]}} */ (res.data).rovers.map((r) => [r.id, r]));
    changed();
  }
}

/** @param {string} rover @param {string} name @returns {RadioInfo | undefined} */
export const radioInfo = (rover, name) => described[rover]?.radios.find((r) => r.name === name);

/** @param {string} rover @param {string} name @returns {RailInfo | undefined} */
export const railInfo = (rover, name) => described[rover]?.rails?.find((r) => r.name === name);

