// The live stream (`GET /api/live`, server-sent events): a snapshot of everything, then
// batches of what changed. Folded into the state here; the views only read the state.

import {EVENTS_KEPT, HISTORY_KEPT, battery, changed, powerSummary, rovers, store} from "./state.js";

/** @typedef {import("./state.js").BatteryState} BatteryState */

/** @typedef {import("./state.js").TwinEvent} TwinEvent */
/** @typedef {import("./state.js").History} History */
/** @typedef {import("./state.js").RoverLink} RoverLink */

/**
 * A message of the stream. `rovers` / `links` (a rover's link to the console: "ok" or
 * "lost") are read where the console sends them.
 * @typedef {{type: "snapshot" | "batch" | "link", v?: number, connected?: boolean,
 *   values?: Record<string, unknown>, events?: TwinEvent[], services?: Record<string, string[]>,
 *   history?: Record<string, History>, rover?: string, link?: RoverLink | boolean,
 *   rovers?: Record<string, {link?: RoverLink}>, links?: Record<string, RoverLink | {link?: RoverLink}>}} LiveMessage
 */

/** Open the stream; the browser reconnects by itself (and the console sends a snapshot again). */
export function connect() {
  const es = new EventSource("/api/live");
  es.onmessage = (m) => receive(JSON.parse(m.data));
  es.onerror = () => {
    store.streamError = "reconnecting to the console…";
    changed();
  };
}

/** @param {LiveMessage} msg one message of the stream, folded into the state */
export function receive(msg) {
  store.streamError = "";
  if (msg.type === "link" && msg.rover === undefined) {
    store.connected = !!msg.connected;
    changed();
    return;
  }
  if (msg.type === "snapshot") {
    store.values = msg.values ?? {};
    store.services = msg.services ?? {};
    store.events = {};
    store.history = simHistory(msg.history ?? {});
    store.links = {};
    store.connected = !!msg.connected;
  } else {
    Object.assign(store.values, msg.values ?? {});
    Object.assign(store.services, msg.services ?? {});
  }
  links(msg);
  for (const k of Object.keys(msg.values ?? {})) {
    const m = /^lunaris\/([^/]+)\/battery\/state$/.exec(k);
    if (m) point(m[1]);
  }
  for (const e of msg.events ?? []) {
    const rover = e.key.split("/")[1];
    const kept = (store.events[rover] ||= []);
    kept.push(e);
    if (kept.length > EVENTS_KEPT) kept.shift();
  }
  const all = rovers();
  if (!store.rover || !all.includes(store.rover)) store.rover = all[0] ?? null;
  changed();
}

/** @param {unknown} v @returns {RoverLink | undefined} */
const linkWord = (v) => (v === "lost" || v === false ? "lost" : v === "ok" || v === true ? "ok" : undefined);

/** @param {LiveMessage} msg the rovers' links, in whichever of its fields it carries them */
function links(msg) {
  /** @param {string} rover @param {unknown} v */
  const set = (rover, v) => {
    const word = linkWord(v);
    if (word) store.links[rover] = word;
  };
  if (msg.rover !== undefined) set(msg.rover, msg.link);
  for (const [rover, data] of Object.entries(msg.rovers ?? {})) set(rover, data?.link);
  for (const [rover, data] of Object.entries(msg.links ?? {})) set(rover, typeof data === "object" ? data?.link : data);
}

/**
 * The console's history kept where it is in sim time (a `t_s` list beside its points); a
 * history in wall-clock time only (`t`) is left out: the plots are in sim time, and they fill
 * from the live values in a few seconds.
 * @param {Record<string, History & {t_s?: number[]}>} sent
 * @returns {Record<string, History>}
 */
function simHistory(sent) {
  /** @type {Record<string, History>} */
  const out = {};
  for (const [rover, h] of Object.entries(sent)) {
    if (Array.isArray(h.t_s) && h.t_s.length === h.soc?.length) out[rover] = {...h, t: h.t_s};
  }
  return out;
}

/** The smallest step of sim time between two points of the plots, in seconds. */
const STEP_S = 1;

/** @param {string} rover a point of its plots, at its battery state's sim time */
function point(rover) {
  const b = /** @type {BatteryState | undefined} */ (battery(rover)), p = powerSummary(rover);
  if (!b) return;
  let h = store.history[rover];
  const last = h?.t.length ? h.t[h.t.length - 1] : null;
  if (!h || (last !== null && b.t_s < last)) {  // a reset or a restore: a new time line
    h = store.history[rover] = {t: [], soc: [], temperature_c: [], load_w: [], generation_w: []};
  } else if (last !== null && b.t_s < last + STEP_S) {
    return;
  }
  h.t.push(b.t_s);
  h.soc.push(b.soc * 100);
  h.temperature_c.push(b.temperature_c);
  h.load_w.push(p ? p.load_power_w : null);
  h.generation_w.push(p ? p.generation_w : null);
  if (h.t.length > HISTORY_KEPT) {
    const half = Math.floor(h.t.length / 2);
    for (const k of /** @type {(keyof History)[]} */ (Object.keys(h))) {
      const col = /** @type {unknown[]} */ (h[k]);
      h[k] = /** @type {any} */ ([...col.slice(0, half).filter((_, i) => i % 2 === 0), ...col.slice(half)]);
    }
  }
}
