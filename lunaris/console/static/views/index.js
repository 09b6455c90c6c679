// Every view of the page, in the order of its tabs. A view is a module exporting
// {name, label, render(ctx)} and optionally enter(ctx) (when it is opened or the rover
// changes), after(ctx) (after each drawing) and tick(ctx) (every second while shown).

import {crew} from "./crew.js";
import {faults} from "./faults.js";
import {inputs} from "./inputs.js";
import {live} from "./live.js";
import {map} from "./map.js";
import {recordings} from "./recordings.js";
import {scenarios} from "./scenarios.js";
import {session} from "./session.js";

/** @typedef {{rover: string, parts: import("../state.js").Parts}} ViewContext */

/**
 * @typedef {{name: string, label: string, render: (ctx: ViewContext) => unknown,
 *   enter?: (ctx: ViewContext) => unknown, after?: (ctx: ViewContext) => unknown,
 *   tick?: (ctx: ViewContext) => unknown}} View
 */

/** @type {View[]} */
export const VIEWS = [live, map, faults, crew, inputs, session, scenarios, recordings];
