// Map: the rover on the site (x east, y north, metres from the site's origin), drawn from the
// twin's own numbers and updated live: where the rover is and where it heads (`drive/state`),
// the route it follows, the part driven and the part to go (`drive/route`), each radio that
// stands at a site with its footprint, in range or not (`radio/<radio>/link`; the rover files
// the console was given, `GET /api/rovers`, when the telemetry does not say), the umbilical's
// plug and how far its cable reaches (`umbilical/state`), and the route the drive panel would
// send (a preview). A scale bar and a north arrow; the view fits the whole site (the radios'
// ranges included) or the rover and its route.
//
// For tests and tools: the <svg> carries `data-scale` (px per metre), `data-x0` / `data-y0`
// (where the site's origin is, in px of the drawing); the rover's marker `#map-rover` its
// `data-x-m`, `data-y-m`, `data-heading-deg`.

import {html, nothing, svg} from "../vendor/lit-html/lit-html.js";
import {num} from "../format.js";
import {changed, drive, radio, redraw, route, umbilical} from "../state.js";
import {field} from "../widgets.js";
import {loadRovers, radioInfo} from "../rovers.js";
import {addWaypoint, clicksAddWaypoints, drivePanel, loadTraverses, metres, pathOf, preview} from "./drive.js";

/** @typedef {import("../state.js").Parts} Parts */
/** @typedef {{x_m: number, y_m: number}} XY */
/** @typedef {{x_m: number, y_m: number, z_m?: number}} XYZ */

/** @typedef {import("../rovers.js").RoverInfo} RoverInfo */

/**
 * Where a radio stands and its footprint: the telemetry's own numbers, else the rover file's.
 * @param {string} rover @param {string} name
 * @returns {{site: XY, a: number, b: number, cx: number, cy: number, inRange: boolean | undefined} | null}
 */
function radioSite(rover, name) {
  const link = radio(rover, name), info = radioInfo(rover, name);
  const from = link?.site !== undefined ? link : info;
  const site = from?.site;
  if (!site || !from?.a_m || !from?.b_m) return null;
  return {site, a: from.a_m, b: from.b_m, cx: site.x_m + (from.offset_x_m ?? 0), cy: site.y_m + (from.offset_y_m ?? 0),
          inRange: link?.in_range};
}

// -- the drawing's frame ---------------------------------------------------------------------------

/** The drawing's size in px (the box it is drawn in, measured after each draw). */
const box = {w: 800, h: 520};
/** What the view fits: the whole site (every radio's range) or the rover and its route. */
let fit = /** @type {"site" | "rover"} */ ("site");
/** The smallest span shown [m] (a parked rover alone is not drawn at a millimetre's scale). */
const MIN_SPAN_M = 20;
const PAD_PX = 34;

/** @typedef {{minX: number, maxX: number, minY: number, maxY: number}} Bounds */
/** @typedef {{s: number, x0: number, y0: number}} Frame px = x0 + x s, py = y0 - y s */

/** @param {Bounds | null} b @param {number} x @param {number} y @param {number} [rx] @param {number} [ry] */
function grow(b, x, y, rx = 0, ry = rx) {
  if (!Number.isFinite(x) || !Number.isFinite(y)) return b;
  if (!b) return {minX: x - rx, maxX: x + rx, minY: y - ry, maxY: y + ry};
  return {minX: Math.min(b.minX, x - rx), maxX: Math.max(b.maxX, x + rx),
          minY: Math.min(b.minY, y - ry), maxY: Math.max(b.maxY, y + ry)};
}

/** @param {Bounds | null} b @returns {Frame} the scale and origin that fit `b` in the box */
function frame(b) {
  const bb = b ?? {minX: -MIN_SPAN_M, maxX: MIN_SPAN_M, minY: -MIN_SPAN_M, maxY: MIN_SPAN_M};
  const spanX = Math.max(bb.maxX - bb.minX, MIN_SPAN_M), spanY = Math.max(bb.maxY - bb.minY, MIN_SPAN_M);
  const s = Math.min((box.w - 2 * PAD_PX) / spanX, (box.h - 2 * PAD_PX) / spanY);
  const cx = (bb.minX + bb.maxX) / 2, cy = (bb.minY + bb.maxY) / 2;
  return {s, x0: box.w / 2 - cx * s, y0: box.h / 2 + cy * s};
}

/** @param {number} target a length [m] @returns {number} a round one near it: 1, 2 or 5 times a power of ten */
function roundLength(target) {
  const p = 10 ** Math.floor(Math.log10(target));
  return [1, 2, 5, 10].map((m) => m * p).reduce((a, b) => (Math.abs(Math.log(b / target)) < Math.abs(Math.log(a / target)) ? b : a));
}

// -- what is drawn --------------------------------------------------------------------------------

/**
 * Everything the map shows of a rover, in site coordinates.
 * @param {string} rover @param {Parts} p
 */
function scene(rover, p) {
  const d = drive(rover), r = route(rover), u = umbilical(rover), pv = preview(rover);
  const at = d ? {x_m: d.x_m, y_m: d.y_m, z_m: d.z_m} : null;
  /** @type {XYZ[]} */
  let driven = [];
  /** @type {XYZ[]} the part to go on the way out */
  let out = [];
  /** @type {XYZ[]} the part to go on the way back (through the same points) */
  let back = [];
  const path = r && r.waypoints.length ? pathOf(r.start ?? r.waypoints[0], r.waypoints, r.return_to_start) : [];
  if (path.length && at) {
    const status = d?.status ?? "", n = r?.waypoints.length ?? 0;
    const k = d?.waypoint;  // the leg being driven: it ends at path[k + 1]
    if (status === "arrived" || k === null || k === undefined) driven = path;
    else {
      driven = [...path.slice(0, k + 1), at];
      const toGo = [at, ...path.slice(k + 1)];
      const turn = Math.max(0, n - k);  // path[n] (the last waypoint) is toGo[n - k]
      out = k < n ? toGo.slice(0, turn + 1) : [];
      back = k < n ? toGo.slice(turn) : toGo;
      if (back.length < 2) back = [];
    }
  }
  const radios = p.radios.map((n) => ({name: n, at: radioSite(rover, n)}));
  const plug = u?.connected && u.plugged_at ? {at: u.plugged_at, cable: u.cable_m ?? null} : null;
  const previewPath = pv && at ? pathOf(at, pv.waypoints, pv.back) : [];
  return {d, at, route: r, path, driven, out, back, radios, plug, pv, previewPath};
}

/** @param {ReturnType<typeof scene>} sc @returns {Bounds | null} what the view must hold */
function bounds(sc) {
  let b = /** @type {Bounds | null} */ (null);
  if (sc.at) b = grow(b, sc.at.x_m, sc.at.y_m);
  for (const q of [...sc.path, ...sc.previewPath]) b = grow(b, q.x_m, q.y_m);
  if (sc.plug) b = grow(b, sc.plug.at.x_m, sc.plug.at.y_m, sc.plug.cable ?? 0);
  for (const {at} of sc.radios) {
    if (!at) continue;
    if (fit === "site" || !b) b = grow(b, at.site.x_m, at.site.y_m);
    if (fit === "site") b = grow(b, at.cx, at.cy, at.a, at.b);
  }
  if (fit === "rover" && b) {  // some room around the rover and its route
    const m = Math.max(b.maxX - b.minX, b.maxY - b.minY, MIN_SPAN_M) * 0.15;
    b = {minX: b.minX - m, maxX: b.maxX + m, minY: b.minY - m, maxY: b.maxY + m};
  }
  return b;
}

/** @param {Frame} f @param {XYZ[]} pts @returns {string} an SVG polyline's points */
const line = (f, pts) => pts.map((q) => `${(f.x0 + q.x_m * f.s).toFixed(1)},${(f.y0 - q.y_m * f.s).toFixed(1)}`).join(" ");

/** @param {Frame} f @param {number} step [m] a light grid at the scale bar's step, the origin's axes darker */
function grid(f, step) {
  const lines = [];
  const x1 = Math.ceil(-f.x0 / f.s / step) * step, x2 = (box.w - f.x0) / f.s;
  for (let x = x1; x <= x2 && lines.length < 80; x += step) {
    const px = f.x0 + x * f.s;
    lines.push(svg`<line class=${Math.abs(x) < step / 2 ? "axis" : "grid"} x1=${px} x2=${px} y1="0" y2=${box.h}></line>`);
  }
  const y1 = Math.ceil((f.y0 - box.h) / f.s / step) * step, y2 = f.y0 / f.s;
  for (let y = y1; y <= y2 && lines.length < 160; y += step) {
    const py = f.y0 - y * f.s;
    lines.push(svg`<line class=${Math.abs(y) < step / 2 ? "axis" : "grid"} y1=${py} y2=${py} x1="0" x2=${box.w}></line>`);
  }
  return lines;
}

/** @param {Frame} f @param {number} step [m] the scale bar, bottom left, and the north arrow, top right */
function furniture(f, step) {
  const len = step * f.s, x = 14, y = box.h - 16;
  return svg`<g class="scale" id="map-scale" data-metres=${step}>
      <rect class="halo" x=${x - 6} y=${y - 22} width=${len + 12} height="30" rx="4"></rect>
      <path d=${`M${x},${y - 6} v6 h${len} v-6`}></path>
      <text x=${x + len / 2} y=${y - 9} text-anchor="middle">${metres(step)}</text></g>
    <g class="north" id="map-north" transform=${`translate(${box.w - 26},${44})`}>
      <circle class="halo" r="20"></circle><path d="M0,-15 L7,7 L0,2 L-7,7 Z"></path>
      <text y="-19" text-anchor="middle" class="n">N</text></g>`;
}

/**
 * A text label beside a point, kept inside the drawing: to its right (`side` 1) or its left (-1),
 * swapped when it would leave the drawing.
 * @param {number} px @param {number} py @param {string} text @param {string} cls @param {1 | -1} [side]
 */
function label(px, py, text, cls, side = 1) {
  const room = 9 + 7 * text.length;
  const right = side === 1 ? px + room < box.w : px - room < 0;
  const x = Math.min(Math.max(px, 4), box.w - 4), y = Math.min(Math.max(py, 14), box.h - 6);
  return svg`<text class=${`label ${cls}`} x=${right ? x + 10 : x - 10} y=${y}
    text-anchor=${right ? "start" : "end"}>${text}</text>`;
}

/** @param {string} rover @param {Parts} p the map itself */
function drawing(rover, p) {
  const sc = scene(rover, p), f = frame(bounds(sc));
  const step = roundLength(110 / f.s);
  /** @param {XYZ} q */
  const px = (q) => f.x0 + q.x_m * f.s, py = (/** @type {XYZ} */ q) => f.y0 - q.y_m * f.s;
  const radios = sc.radios.filter((r) => r.at).map(({name, at}) => {
    const a = /** @type {NonNullable<typeof at>} */ (at), state = a.inRange === undefined ? "" : a.inRange ? "in" : "out";
    return {name, a, state, ellipse: svg`<ellipse class=${`range ${state}`} data-radio=${name} cx=${f.x0 + a.cx * f.s}
        cy=${f.y0 - a.cy * f.s} rx=${a.a * f.s} ry=${a.b * f.s}></ellipse>`,
      mark: svg`<g class=${`radio ${state}`} data-radio=${name} transform=${`translate(${px(a.site)},${py(a.site)})`}>
          <path d="M-7,8 L0,-9 L7,8 Z M0,-9 V-14"></path><circle cy="-15" r="2.5"></circle></g>
        ${label(px(a.site), py(a.site) + 16, `${name}: ${state === "in" ? "in range" : state === "out" ? "out of range" : "radio"}`,
                `radio ${state}`, -1)}`};
  });
  const plug = sc.plug ? svg`<g class="plug" id="map-plug">${sc.plug.cable !== null ? svg`<circle class="cable"
      cx=${px(sc.plug.at)} cy=${py(sc.plug.at)} r=${sc.plug.cable * f.s}></circle>` : nothing}
      <rect x=${px(sc.plug.at) - 5} y=${py(sc.plug.at) - 5} width="10" height="10"></rect></g>
      ${label(px(sc.plug.at), py(sc.plug.at) - (sc.plug.cable ?? 0) * f.s - 6, sc.plug.cable !== null
        ? `umbilical plug: cable ${metres(sc.plug.cable)}` : "umbilical plug", "plug", -1)}` : nothing;
  const r = sc.route;
  const waypoints = r ? r.waypoints.map((w, i) => svg`<g class="wp" data-waypoint=${i + 1}
      transform=${`translate(${px(w)},${py(w)})`}><circle r="9"></circle><text y="4" text-anchor="middle">${i + 1}</text></g>`) : [];
  const start = r?.start ? svg`<g class="start" transform=${`translate(${px(r.start)},${py(r.start)})`}><rect x="-5" y="-5"
      width="10" height="10"></rect></g>${label(px(r.start), py(r.start) + 16, "start", "start", 1)}` : nothing;
  const pv = sc.pv && sc.previewPath.length ? svg`<g class="preview" id="map-preview" data-waypoints=${sc.pv.waypoints.length}>
      <polyline points=${line(f, sc.previewPath)}></polyline>${sc.pv.waypoints.map((w, i) => svg`<g class="wp"
        data-waypoint=${i + 1} transform=${`translate(${px(w)},${py(w)})`}><circle r="9"></circle>
        <text y="4" text-anchor="middle">${i + 1}</text></g>`)}</g>` : nothing;
  const d = sc.d;
  const rov = d ? svg`<g id="map-rover" class=${`rover st-${d.status ?? "parked"}`} data-x-m=${d.x_m} data-y-m=${d.y_m}
      data-heading-deg=${d.heading_deg} transform=${`translate(${px(d)},${py(d)}) rotate(${d.heading_deg})`}>
      <circle class="halo" r="14"></circle><path d="M0,-13 L9,10 L0,5 L-9,10 Z"></path></g>
      ${label(px(d), py(d) - 12, rover, "rover", 1)}` : nothing;
  /** @param {MouseEvent} ev a click adds a waypoint there (waypoints by hand) */
  const click = (ev) => {
    if (!clicksAddWaypoints(rover)) return;
    const rect = /** @type {SVGSVGElement} */ (ev.currentTarget).getBoundingClientRect();
    const x = (ev.clientX - rect.left - f.x0) / f.s, y = (f.y0 - (ev.clientY - rect.top)) / f.s;
    const unit = 10 ** Math.floor(Math.log10(Math.max(2 / f.s, 0.01)));
    addWaypoint(rover, Math.round(x / unit) * unit, Math.round(y / unit) * unit);
  };
  return html`<svg id="map-svg" class=${clicksAddWaypoints(rover) ? "map adding" : "map"} role="img"
      aria-label=${`map of the site around ${rover}: x east, y north`} width=${box.w} height=${box.h}
      viewBox=${`0 0 ${box.w} ${box.h}`} data-scale=${f.s} data-x0=${f.x0} data-y0=${f.y0} @click=${click}>
    <rect class="ground" width=${box.w} height=${box.h}></rect>
    ${grid(f, step)}${radios.map((x) => x.ellipse)}${plug}
    ${sc.driven.length ? svg`<polyline class="route driven" id="map-driven" points=${line(f, sc.driven)}></polyline>` : nothing}
    ${sc.out.length ? svg`<polyline class="route to-go" id="map-to-go" points=${line(f, sc.out)}></polyline>` : nothing}
    ${sc.back.length ? svg`<polyline class="route to-go back" id="map-back" points=${line(f, sc.back)}></polyline>` : nothing}
    ${start}${waypoints}${pv}${radios.map((x) => x.mark)}${rov}${furniture(f, step)}</svg>`;
}

/**
 * The preview's key, and which of its waypoints lie outside a radio's range (nominal footprint:
 * `((x - cx) / a)^2 + ((y - cy) / b)^2 > 1`, as the twin decides it).
 * @param {string} rover @param {Parts} p
 */
function previewNote(rover, p) {
  const pv = preview(rover);
  if (!pv) return nothing;
  const outside = p.radios.map((n) => {
    const at = radioSite(rover, n);
    if (!at) return "";
    const out = pv.waypoints.map((w, i) => (((w.x_m - at.cx) / at.a) ** 2 + ((w.y_m - at.cy) / at.b) ** 2 > 1 ? i + 1 : 0))
      .filter((i) => i);
    return out.length ? `${out.length === 1 ? "waypoint" : "waypoints"} ${out.join(", ")} outside ${n}'s range` : "";
  }).filter((x) => x);
  return html`<span id="map-preview-note"><i class="k preview"></i>not sent yet${outside.length
    ? html`: <b class="sev-warning">${outside.join("; ")}</b>` : nothing}</span>`;
}

/** @param {string} rover @param {Parts} p the map's key, and the twin's numbers beside it */
function legend(rover, p) {
  const u = umbilical(rover);
  return html`<div class="map-legend" id="map-legend">
    ${p.drive ? html`<span><i class="k rover"></i>${rover}: ${field(rover, "drive/state", "x_m", "m")} east,
      ${field(rover, "drive/state", "y_m", "m")} north, heading ${field(rover, "drive/state", "heading_deg", "deg")}
      <small>(compass: 0° north, 90° east)</small></span>` : html`<span>${rover} does not drive: no position.</span>`}
    ${route(rover)?.waypoints.length ? html`<span><i class="k driven"></i>driven <i class="k to-go"></i>to go${route(rover)?.return_to_start
      ? html` <i class="k back"></i>and back` : nothing}</span>` : nothing}
    ${previewNote(rover, p)}
    ${p.radios.map((n) => radioSite(rover, n) ? html`<span><i class=${`k range ${radio(rover, n)?.in_range ? "in" : "out"}`}></i>${n}'s range:
      ${field(rover, `radio/${n}/link`, "in_range", "range")}</span>`
      : html`<span>${n}: ${field(rover, `radio/${n}/link`, "in_range", "range")} <small>(no site: not on the map)</small></span>`)}
    ${p.umbilical ? html`<span><i class="k plug"></i>umbilical ${u?.connected ? html`plugged in${u.plugged_at
      ? ` at ${num(u.plugged_at.x_m)} m east, ${num(u.plugged_at.y_m)} m north` : ""}${u.cable_m ? `, cable ${metres(u.cable_m)}` : ""}`
      : "unplugged"}</span>` : nothing}
  </div>`;
}

/** @param {"site" | "rover"} to */
const fitTo = (to) => () => {
  fit = to;
  redraw();
};

/** @param {string} rover @param {Parts} p */
function mapCard(rover, p) {
  /** @param {"site" | "rover"} to @param {string} text */
  const b = (to, text) => html`<button type="button" class=${fit === to ? "tab on" : "tab"} data-map-fit=${to}
    aria-pressed=${fit === to ? "true" : "false"} @click=${fitTo(to)}>${text}</button>`;
  return html`<section class="card map-card"><h2>Map <small>x east, y north, metres from the site's origin</small>
      <span class="tabs">${b("site", "Whole site")}${b("rover", "Rover and route")}</span></h2>
    <div class="map-box" id="map-box">${drawing(rover, p)}</div>${legend(rover, p)}</section>`;
}

/** Every few seconds, the traverse files' plans again (they start from where the rover is). */
let ticks = 0;

export const map = {
  name: "map",
  label: "Map & drive",
  /** @param {{rover: string, parts: Parts}} ctx */
  render: ({rover, parts}) => html`<div class="grid map-grid">
    <div class="col">${mapCard(rover, parts)}</div>
    <div class="col">${drivePanel(rover, parts.drive)}</div></div>`,
  /** @param {{rover: string}} ctx */
  enter: ({rover}) => {
    ticks = 0;
    return Promise.all([loadRovers(), loadTraverses(rover)]);
  },
  /** The drawing takes the size of its box (a resize, a tablet turned). */
  after: () => {
    const el = document.getElementById("map-box");
    if (!el) return;
    const w = Math.floor(el.clientWidth), h = Math.floor(el.clientHeight);
    if (w > 0 && h > 0 && (Math.abs(w - box.w) > 1 || Math.abs(h - box.h) > 1)) {
      box.w = w;
      box.h = h;
      changed();
    }
  },
  /** @param {{rover: string, parts: Parts}} ctx */
  tick: ({rover, parts}) => {
    if (parts.drive && ++ticks % 5 === 0) loadTraverses(rover);
  },
};
