// The page's state: the latest value of every key of every rover, their recent events, the
// live services, the plots' history, and what the instructor has chosen (rover, view). One
// object, changed only through this module and the modules that own a part of it; every
// change asks for one redraw (at most one an animation frame).

/** @typedef {import("./types.js").ActiveFault} ActiveFault */
/** @typedef {import("./types.js").ActiveFaults} ActiveFaults */
/** @typedef {import("./types.js").BatteryState} BatteryState */
/** @typedef {import("./types.js").Clock} Clock */
/** @typedef {import("./types.js").DriveRoute} DriveRoute */
/** @typedef {import("./types.js").DriveState} DriveState */
/** @typedef {import("./types.js").Event} TwinEvent */
/** @typedef {import("./types.js").LoadPower} LoadPower */
/** @typedef {import("./types.js").PowerSummary} PowerSummary */
/** @typedef {import("./types.js").RadioLink} RadioLink */
/** @typedef {import("./types.js").RailState} RailState */
/** @typedef {import("./types.js").SolarPower} SolarPower */
/** @typedef {import("./types.js").UmbilicalState} UmbilicalState */

/**
 * The plots' history of one rover, by simulated time (`t`: the battery state's `t_s`): a point
 * every sim second at most, the older points thinned as the history grows.
 * @typedef {{t: number[], soc: number[], temperature_c: number[], load_w: (number | null)[],
 *   generation_w: (number | null)[]}} History
 */

/** @typedef {{name: string, role: string, local: boolean, may_act: boolean, accounts: boolean}} Me */

/**
 * The fault catalogue the forms are built from (`GET /api/catalogue`).
 * @typedef {{name: string, type: string, ge?: number, gt?: number, le?: number, lt?: number,
 *   default: number | null, label?: string, unit?: string, hint?: string}} CatalogueParam
 * @typedef {{name?: string, effect?: string, description: string, params: CatalogueParam[]}} CatalogueKind
 * @typedef {{named: boolean, kinds: Record<string, CatalogueKind>}} CatalogueComponent
 * @typedef {{components: Record<string, CatalogueComponent>, derived: Record<string, unknown>}} Catalogue
 */

/**
 * A rover's link to the console, as the console says it: `up`, `lost` (no clock tick for 2 s,
 * or its clock's liveliness gone) or `unknown` (no tick seen yet); since when (wall time) and why.
 * @typedef {{state: "up" | "lost" | "unknown", since: number | null, reason: string}} RoverLink
 */

/**
 * Where the console is with the twin's router: `waiting` (not reached yet: the page is up
 * before the twin), `connected` or `lost`; `message` in words.
 * @typedef {{state: "waiting" | "connected" | "lost", endpoint: string, message: string}} Router
 */

/**
 * A rover's running trainee session, as the console says it (SPEC 12c): its `id` (as the
 * sessions list gives it) and its `trainee` ("" when none was named, null until known).
 * @typedef {{id: string, trainee: string | null}} Session
 */

export const EVENTS_KEPT = 300;
/** Points of a rover's plots kept; past it, the older half is thinned to every other point. */
export const HISTORY_KEPT = 2400;
/** The spans of sim time the plots may show, in seconds, and their words. */
export const SPANS = /** @type {const} */ ([[900, "15 min"], [3600, "1 h"], [8 * 3600, "8 h"]]);

export const store = {
  /** @type {Record<string, unknown>} the latest payload of every key, by its full key */
  values: {},
  /** @type {Record<string, TwinEvent[]>} recent events by rover, oldest first */
  events: {},
  /** @type {Record<string, string[]>} live services by rover */
  services: {},
  /** @type {Record<string, History>} */
  history: {},
  /** @type {Record<string, Session>} each rover's running trainee session */
  sessions: {},
  /** @type {Record<string, number>} the sim time each rover's session began, when the page saw it begin */
  sessionStart: {},
  /** @type {Record<string, RoverLink>} each rover's link, where the console says it */
  links: {},
  /** @type {boolean | null} whether the console reaches the twin (null: not known yet) */
  connected: /** @type {boolean | null} */ (null),
  /** @type {Router | null} where the console is with the twin's router, in words */
  router: /** @type {Router | null} */ (null),
  /** @type {string} what to say when the page has lost the console itself */
  streamError: "",
  /** @type {string | null} */
  rover: /** @type {string | null} */ (null),
  /** @type {string | null} the rover the page's address names, shown once the stream brings it */
  wanted: /** @type {string | null} */ (null),
  view: "live",
  /** @type {Me | null} */
  me: /** @type {Me | null} */ (null),
  /** @type {Catalogue | null} */
  cat: /** @type {Catalogue | null} */ (null),
  /** @type {Set<string>} the actions sent and not answered yet (their buttons wait) */
  pending: new Set(),
  /** the span of sim time the plots show, in seconds (one of SPANS) */
  span: 900,
  /** the instructor stands in for the crew: the rail buttons count as the crew's actions */
  asCrew: false,
};

/** @type {Set<() => void>} */
const listeners = new Set();
let asked = false;

/** Ask for a redraw: the listeners run once, at the next animation frame. */
export function changed() {
  if (asked) return;
  asked = true;
  requestAnimationFrame(() => {
    asked = false;
    for (const fn of listeners) fn();
  });
}

/** Redraw now: after the instructor's own choices (a view, a rover, a select), so what
 * depends on the choice is there as soon as the choice is made. */
export function redraw() {
  for (const fn of listeners) fn();
}

/** @param {() => void} fn called after every change (once a frame at most) */
export function onChange(fn) {
  listeners.add(fn);
}

/** May the signed-in user change the twin? (An observer may not; the server refuses anyway.) */
export const mayAct = () => !!store.me?.may_act;

// -- reading the values ---------------------------------------------------------------------

/** @param {string} rover @param {string} tail the key under lunaris/<rover>/ */
export const key = (rover, tail) => `lunaris/${rover}/${tail}`;

/**
 * The latest payload of a key of the rover (typed by the key: see types.js's Payload).
 * @template {string} K
 * @param {string} rover
 * @param {K} tail the key under lunaris/<rover>/
 * @returns {import("./types.js").Payload<K> | undefined}
 */
export const val = (rover, tail) => /** @type {import("./types.js").Payload<K> | undefined} */ (store.values[key(rover, tail)]);

/** @param {string} rover @returns {BatteryState | undefined} */
export const battery = (rover) => val(rover, "battery/state");
/** @param {string} rover @returns {Clock | undefined} */
export const clock = (rover) => val(rover, "clock");
/** @param {string} rover @returns {PowerSummary | undefined} */
export const powerSummary = (rover) => val(rover, "power/summary");
/** @param {string} rover @param {string} name @returns {RailState | undefined} */
export const rail = (rover, name) => val(rover, `rail/${name}/state`);
/** @param {string} rover @param {string} name @returns {LoadPower | undefined} */
export const load = (rover, name) => val(rover, `load/${name}/power`);
/** @param {string} rover @param {string} name @returns {SolarPower | undefined} */
export const panel = (rover, name) => val(rover, `solar/${name}/power`);
/** @param {string} rover @param {string} name @returns {RadioLink | undefined} */
export const radio = (rover, name) => val(rover, `radio/${name}/link`);
/** @param {string} rover @returns {DriveState | undefined} */
export const drive = (rover) => val(rover, "drive/state");
/** @param {string} rover @returns {DriveRoute | undefined} */
export const route = (rover) => val(rover, "drive/route");
/** @param {string} rover @returns {UmbilicalState | undefined} */
export const umbilical = (rover) => val(rover, "umbilical/state");

// -- what a rover has, from its keys ----------------------------------------------------------

/** Every rover the console has heard of (a live service or a value), sorted. */
export function rovers() {
  const set = new Set(Object.keys(store.services));
  for (const k of Object.keys(store.values)) set.add(k.split("/")[1]);
  return [...set].sort();
}

/**
 * The names of a family's components: `named(r, "load", "power")` -> the loads.
 * @param {string} rover @param {string} head @param {string} tail
 */
export function named(rover, head, tail) {
  const pre = `lunaris/${rover}/${head}/`, out = [];
  for (const k of Object.keys(store.values)) {
    if (k.startsWith(pre) && k.endsWith(`/${tail}`)) {
      const n = k.slice(pre.length, -tail.length - 1);
      if (n && !n.includes("/")) out.push(n);
    }
  }
  return out.sort();
}

/** @typedef {{rails: string[], loads: string[], panels: string[], radios: string[], drive: boolean, umbilical: boolean}} Parts */

/** @param {string} rover @returns {Parts} what the rover has */
export function parts(rover) {
  return {rails: named(rover, "rail", "state"), loads: named(rover, "load", "power"),
          panels: named(rover, "solar", "power"), radios: named(rover, "radio", "link"),
          drive: !!drive(rover), umbilical: !!umbilical(rover)};
}

/**
 * Every fault in effect, oldest first, each with the service that owns it (its
 * `faults/active/<service>` key).
 * @param {string} rover
 * @returns {(ActiveFault & {service: string})[]}
 */
export function activeFaults(rover) {
  const pre = `lunaris/${rover}/faults/active/`, out = [];
  for (const [k, v] of Object.entries(store.values)) {
    if (!k.startsWith(pre)) continue;
    const service = k.slice(pre.length);
    out.push(.../** @type {ActiveFaults} */ (v).faults.map((f) => ({...f, service})));
  }
  return out.sort((a, b) => a.since_t_s - b.since_t_s || a.key.localeCompare(b.key));
}

/** @param {string} rover @returns {Session | undefined} its running trainee session */
export const runningSession = (rover) => store.sessions[rover];

/** A crew's dashboard silent this long, after it was receiving, is an alarm (SPEC 13d), s. */
export const DASHBOARD_SILENT_S = 3;
/** The bridge's delivery record arrives about once a second: none for this long, it stopped, s. */
const DELIVERY_STALE_S = 3;
/** Each rover's last delivery record's wall_s and when the page saw it arrive (ms, its own clock). */
const deliverySeen = /** @type {Record<string, {wall_s: number, at_ms: number}>} */ ({});

/**
 * Whether the crew's dashboard hears the bridge (SPEC 13d), from `bridge/delivery`:
 * `receiving` (some flavour has a reader), `silent` (it had one and has none, or the record
 * stopped coming: the bridge is gone or stuck), `none` (no dashboard seen yet) or `unknown` (no
 * record: no bridge). `since` is the wall time it went silent (the bridge's clock); `for_s`
 * how long, measured on the bridge's clock and then on the page's (no skew between the two).
 * @param {string} rover
 * @returns {{state: "receiving" | "silent" | "none" | "unknown", since: number | null, for_s: number, why: string}}
 */
export function dashboardHearing(rover) {
  const rec = val(rover, "bridge/delivery");
  if (!rec) return {state: "unknown", since: null, for_s: 0, why: ""};
  const now = Date.now();
  let seen = deliverySeen[rover];
  if (!seen || seen.wall_s !== rec.wall_s) seen = deliverySeen[rover] = {wall_s: rec.wall_s, at_ms: now};
  const aged_s = (now - seen.at_ms) / 1000;
  if (aged_s > DELIVERY_STALE_S && (rec.receiving || rec.ever_received)) {
    const since = rec.receiving ? rec.wall_s : rec.silent_since_wall_s ?? rec.wall_s;
    return {state: "silent", since, for_s: rec.wall_s - since + aged_s,
            why: "the bridge's delivery report stopped coming (the bridge is gone or stuck)"};
  }
  if (rec.receiving) return {state: "receiving", since: null, for_s: 0, why: ""};
  if (!rec.ever_received) return {state: "none", since: null, for_s: 0, why: ""};
  const since = rec.silent_since_wall_s ?? rec.wall_s;
  return {state: "silent", since, for_s: rec.wall_s - since + aged_s, why: "no reader of its topics in any flavour"};
}

/**
 * Whether to alarm the instructor: a dashboard that was receiving has heard nothing for
 * DASHBOARD_SILENT_S during a trainee session.
 * @param {string} rover
 */
export function dashboardAlarm(rover) {
  const h = dashboardHearing(rover);
  return h.state === "silent" && h.for_s >= DASHBOARD_SILENT_S && !!store.sessions[rover]?.id;
}

/** @param {string} rover @returns {boolean} the console says the rover's link is lost */
export const linkLost = (rover) => store.links[rover]?.state === "lost";

// -- choices --------------------------------------------------------------------------------

/** @param {string} rover */
export function pickRover(rover) {
  store.rover = rover;
  store.wanted = null;
  remember();
  redraw();
}

/** @param {string} view */
export function pickView(view) {
  store.view = view;
  remember();
  redraw();
}

/**
 * The view and the rover in the page's address (`#crew/mapp-1`): a reload, a link or the way
 * back from the sign-in page opens them again (a reload always went back to Live). Each choice
 * is a step of the browser's history: Back shows the view before (it left the console).
 */
function remember() {
  const rover = store.rover ? `/${encodeURIComponent(store.rover)}` : "";
  const address = `#${encodeURIComponent(store.view)}${rover}`;
  if (location.hash !== address) history.pushState(null, "", address);
}

/** The address changed under the page (Back, Forward, a link, typed): show what it asks. */
export function followAddress() {
  fromAddress();
  if (store.wanted && rovers().includes(store.wanted)) [store.rover, store.wanted] = [store.wanted, null];
  redraw();
}

/** What the address asks for, read at the start: the view (an unknown one shows the first). */
export function fromAddress() {
  try {
    const [view, rover] = location.hash.slice(1).split("/").map(decodeURIComponent);
    if (view) store.view = view;
    if (rover) store.wanted = rover;
  } catch {
    // an address no page of ours made: the first view
  }
}
