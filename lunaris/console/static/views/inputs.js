// Inputs: the sun angle (all panels, or one panel's own), each radio's position (a radio that
// follows the drive takes none: the rover is moved on the map instead), the umbilical; Stop,
// and the way to the map, where the rover is driven.

import {html} from "../vendor/lit-html/lit-html.js";
import {send} from "../api.js";
import {panel, pickView, radio} from "../state.js";
import {actionButton, field} from "../widgets.js";
import {loadRovers, radioInfo} from "../rovers.js";

/** @typedef {import("../state.js").Parts} Parts */

/** @param {string} id @returns {number | null} the number typed in the input `id`, or null */
function num(id) {
  const el = /** @type {HTMLInputElement | null} */ (document.getElementById(id));
  return !el || el.value === "" ? null : Number(el.value);
}

/** @param {string} r @param {Parts} p */
function sunCard(r, p) {
  const now = p.panels.length ? panel(r, p.panels[0])?.sun_angle_deg : undefined;
  return html`<section class="card"><h2>Sun angle</h2>
    <p class="help">Angle between the sun and the way the panels face: 0° is full sun, 90° is edge-on (no power).</p>
    <div class="row"><label>All panels [°]<input type="number" id="sun-all" min="-360" max="360" step="1" value=${now ?? 60}></label>
      ${actionButton({action: "input-sun", label: "Set for all panels", rover: r, cls: "primary",
                      run: () => send("PUT", "input/sun_angle", JSON.stringify({angle_deg: num("sun-all")}), r)})}</div>
    ${p.panels.map((n) => html`<div class="row"><label>Panel ${n} [°]<input type="number" id=${`sun-${n}`} min="-360"
        max="360" step="1"></label>
      ${actionButton({action: "input-panel-sun", label: "Set", rover: r, target: {panel: n},
                      run: () => send("PUT", `input/solar/${n}/sun_angle`, JSON.stringify({angle_deg: num(`sun-${n}`)}), r)})}
      ${actionButton({action: "input-panel-sun-clear", label: "Back to the rover's angle", rover: r, target: {panel: n},
                      run: () => send("DELETE", `input/solar/${n}/sun_angle`, undefined, r)})}
      <span>now ${field(r, `solar/${n}/power`, "sun_angle_deg", "deg")}</span></div>`)}</section>`;
}

/** @param {string} r */
function umbilicalCard(r) {
  /** @param {boolean} connected */
  const plug = (connected) => () => send("PUT", "input/umbilical", JSON.stringify({connected}), r);
  return html`<section class="card"><h2>Umbilical</h2><p>Now: ${field(r, "umbilical/state", "connected", "conn")},
      supplying ${field(r, "umbilical/state", "power_w", "w")}</p>
    <div class="row">${actionButton({action: "input-umbilical", label: "Plug in", rover: r, target: {value: "true"},
                                     cls: "primary", run: plug(true)})}
      ${actionButton({action: "input-umbilical", label: "Unplug", rover: r, target: {value: "false"}, run: plug(false)})}</div>
  </section>`;
}

/**
 * Whether a radio follows the drive (the drive sets where the rover is from it, and the twin
 * refuses a position typed for it): its telemetry's `follows_drive`, else what the console
 * knows from the rover file (`GET /api/rovers`); null when neither says.
 * @param {string} r @param {string} n
 * @returns {boolean | null}
 */
function followsDrive(r, n) {
  const said = radio(r, n)?.follows_drive;
  if (typeof said === "boolean") return said;
  const info = radioInfo(r, n);
  return info ? info.follows_drive : null;
}

/** @param {string} r @param {Parts} p */
function radiosCard(r, p) {
  return html`<section class="card"><h2>Where the rover is from each radio</h2>
    <p class="help">A distance, and an angle measured from east, counter-clockwise: 0° east, 90° north, 180° west,
      270° south. (Not a compass bearing: the drive's heading is one, 0° north and clockwise.)</p>
    ${p.radios.length ? p.radios.map((n) => {
      const link = radio(r, n), x = link?.x_m ?? 0, y = link?.y_m ?? 0;
      const angle = Math.round((Math.atan2(y, x) * 180 / Math.PI + 360) % 360), distance = Math.round(Math.hypot(x, y));
      if (followsDrive(r, n)) {
        return html`<div class="radio-follows" data-radio=${n} data-follows-drive="true"><b>${n}</b> ${field(r, `radio/${n}/link`,
            "in_range", "range")}: now ${distance} m at ${angle}° from east.
          <p class="help">The drive sets where the rover is: move the rover on the map's drive panel instead.
            <button type="button" class="act" data-to-map=${n} @click=${() => pickView("map")}>Open the map</button></p></div>`;
      }
      return html`<div class="row" data-radio=${n}><b>${n}</b><label>distance [m]<input type="number" id=${`pos-d-${n}`} min="0" step="10"
          value=${distance}></label>
        <label>angle from east [°]<input type="number" id=${`pos-a-${n}`} min="-360" max="360" step="1"
          value=${angle}></label>
        ${actionButton({action: "input-position", label: "Set", rover: r, target: {radio: n},
                        run: () => send("PUT", `input/radio/${n}/position`,
                                        JSON.stringify({distance_m: num(`pos-d-${n}`), angle_deg: num(`pos-a-${n}`)}), r)})}
        ${field(r, `radio/${n}/link`, "in_range", "range")}</div>`;
    }) : html`<p>No radio.</p>`}</section>`;
}

/** @param {string} r @param {Parts} p where to drive the rover from */
function driveCard(r, p) {
  if (!p.drive) return html`<section class="card"><h2>Drive</h2><p>${r} has no drive section: it does not drive.</p></section>`;
  return html`<section class="card"><h2>Drive</h2><p class="help">The rover is driven from the map: a shipped traverse,
      waypoints typed or clicked on the map, Stop; each shown on the map before it is sent.</p>
    <div class="row"><button type="button" class="primary" id="to-map" @click=${() => pickView("map")}>Open the map</button>
      ${actionButton({action: "traverse-stop", label: "Stop the rover", rover: r, cls: "danger",
                      run: () => send("DELETE", "input/drive/traverse", undefined, r)})}</div></section>`;
}

export const inputs = {
  name: "inputs",
  label: "Inputs",
  /** @param {{rover: string, parts: Parts}} ctx */
  render: ({rover, parts}) => html`<div class="grid two">
    <div class="col">${sunCard(rover, parts)}${umbilicalCard(rover)}</div>
    <div class="col">${radiosCard(rover, parts)}${driveCard(rover, parts)}</div></div>`,
  enter: () => loadRovers(),
};
