// The live stream (`GET /api/live`, server-sent events): a snapshot of everything, then
// batches of what changed. Folded into the state here; the views only read the state.

import {EVENTS_KEPT, HISTORY_KEPT, battery, changed, powerSummary, rovers, store} from "./state.js";

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
    store.history = {...(msg.history ?? {})};
    store.links = {};
    store.connected = !!msg.connected;
  } else {
    Object.assign(store.values, msg.values ?? {});
    Object.assign(store.services, msg.services ?? {});
  }
  links(msg);
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

/** A point a second of every rover's plots (drawn when its plots are shown). */
export function sample() {
  const now = Date.now() / 1000;
  for (const r of rovers()) {
    const b = battery(r), p = powerSummary(r);
    if (!b) continue;
    const h = (store.history[r] ||= {t: [], soc: [], temperature_c: [], load_w: [], generation_w: []});
    h.t.push(now);
    h.soc.push(b.soc * 100);
    h.temperature_c.push(b.temperature_c);
    h.load_w.push(p ? p.load_power_w : null);
    h.generation_w.push(p ? p.generation_w : null);
    if (h.t.length > HISTORY_KEPT) for (const k of /** @type {(keyof History)[]} */ (Object.keys(h))) h[k].shift();
  }
}
