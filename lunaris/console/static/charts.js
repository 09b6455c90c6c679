// The live view's plots (uPlot) of the last minutes or hours of simulated time: made when the
// live view shows a rover with enough history, given new data every second, made again when
// the rover, the container, its width or the span changes.
//
// Readable axes: time in sim time (hh:mm:ss) at round steps (1 s ... 1 h) with room for each
// label; each quantity with a smallest span (a change of 0.01 % does not fill the height), and
// labels with as many decimals as their step needs (never "100 100 100").

import uPlot from "./vendor/uplot/uPlot.esm.js";
import {clockText} from "./format.js";
import {store} from "./state.js";

/** @type {{box: HTMLElement | null, rover: string | null, width: number, span: number, plots: uPlot[],
 *   history: import("./state.js").History | undefined}} */
const drawn = {box: null, rover: null, width: 0, span: 0, plots: [], history: undefined};

/** What each axis shows now: its ticks' values and labels, by plot and axis (for tests and tools). */
/** @type {Map<uPlot, Map<number, {splits: number[], labels: (string | null)[]}>>} */
const shown = new Map();

const FONT = "12px system-ui, sans-serif";
const INK = "#5f6b7a", GRID = "#eef0f3";
/** Round steps of sim time for the time axis, in seconds. */
const TIME_STEPS = [1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400];
/** Round steps for the values: 1, 2, 5 times a power of ten. */
const VALUE_STEPS = [-3, -2, -1, 0, 1, 2, 3, 4, 5].flatMap((e) => [1, 2, 5].map((m) => m * 10 ** e));

function destroy() {
  for (const p of drawn.plots) {
    shown.delete(p);
    p.destroy();
  }
  drawn.plots = [];
}

/**
 * A legend line: coloured marks and labels (classes, not inline styles).
 * @param {[string, string][]} items [class, label]
 */
function legend(items) {
  const h = document.createElement("h3");
  items.forEach(([cls, label], i) => {
    if (i) h.append(" · ");
    const s = document.createElement("span");
    s.className = cls;
    s.textContent = `━ ${label}`;
    h.append(s);
  });
  return h;
}

/**
 * An axis' labels, kept for axisTicks().
 * @param {(v: number, step: number) => string} write
 * @returns {uPlot.Axis.DynamicValues}
 */
const labels = (write) => (u, splits, axisIdx, _space, step) => {
  const out = splits.map((v) => (v === null || v === undefined ? null : write(v, step)));
  let axes = shown.get(u);
  if (!axes) shown.set(u, axes = new Map());
  axes.set(axisIdx, {splits: [...splits], labels: out});
  return /** @type {string[]} */ (out);
};

/** @param {number} step @returns {number} the decimals a value needs at this step */
const decimals = (step) => Math.max(0, Math.min(3, -Math.floor(Math.log10(step) + 1e-9)));

/**
 * Room for each time label: 84 px where the plot is wide, down to the 64 px an hh:mm:ss label
 * and its gap need, so that a narrow plot still shows several (at 84 px, 384 px of 570 s
 * showed only 00:05:00).
 * @type {uPlot.Axis.Space}
 */
const timeSpace = (_u, _axis, _min, _max, dim) => Math.max(64, Math.min(84, dim / 5));

/** @type {uPlot.Axis} */
const timeAxis = {stroke: INK, grid: {stroke: GRID}, size: 26, font: FONT, space: timeSpace, incrs: TIME_STEPS,
                  values: labels((v) => clockText(v))};

/** @param {string} label @param {string} scale @param {number} side */
const valueAxis = (label, scale, side) => ({label, scale, side, size: 52, labelSize: 16, font: FONT, labelFont: FONT,
  space: 22, incrs: VALUE_STEPS, stroke: INK, grid: {stroke: side === 3 ? GRID : "transparent"},
  values: labels((v, step) => v.toFixed(decimals(step)))});

/**
 * A scale's range: the data's, padded, and at least `span` wide (or `share` of the largest
 * value, if wider), centred on the data, kept inside [floor, ceiling] where a quantity has bounds.
 * @param {number} span @param {{floor?: number, ceiling?: number, share?: number}} [opts]
 * @returns {uPlot.Range.Function}
 */
const atLeast = (span, {floor = -Infinity, ceiling = Infinity, share = 0} = {}) => (_u, lo, hi) => {
  if (lo === null || hi === null || !Number.isFinite(lo) || !Number.isFinite(hi)) return [0, span];
  const pad = (hi - lo) * 0.08;
  let a = lo - pad, b = hi + pad;
  const wide = Math.max(span, Math.max(Math.abs(lo), Math.abs(hi)) * share);
  if (b - a < wide) {
    const mid = (lo + hi) / 2;
    a = mid - wide / 2;
    b = mid + wide / 2;
  }
  if (a < floor) [a, b] = [floor, Math.min(ceiling, floor + Math.max(b - a, wide))];
  if (b > ceiling) [a, b] = [Math.max(floor, ceiling - Math.max(b - a, wide)), ceiling];
  return [a, b];
};

/** @param {string} label @param {string} stroke @param {string} scale @param {number} width */
const line = (label, stroke, scale, width) => ({label, stroke, width, scale, points: {show: false}});

/** @param {import("./state.js").History} h @param {number} span the points of the last `span` s */
function recent(h, span) {
  const end = h.t[h.t.length - 1];
  let i = h.t.length - 1;
  while (i > 0 && h.t[i - 1] >= end - span) i--;
  /** @template T @param {T[]} col @returns {T[]} */
  const cut = (col) => col.slice(i);
  return {t: cut(h.t), soc: cut(h.soc), temperature_c: cut(h.temperature_c), load_w: cut(h.load_w),
          generation_w: cut(h.generation_w)};
}

/**
 * Keep the plots in `box` (the live view's container, or null when it is not shown) for `rover`.
 * @param {HTMLElement | null} box
 * @param {string} rover
 */
export function syncCharts(box, rover) {
  if (!box) {
    destroy();
    drawn.box = null;
    return;
  }
  const h = store.history[rover];
  const width = Math.max(240, box.clientWidth - 2);
  // made again for a new history too (a new session, a reset): nothing of the last one is drawn
  if (box === drawn.box && rover === drawn.rover && drawn.span === store.span && h === drawn.history
      && (drawn.plots.length || (h?.t.length ?? 0) < 2) && Math.abs(width - drawn.width) < 8) return;
  destroy();
  Object.assign(drawn, {box, rover, width, span: store.span, history: h});
  box.replaceChildren();
  if (!h || h.t.length < 2) {
    const p = document.createElement("p");
    p.className = "help";
    p.textContent = "The plots start after a few seconds of simulated time.";
    box.append(p);
    return;
  }
  const w = recent(h, store.span);
  const x = {time: false};
  box.append(legend([["soc", "charge %"], ["temperature", "battery temperature °C"]]));
  const soc = new uPlot({width, height: 120, legend: {show: false}, cursor: {show: false},
    scales: {x, "%": {range: atLeast(2, {floor: 0, ceiling: 100})}, C: {range: atLeast(2)}},
    series: [{}, line("charge %", "#1b7f3b", "%", 2), line("temperature °C", "#8e3fb0", "C", 1.5)],
    axes: [timeAxis, valueAxis("%", "%", 3), valueAxis("°C", "C", 1)]},
  [w.t, w.soc, w.temperature_c], box);
  box.append(legend([["loads", "loads W"], ["generation", "generation W"]]));
  const power = new uPlot({width, height: 120, legend: {show: false}, cursor: {show: false},
    scales: {x, W: {range: atLeast(5, {share: 0.1})}},
    series: [{}, line("loads W", "#c0262d", "W", 1.5), line("generation W", "#e0a800", "W", 1.5)],
    axes: [timeAxis, valueAxis("W", "W", 3)]},
  [w.t, w.load_w, w.generation_w], box);
  drawn.plots = [soc, power];
}

/** New points (every second): drawn into the plots shown. */
export function updateCharts() {
  const h = drawn.rover ? store.history[drawn.rover] : undefined;
  if (!h || drawn.plots.length !== 2 || h !== drawn.history) return;
  const w = recent(h, drawn.span);
  drawn.plots[0].setData([w.t, w.soc, w.temperature_c]);
  drawn.plots[1].setData([w.t, w.load_w, w.generation_w]);
}

/**
 * What the plots' axes show now: each axis' labels, their positions across the axis (CSS px)
 * and their widths, and the span of sim time the plots cover (for tests and tools).
 * @returns {{plot: number, axis: number, labels: string[], px: number[], widths: number[], span_s: number}[]}
 */
export function axisTicks() {
  const ctx = document.createElement("canvas").getContext("2d");
  if (ctx) ctx.font = FONT;
  const out = [];
  for (const [plot, u] of drawn.plots.entries()) {
    for (const [axis, seen] of shown.get(u) ?? []) {
      const scale = u.axes[axis].scale ?? (axis === 0 ? "x" : "y");
      const px = seen.splits.map((v) => u.valToPos(v, scale));
      const text = seen.labels.map((l) => l ?? "");
      out.push({plot, axis, labels: text, px, widths: text.map((l) => ctx?.measureText(l).width ?? 0),
                span_s: drawn.span});
    }
  }
  return out;
}

/**
 * The sim times the plots shown draw, by plot (for tests and tools): what the instructor sees
 * plotted, not only what the page keeps.
 * @returns {number[][]}
 */
export const plotted = () => drawn.plots.map((u) => [...(u.data[0] ?? [])]);
