// The live stream (`GET /api/live`, server-sent events): a snapshot of everything, then
// batches of what changed. Folded into the state here; the views only read the state.
//
// Trainee sessions never mix (SPEC 12c): when a rover's session changes the console sends a
// snapshot without the previous session's events and history, and the page keeps nothing of
// them either: an event of another session is never kept, and a plot's point from before the
// new session's beginning (a value published just before it, heard just after) is dropped.

import {toSignIn} from "./api.js";
import {EVENTS_KEPT, HISTORY_KEPT, battery, changed, clock, powerSummary, rovers, store} from "./state.js";

/** @typedef {import("./state.js").BatteryState} BatteryState */

/** @typedef {import("./state.js").TwinEvent} TwinEvent */
/** @typedef {import("./state.js").History} History */
/** @typedef {import("./state.js").RoverLink} RoverLink */
/** @typedef {import("./state.js").Session} Session */

/**
 * A message of the stream (lunaris/console/live.py): a `snapshot` of everything, `batch`es of
 * what changed (`links`: the rovers whose link changed; `sessions`: each rover's trainee
 * session, in a batch those whose trainee became known), `link` when the router comes or goes.
 * @typedef {{type: "snapshot" | "batch" | "link", v?: number, connected?: boolean,
 *   router?: import("./state.js").Router, values?: Record<string, unknown>, events?: TwinEvent[],
 *   services?: Record<string, string[]>, history?: Record<string, History>,
 *   links?: Record<string, RoverLink>, sessions?: Record<string, Session>}} LiveMessage
 */

/** How long the page waits to open the stream again once the browser gave up on it [ms]. */
const RETRY_MS = 2000;

/**
 * Open the stream; the browser reconnects by itself after a lost connection (and the console
 * sends a snapshot again). An answer that is no stream (401: signed out elsewhere; a console
 * restarting) ends the browser's tries: a page signed out goes to the sign-in page, any other
 * opens the stream again after a while.
 */
export function connect() {
  const es = new EventSource("/api/live");
  es.onmessage = (m) => receive(JSON.parse(m.data));
  es.onerror = () => {
    store.streamError = "reconnecting to the console…";
    changed();
    if (es.readyState !== EventSource.CLOSED) return;
    fetch("/api/me").then((res) => (res.status === 401 ? toSignIn() : undefined), () => undefined);
    setTimeout(connect, RETRY_MS);
  };
}

/** @param {LiveMessage} msg one message of the stream, folded into the state */
export function receive(msg) {
  store.streamError = "";
  if (msg.router) store.router = msg.router;
  if (msg.type === "link") {
    store.connected = !!msg.connected;
    changed();
    return;
  }
  const before = store.sessions;
  if (msg.type === "snapshot") {
    store.values = msg.values ?? {};
    store.services = msg.services ?? {};
    store.events = {};
    store.history = simHistory(msg.history ?? {});
    store.links = {};
    store.sessions = {};
    store.connected = !!msg.connected;
  } else {
    Object.assign(store.values, msg.values ?? {});
    Object.assign(store.services, msg.services ?? {});
  }
  store.sessions = {...store.sessions, ...sessionsOf(msg)};
  for (const [rover, s] of Object.entries(store.sessions)) {
    if (before[rover] && before[rover].id !== s.id) begin(rover, s.id, msg.events ?? []);
  }
  links(msg);
  for (const k of Object.keys(msg.values ?? {})) {
    const m = /^lunaris\/([^/]+)\/battery\/state$/.exec(k);
    if (m) point(m[1]);
  }
  for (const e of msg.events ?? []) {
    const rover = e.key.split("/")[1];
    if (!ofSession(e, rover)) continue;
    const t0 = startOf(e, store.sessions[rover]?.id ?? "");
    if (t0 !== null && store.sessionStart[rover] !== undefined) {  // the tick came first: now exact
      store.sessionStart[rover] = Math.min(store.sessionStart[rover], t0);
    }
    const kept = (store.events[rover] ||= []);
    kept.push(e);
    if (kept.length > EVENTS_KEPT) kept.shift();
  }
  const all = rovers();
  if (store.wanted && all.includes(store.wanted)) [store.rover, store.wanted] = [store.wanted, null];
  if (!store.rover || !all.includes(store.rover)) store.rover = all[0] ?? null;
  changed();
}

/** @param {LiveMessage} msg the rovers' links that it carries */
function links(msg) {
  for (const [rover, link] of Object.entries(msg.links ?? {})) {
    if (link && typeof link === "object" && typeof link.state === "string") store.links[rover] = link;
  }
}

/** @param {LiveMessage} msg @returns {Record<string, Session>} the well-formed sessions it says */
function sessionsOf(msg) {
  /** @type {Record<string, Session>} */
  const out = {};
  for (const [rover, s] of Object.entries(msg.sessions ?? {})) {
    if (s && typeof s === "object" && typeof s.id === "string" && s.id) {
      out[rover] = {id: s.id, trainee: typeof s.trainee === "string" ? s.trainee : null};
    }
  }
  return out;
}

/**
 * Is the event of the rover's running session? (One of no session, from a service older than
 * sessions, is kept; so is every event while the session is not known yet.)
 * @param {TwinEvent} e @param {string} rover
 */
const ofSession = (e, rover) => !e.session || !store.sessions[rover] || e.session === store.sessions[rover].id;

/**
 * The sim time session `id` began at, if `e` is the clock's event that opened it.
 * @param {TwinEvent} e @param {string} id @returns {number | null}
 */
function startOf(e, id) {
  const p = e.params;
  return e.kind === "session" && e.source === "clock" && p?.session === id && typeof p.start_t_s === "number"
    ? p.start_t_s : null;
}

/**
 * The page saw the rover's session change to `id`: nothing of the previous one stays (its
 * events; the plots' points from before the new session's beginning: `start_t_s` of the
 * clock's event that opened it, the snapshot's time for a session begun from one; or, as the
 * clock's first tick of a session goes out before that event, the sim time of that tick).
 * @param {string} rover @param {string} id @param {TwinEvent[]} events what came with the change
 */
function begin(rover, id, events) {
  store.events[rover] = (store.events[rover] ?? []).filter((e) => e.session === id);
  const opened = events.map((e) => startOf(e, id)).find((t) => t !== null);
  const c = clock(rover), h = store.history[rover];
  const t0 = opened ?? (c?.session === id ? c.t_s : null);
  if (t0 === null || t0 === undefined) {
    delete store.sessionStart[rover];
    if (h) store.history[rover] = since(h, -Infinity);
    return;
  }
  store.sessionStart[rover] = t0;
  if (h) {
    store.history[rover] = since(h, t0);
    if (store.history[rover].t.length) delete store.sessionStart[rover];
  }
}

/**
 * The points of a history in the running session: from `t0` on, and after the last time the
 * sim time went back (a reset).
 * @param {History} h @param {number} t0 @returns {History}
 */
function since(h, t0) {
  let from = 0;
  h.t.forEach((t, i) => {
    if (t < t0 || (i > 0 && t < h.t[i - 1])) from = t < t0 ? i + 1 : i;
  });
  /** @template T @param {T[]} col @returns {T[]} */
  const cut = (col) => col.slice(from);
  return {t: cut(h.t), soc: cut(h.soc), temperature_c: cut(h.temperature_c), load_w: cut(h.load_w),
          generation_w: cut(h.generation_w)};
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
  const t0 = store.sessionStart[rover];
  if (t0 !== undefined) {  // a new session seen begin: its first point is at its beginning or later
    if (b.t_s < t0) return;
    delete store.sessionStart[rover];
  }
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
