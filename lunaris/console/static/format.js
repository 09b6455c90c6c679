// How the page writes numbers, times, states and the twin's words: one place for every unit
// it shows and every plain label it puts on the twin's field names (a fault's words are the
// catalogue's: GET /api/catalogue).

import {store} from "./state.js";
//
// One time base: simulated time, written hh:mm:ss everywhere (the top bar, events, faults,
// plots, snapshots). Durations as "2 h 05 min", "3 min 20 s", "45 s".

/** @param {number | null | undefined} s a duration in seconds */
export function dur(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  if (s >= 3600 - 30) {
    const min = Math.round(s / 60);
    return min % 60 ? `${Math.floor(min / 60)} h ${String(min % 60).padStart(2, "0")} min` : `${min / 60} h`;
  }
  if (s >= 60 - 0.5) {
    const sec = Math.round(s);
    return sec % 60 ? `${Math.floor(sec / 60)} min ${String(sec % 60).padStart(2, "0")} s` : `${sec / 60} min`;
  }
  return `${Math.round(s)} s`;
}

/** @param {number} t sim time in seconds, as hh:mm:ss (whole seconds) */
export function clockText(t) {
  const whole = Math.max(0, Math.floor(t + 1e-6));
  const h = Math.floor(whole / 3600), m = Math.floor(whole % 3600 / 60), s = whole % 60;
  return `${String(h).padStart(2, "0")}:${String(m).padStart(2, "0")}:${String(s).padStart(2, "0")}`;
}

/** @param {number} v @param {number} [digits] a number with a thousands separator */
export const num = (v, digits = 0) => v.toLocaleString("en-GB", {minimumFractionDigits: digits,
                                                                  maximumFractionDigits: digits});

/** @param {number} v a number as short as it can be said (0.05, 12, 1,000,000) */
export const plainNumber = (v) => (Number.isInteger(v) ? num(v) : String(Number(v.toPrecision(6))));

/** @param {string} s words with underscores (a state, a derived fault's name) as words */
export const words = (s) => String(s).replace(/_/g, " ");

/** @param {string[] | null | undefined} v */
const list = (v) => (v && v.length ? v.map(words).join(", ") : "none");

/** The formats a value's element may ask for (its `data-fmt`). */
export const FORMATS = /** @type {const} */ ({
  pct: (/** @type {number} */ v) => `${(v * 100).toFixed(1)} %`,
  kj: (/** @type {number} */ v) => `${num(v / 1000, 1)} kJ`,
  v: (/** @type {number} */ v) => `${v.toFixed(2)} V`,
  a: (/** @type {number} */ v) => `${v.toFixed(2)} A`,
  w: (/** @type {number} */ v) => `${v.toFixed(1)} W`,
  c: (/** @type {number} */ v) => `${v.toFixed(1)} °C`,
  dur,
  deg: (/** @type {number} */ v) => `${v.toFixed(0)}°`,
  m: (/** @type {number} */ v) => `${v.toFixed(1)} m`,
  mps: (/** @type {number} */ v) => `${v.toFixed(2)} m/s`,
  frac: (/** @type {number} */ v) => `${(v * 100).toFixed(0)} %`,
  s: (/** @type {number} */ v) => `${v.toFixed(1)} s`,
  clock: clockText,
  x: (/** @type {number} */ v) => `×${v}`,
  range: (/** @type {boolean} */ v) => (v ? "IN RANGE" : "OUT OF RANGE"),
  onoff: (/** @type {boolean} */ v) => (v ? "on" : "off"),
  ok: (/** @type {boolean} */ v) => (v ? "operational" : "NOT OPERATIONAL"),
  conn: (/** @type {boolean} */ v) => (v ? "connected" : "unplugged"),
  list,
  text: (/** @type {unknown} */ v) => words(String(v)),
  limit: (/** @type {number | null} */ v) => (v === null ? "–" : v.toFixed(1)),
  num3: (/** @type {number} */ v) => v.toFixed(3),
  num2: (/** @type {number} */ v) => v.toFixed(2),
  faults: (/** @type {string[]} */ v) => (v && v.length ? v.map(words).join(", ") : ""),
});

/** @typedef {keyof typeof FORMATS | ""} Format */

/**
 * A payload's field as the page writes it: "–" when there is none yet.
 * @param {unknown} value
 * @param {Format} how
 * @returns {string}
 */
export function fmt(value, how) {
  if (value === undefined) return "–";
  if (value === null) return how === "dur" ? "not draining" : "–";
  if (how === "") return String(value);
  const f = /** @type {(v: unknown) => string} */ (FORMATS[how]);
  return f(value);
}

/**
 * What "empty" means for a rover's battery, in numbers: "the charge reaches 0 % or the pack's
 * cut-off at 12.8 V" (from battery/state's depleted_soc and cutoff_v; "" before they are known).
 * @param {import("./types.js").BatteryState | undefined} b
 */
export function emptyWords(b) {
  if (!b || b.depleted_soc === undefined) return "";
  const soc = `the charge reaches ${num(b.depleted_soc * 100)} %`;
  return b.cutoff_v === null || b.cutoff_v === undefined ? soc : `${soc} or the pack's cut-off at ${num(b.cutoff_v, 1)} V`;
}

/** @param {number} t seconds since the epoch, as the browser's local date and time */
export const wallTime = (t) => new Date(t * 1000).toLocaleString();

/** @param {number} t seconds since the epoch, as a short local day and time: "25 Nov 20:56:32" */
export function dayTime(t) {
  const d = new Date(t * 1000);
  return `${d.toLocaleDateString("en-GB", {day: "numeric", month: "short"})} ${d.toLocaleTimeString("en-GB", {hour12: false})}`;
}

/** A session's id: the UTC time it began, YYYYMMDD-HHMMSS (SessionInfo.id). */
const SESSION_ID = /\b(\d{4})(\d{2})(\d{2})-(\d{2})(\d{2})(\d{2})\b/g;

/**
 * A trainee session by when it began, as a person says it ("25 Nov 20:56:32", local time),
 * rather than by its id (20261125-205632, UTC: what `lunaris report --session` takes).
 * @param {string} id
 */
export const sessionName = (id) => id.replace(SESSION_ID, (_, y, mo, d, h, mi, s) =>
  dayTime(Date.UTC(Number(y), Number(mo) - 1, Number(d), Number(h), Number(mi), Number(s)) / 1000));

// -- the twin's fields in plain words -------------------------------------------------------

/**
 * A payload field as a person says it: its label, its unit, and how a value of it is written
 * (`scale` multiplies the value first: a fraction shown in %).
 * @typedef {{label: string, unit?: string, scale?: number, digits?: number, prefix?: string}} FieldWords
 */

/** Fields by name, whatever payload they are in (the same name means the same thing). */
const FIELD_WORDS = /** @type {Record<string, FieldWords>} */ ({
  soc: {label: "charge", unit: "%", scale: 100, digits: 1},
  energy_j: {label: "stored energy", unit: "kJ", scale: 0.001, digits: 1},
  capacity_j: {label: "capacity", unit: "kJ", scale: 0.001, digits: 1},
  ocv_v: {label: "open-circuit voltage", unit: "V", digits: 2},
  voltage_v: {label: "voltage", unit: "V", digits: 2},
  current_a: {label: "current", unit: "A", digits: 2},
  current_limit_a: {label: "current limit", unit: "A", digits: 1},
  power_w: {label: "power", unit: "W", digits: 1},
  heat_w: {label: "extra heat", unit: "W"},
  temperature_c: {label: "temperature", unit: "°C", digits: 1},
  time_to_empty_s: {label: "time to empty", unit: "s", digits: 0},
  fault_code: {label: "fault code"},
  load_power_w: {label: "loads", unit: "W", digits: 1},
  bus_power_w: {label: "bus draw", unit: "W", digits: 1},
  generation_w: {label: "generation", unit: "W", digits: 1},
  net_battery_power_w: {label: "battery balance", unit: "W", digits: 1},
  bus_voltage_v: {label: "bus voltage", unit: "V", digits: 2},
  sun_angle_deg: {label: "sun angle", unit: "°", digits: 0},
  angle_deg: {label: "angle", unit: "°", digits: 0},
  distance_m: {label: "distance", unit: "m", digits: 0},
  dust: {label: "dust", unit: "%", scale: 100, digits: 0},
  in_range: {label: "in range"},
  x_m: {label: "x (east)", unit: "m", digits: 1},
  y_m: {label: "y (north)", unit: "m", digits: 1},
  z_m: {label: "z (up)", unit: "m", digits: 1},
  speed_m_per_s: {label: "speed", unit: "m/s", digits: 2},
  heading_deg: {label: "heading", unit: "°", digits: 0},
  grade_deg: {label: "slope", unit: "°", digits: 0},
  odometer_m: {label: "distance driven", unit: "m", digits: 0},
  remaining_m: {label: "distance to go", unit: "m", digits: 0},
  tractive_force_n: {label: "tractive force", unit: "N", digits: 0},
  wheel_torque_nm: {label: "wheel torque", unit: "N·m", digits: 0},
  t_s: {label: "sim time"},
  time_scale: {label: "speed of the clock", unit: "×"},
  resistance_ohm: {label: "resistance of the short", unit: "Ω"},
  range_scale: {label: "range kept", unit: "%", scale: 100, digits: 0},
  return_to_start: {label: "and back"},
  horizon_s: {label: "hours ahead"},
  speed: {label: "speed"},
  connected: {label: "plugged in"},
});

/**
 * A fault's value as the instructor types it, from the fault catalogue (`GET /api/catalogue`:
 * per parameter its `label`, `unit`, `hint`), and how it reads once injected (`shown`): the
 * label in lower case with its unit, a fraction as a percentage ("dust cover 25 %"), a factor
 * as "×3".
 * @typedef {{label: string, unit: string, hint: string, shown: FieldWords}} ParamWords
 */

/** @param {string} component @param {string} kind @returns {import("./state.js").CatalogueKind | undefined} */
const kindOf = (component, kind) => store.cat?.components[component.split("/")[0]]?.kinds[kind];

/** @param {string} text a sentence of the catalogue ("the panel gives no power") as it starts and ends on the page */
const sentence = (text) => (text ? `${text.charAt(0).toUpperCase()}${text.slice(1)}${/[.!?]$/.test(text) ? "" : "."}` : "");

/** @param {string} component `load/imu` or `load` @param {string} kind */
export function faultName(component, kind) {
  return kindOf(component, kind)?.name || words(kind);
}

/** @param {string} component @param {string} kind @param {string} fallback the model's own description */
export function faultEffect(component, kind, fallback) {
  return sentence(kindOf(component, kind)?.effect || fallback);
}

/**
 * @param {string} component @param {string} kind @param {string} field
 * @returns {ParamWords | undefined}
 */
export function paramWords(component, kind, field) {
  const q = kindOf(component, kind)?.params.find((x) => x.name === field);
  if (!q || !q.label) return undefined;
  const unit = q.unit ?? "", label = q.label.toLowerCase();
  /** @type {FieldWords} */
  const shown = unit === "fraction" ? {label, unit: "%", scale: 100}
    : unit === "×" ? {label: label.replace(/ times$/, ""), unit: "", prefix: "×"}
      : {label, unit: unit || undefined};
  return {label: q.label, unit, hint: q.hint ?? "", shown};
}

/** The parts of a rover, as the fault form and the faults' list name them. */
export const PART_WORDS = /** @type {Record<string, string>} */ ({
  battery: "Battery", load: "Load", rail: "Rail", solar: "Solar panel", umbilical: "Umbilical", radio: "Radio",
});

/** @param {string} component `battery`, `load/imu` @returns {string} "Battery", "Load imu" */
export function partName(component) {
  const [family, ...name] = component.split("/");
  return [PART_WORDS[family] ?? words(family), ...name].join(" ");
}

/**
 * A value with its unit, as a person writes it: "400 W", "25 %", "on".
 * @param {unknown} value
 * @param {FieldWords | undefined} w
 */
export function valueText(value, w) {
  if (typeof value === "boolean") return value ? "yes" : "no";
  if (typeof value !== "number") return words(String(value));
  const v = value * (w?.scale ?? 1);
  const shown = `${w?.prefix ?? ""}${w?.digits !== undefined ? num(v, w.digits) : plainNumber(v)}`;
  return w?.unit ? `${shown} ${w.unit}` : shown;
}

/** @param {string} name a field @returns {string} its label ("heat_w" -> "extra heat") */
export const fieldLabel = (name) => FIELD_WORDS[name]?.label ?? words(name).replace(/ (w|v|a|s|m|c|j|deg|ohm|n|nm)$/, "");

/**
 * A fault's values, as they read once injected: "extra heat 400 W, dust cover 25 %".
 * @param {string} component @param {string} kind @param {Record<string, unknown> | null | undefined} params
 */
export function paramsText(component, kind, params) {
  return Object.entries(params ?? {}).map(([k, v]) => {
    const w = paramWords(component, kind, k)?.shown ?? FIELD_WORDS[k];
    return `${w?.label ?? fieldLabel(k)} ${valueText(v, w)}`;
  }).join(", ");
}

/**
 * What is wrong with a name the instructor typed for a snapshot or a recording, in words (""
 * when nothing is): the twin takes letters, digits, "-", "_" and ".", one word.
 * @param {string} name
 * @param {string} what "snapshot", "recording"
 * @param {number} most its longest
 */
export function nameProblem(name, what, most) {
  const rule = `a ${what} name is one word of letters, digits, "-", "_" and ".", at most ${most} of them`;
  if (!name) return `type a name for the ${what} first (for example before-storm)`;
  if (/\s/.test(name)) return `"${name}" has a space: ${rule}, like "${name.replace(/\s+/g, "-")}"`;
  const bad = [...new Set(name.replace(/[A-Za-z0-9_.-]/g, ""))];
  if (bad.length) return `"${name}" holds ${bad.map((c) => `"${c}"`).join(", ")}: ${rule}`;
  if (name.length > most) return `"${name.slice(0, 20)}…" is ${name.length} characters long: ${rule}`;
  return "";
}

// -- the twin's messages, made plain ---------------------------------------------------------

const COMPARE = /** @type {Record<string, string>} */ ({
  "<=": "at most", ">=": "at least", "<": "below", ">": "above", "==": "is", "!=": "is not"});

/**
 * The field names of a message as labels, its JSON objects as labelled values, its `$.field`
 * paths, Python reprs and `name=value` pairs as words. The twin's own words are kept; what a
 * person would not read is said again plainly.
 * @param {string} message
 * @param {string} [key] the key the message is about (under lunaris/<rover>/ or whole), for a fault's values
 */
export function plainMessage(message, key = "") {
  const tail = key.replace(/^lunaris\/[^/]+\//, "");
  const fault = tail.startsWith("fault/") ? tail.slice(6).split("/") : null;
  const kind = fault ? fault.pop() ?? "" : "", component = fault ? fault.join("/") : "";
  /** @param {string} field */
  const label = (field) => (fault ? paramWords(component, kind, field)?.label.toLowerCase() : undefined)
    ?? fieldLabel(field);
  let out = sessionName(String(message));  // a session's id: when it began
  // "Expected `float` <= 1.0 - at `$.fraction`": what msgspec says, as words.
  out = out.replace(/Expected `\w+` (<=|>=|<|>) (\S+) - at `\$\.(\w+)`/g,
                    (_, op, v, f) => `${label(f)} must be ${COMPARE[op]} ${v}`);
  out = out.replace(/Expected `(\w+)`, got `(\w+)` - at `\$\.(\w+)`/g, (_, want, got, f) =>
    `${label(f)} must be ${{float: "a number", int: "a whole number", bool: "yes or no", str: "text"}[
      /** @type {"float"} */ (want)] ?? want}, not ${{str: "text", int: "a number", float: "a number", bool: "yes or no",
      null: "nothing"}[/** @type {"str"} */ (got)] ?? got}`);
  out = out.replace(/`?\$\.([\w.]+)`?/g, (_, f) => label(String(f).split(".").pop() ?? f));
  // JSON objects: {"heat_w": 400.0} -> "extra heat 400 W".
  out = out.replace(/\{[^{}]*\}/g, (text) => {
    try {
      const obj = JSON.parse(text);
      if (!obj || typeof obj !== "object" || Array.isArray(obj)) return text;
      const said = fault ? paramsText(component, kind, obj)
        : Object.entries(obj).map(([k, v]) => `${fieldLabel(k)} ${valueText(v, FIELD_WORDS[k])}`).join(", ");
      return said ? `(${said})` : "";
    } catch {
      return text;
    }
  });
  // b'5' -> "5"; name=value -> "label value".
  out = out.replace(/\bb'([^']*)'|\bb"([^"]*)"/g, (_, a, b) => `"${a ?? b}"`);
  out = out.replace(/\b([a-z][a-z0-9]*(?:_[a-z0-9]+)*)=(true|false|-?[\d.]+)\b/g, (all, f, v) => {
    if (f === "on") return v === "true" ? "switch on" : "switch off";
    if (f === "reset") return v === "true" ? "reset" : "";
    if (!FIELD_WORDS[f] && !(fault && paramWords(component, kind, f))) return all;
    return `${label(f)} ${v === "true" ? "yes" : v === "false" ? "no" : v}`;
  });
  // Any field name of the twin left: its label.
  out = out.replace(/\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b/g, (f) => (FIELD_WORDS[f] || (fault && paramWords(component, kind, f))
    ? label(f) : f));
  // "not sent: not sent: ..." said once.
  return out.replace(/^(not sent: )+/i, "").replace(/ {2,}/g, " ").replace(/ ;/g, ";").trim();
}

// -- scenario conditions in plain words ------------------------------------------------------

const SOURCE_WORDS = /** @type {Record<string, (name: string) => string>} */ ({
  battery: () => "the battery's", summary: () => "the rover's", clock: () => "the clock's",
  umbilical: () => "the umbilical's", drive: () => "the rover's", rail: (n) => `rail ${n}:`,
  load: (n) => `load ${n}:`, solar: (n) => `panel ${n}:`, radio: (n) => `radio ${n}:`,
});

/**
 * One comparison of a scenario's condition, in words.
 * @param {string} source @param {string} name @param {string} field @param {string} op @param {string} raw
 */
function comparisonText(source, name, field, op, raw) {
  const who = SOURCE_WORDS[source]?.(name) ?? `${source} ${name}`;
  const bool = raw === "true" || raw === "false";
  const yes = (raw === "true") === (op === "==");
  if (field === "in_range" && bool) return `radio ${name} is ${yes ? "in range" : "out of range"}`;
  if (field === "on" && bool) return `load ${name} is ${yes ? "on" : "off"}`;
  if (field === "connected" && bool) return `the umbilical is ${yes ? "plugged in" : "unplugged"}`;
  if (field === "paused" && bool) return `the clock is ${yes ? "paused" : "running"}`;
  if (field === "operational" && bool) return `the battery is ${yes ? "working" : "off"}`;
  if (field === "state" && source === "rail") return `rail ${name} is ${op === "!=" ? "not " : ""}${words(raw)}`;
  if (field === "status" && source === "drive") return `the rover is ${op === "!=" ? "not " : ""}${words(raw)}`;
  const w = FIELD_WORDS[field];
  const value = Number.isFinite(Number(raw)) ? valueText(Number(raw), w) : words(raw);
  return `${who} ${w?.label ?? fieldLabel(field)} ${COMPARE[op] ?? op} ${value}`;
}

/**
 * A scenario's condition (`rail.5V_CH2.state == off and battery.soc < 0.3`) in words; the text
 * as it is when it does not read as one.
 * @param {string} text
 */
export function conditionText(text) {
  const parts = text.split(/\s+and\s+/).map((part) => {
    const m = /^\s*([A-Za-z][\w.-]*)\s*(<=|>=|==|!=|<|>)\s*(\S+)\s*$/.exec(part);
    if (!m) return null;
    const [source, ...rest] = m[1].split(".");
    const field = rest.pop() ?? "", name = rest.join(".");
    return comparisonText(source, name, field, m[2], m[3]);
  });
  return parts.every((p) => p !== null) ? parts.join(" and ") : words(text);
}

/**
 * A step's trigger ("at 30 s, then when rail.5V_CH2.state == off (within 900 s)") in words.
 * @param {string} trigger
 */
export function triggerText(trigger) {
  return trigger.split(", then ").map((part) => {
    const when = /^when (.*?)(?: \(within ([\d.]+) s\))?$/.exec(part);
    if (when) return `when ${conditionText(when[1])}${when[2] ? ` (waits up to ${dur(Number(when[2]))})` : ""}`;
    const at = /^at ([\d.]+) s$/.exec(part);
    if (at) return `${dur(Number(at[1]))} into the drill`;
    const after = /^([\d.]+) s after the previous step$/.exec(part);
    if (after) return Number(after[1]) === 0 ? "right after the step before" : `${dur(Number(after[1]))} after the step before`;
    return part;
  }).join(", then ");
}
