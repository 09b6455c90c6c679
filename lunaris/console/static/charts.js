// The live view's plots of the last minutes (uPlot): made when the live view shows a rover
// with enough history, given new data every second, made again when the rover, the
// container or its width changes.

import uPlot from "./vendor/uplot/uPlot.esm.js";
import {store} from "./state.js";

/** @type {{box: HTMLElement | null, rover: string | null, width: number, plots: uPlot[]}} */
const drawn = {box: null, rover: null, width: 0, plots: []};

function destroy() {
  for (const p of drawn.plots) p.destroy();
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

/** @param {string} label @param {number} side */
const axis = (label, side) => ({label, side, size: 46, labelSize: 14, space: 18, stroke: "#5f6b7a",
                                grid: {stroke: "#eef0f3"}});
const clockAxis = {stroke: "#5f6b7a", grid: {stroke: "#eef0f3"}, size: 24,
  /** @param {uPlot} u @param {number[]} vals */
  values: (u, vals) => vals.map((v) => new Date(v * 1000).toLocaleTimeString([], {hour: "2-digit", minute: "2-digit",
                                                                                second: "2-digit"}))};
/** @type {uPlot.Range.Function} */
const pad = (u, lo, hi) => (lo === null || hi === null ? [0, 1] : lo === hi ? [lo - 1, hi + 1]
  : [lo - (hi - lo) * 0.05, hi + (hi - lo) * 0.05]);
/** @param {string} label @param {string} stroke @param {string} scale @param {number} width */
const line = (label, stroke, scale, width) => ({label, stroke, width, scale, points: {show: false}});

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
  const width = Math.max(280, box.clientWidth - 4);
  if (box === drawn.box && rover === drawn.rover && (drawn.plots.length || (h?.t.length ?? 0) < 2)
      && Math.abs(width - drawn.width) < 8) return;
  destroy();
  Object.assign(drawn, {box, rover, width});
  box.replaceChildren();
  if (!h || h.t.length < 2) {
    const p = document.createElement("p");
    p.className = "help";
    p.textContent = "The plots start after a few seconds.";
    box.append(p);
    return;
  }
  box.append(legend([["soc", "state of charge %"], ["temperature", "battery temperature °C"]]));
  const soc = new uPlot({width, height: 100, legend: {show: false},
    scales: {x: {time: true}, "%": {range: pad}, C: {range: pad}},
    series: [{}, line("state of charge %", "#1b7f3b", "%", 2), line("temperature °C", "#8e3fb0", "C", 1.5)],
    axes: [clockAxis, {...axis("%", 3), scale: "%"}, {...axis("°C", 1), scale: "C"}]},
  [h.t, h.soc, h.temperature_c], box);
  box.append(legend([["loads", "loads W"], ["generation", "generation W"]]));
  const power = new uPlot({width, height: 100, legend: {show: false}, scales: {x: {time: true}, W: {range: pad}},
    series: [{}, line("loads W", "#c0262d", "W", 1.5), line("generation W", "#e0a800", "W", 1.5)],
    axes: [clockAxis, {...axis("W", 3), scale: "W"}]},
  [h.t, h.load_w, h.generation_w], box);
  drawn.plots = [soc, power];
}

/** New points (every second): drawn into the plots shown. */
export function updateCharts() {
  const h = drawn.rover ? store.history[drawn.rover] : undefined;
  if (!h || drawn.plots.length !== 2) return;
  drawn.plots[0].setData([h.t, h.soc, h.temperature_c]);
  drawn.plots[1].setData([h.t, h.load_w, h.generation_w]);
}
