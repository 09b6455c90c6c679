// How the page writes numbers, times and states: one place for every unit it shows.

/** @param {number | null | undefined} s a duration in seconds */
export function dur(s) {
  if (s === null || s === undefined) return "–";
  if (s >= 3600) return `${Math.floor(s / 3600)} h ${String(Math.floor(s % 3600 / 60)).padStart(2, "0")} min`;
  if (s >= 60) return `${Math.floor(s / 60)} min ${String(Math.floor(s % 60)).padStart(2, "0")} s`;
  return `${s.toFixed(0)} s`;
}

/** @param {number} t sim time in seconds, as hh:mm:ss.s */
export function clockText(t) {
  const h = Math.floor(t / 3600), m = Math.floor(t % 3600 / 60), s = t % 60;
  return `${String(h).padStart(2, "0")}:${String(m).padStart(2, "0")}:${s.toFixed(1).padStart(4, "0")}`;
}

/** @param {string[] | null | undefined} v */
const list = (v) => (v && v.length ? v.join(", ") : "none");

/** The formats a value's element may ask for (its `data-fmt`). */
export const FORMATS = /** @type {const} */ ({
  pct: (/** @type {number} */ v) => `${(v * 100).toFixed(1)} %`,
  kj: (/** @type {number} */ v) => `${(v / 1000).toFixed(1)} kJ`,
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
  text: (/** @type {unknown} */ v) => String(v).replace(/_/g, " "),
  limit: (/** @type {number | null} */ v) => (v === null ? "–" : v.toFixed(1)),
  num3: (/** @type {number} */ v) => v.toFixed(3),
  num2: (/** @type {number} */ v) => v.toFixed(2),
  faults: (/** @type {string[]} */ v) => (v && v.length ? v.join(", ") : ""),
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

/** @param {number} t seconds since the epoch, as the browser's local date and time */
export const wallTime = (t) => new Date(t * 1000).toLocaleString();
