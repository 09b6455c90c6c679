// Live: the battery, power, solar panels, umbilical, radio links, drive, the PDM table (each
// rail's On / Off / Reset), plots of the last minutes, whether the crew's dashboard is
// receiving (SPEC 13d), the active faults and the event log.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {send} from "../api.js";
import {SPANS, battery, load, mayAct, powerSummary, rail, redraw, store} from "../state.js";
import {emptyWords} from "../format.js";
import {actionButton, checkFaults, clearFault, dashboardCard, eventsCard, faultsCard, field} from "../widgets.js";
import {loadRovers, railInfo} from "../rovers.js";

/** @typedef {import("../state.js").Parts} Parts */

/** Below this, a current or a power is as good as none. */
const IDLE_A = 0.005, IDLE_W = 0.05;

/** @param {string} r */
function batteryCard(r) {
  const t = "battery/state", b = battery(r);
  const flow = !b ? "" : b.current_a > IDLE_A ? "discharging" : b.current_a < -IDLE_A ? "charging" : "idle";
  return html`<section class="card"><h2>Battery</h2>
    <div class="big">${field(r, t, "soc", "pct")} <small>charge</small></div>
    <dl class="kv">
      <dt>stored energy</dt><dd>${field(r, t, "energy_j", "kj")} of ${field(r, t, "capacity_j", "kj")}</dd>
      <dt>voltage</dt><dd>${field(r, t, "voltage_v", "v")} <small>(at rest ${field(r, t, "ocv_v", "v")})</small></dd>
      <dt>current</dt><dd>${field(r, t, "current_a", "a")} · ${field(r, t, "power_w", "w")} <small>${flow}</small></dd>
      <dt>temperature</dt><dd>${field(r, t, "temperature_c", "c")}</dd>
      <dt>time to empty</dt><dd>${field(r, t, "time_to_empty_s", "dur")} <small id="empty-words">${b?.time_to_empty_s === null ? ""
        : emptyWords(b) ? `at this draw, until ${emptyWords(b)}` : "at this draw, until the battery cuts off"}</small></dd>
      <dt>status</dt><dd>${field(r, t, "operational", "ok")}</dd>
      <dt>alarms</dt><dd>${field(r, t, "faults", "list")} <small>(code ${field(r, t, "fault_code", "")})</small></dd>
    </dl></section>`;
}

/** @param {string} r what the battery balance's sign means now */
function balanceWords(r) {
  const s = powerSummary(r), b = battery(r);
  if (!s) return "";
  if (s.net_battery_power_w > IDLE_W) return "drawn from the battery";
  if (s.net_battery_power_w < -IDLE_W) {
    if (!b || b.current_a < -IDLE_A) return "surplus, charging the battery";
    if (!b.operational) return "surplus: the battery is off and takes none";
    return b.soc >= 0.999 ? "surplus: the battery is full and takes none" : "surplus offered to the battery";
  }
  return "balanced";
}

/** @param {string} r @param {Parts} p */
function powerCard(r, p) {
  const t = "power/summary";
  const panels = p.panels.map((n) => html`<tr><td>${n}</td><td class="num">${field(r, `solar/${n}/power`, "power_w", "w")}</td>
    <td class="num">${field(r, `solar/${n}/power`, "sun_angle_deg", "deg")}</td>
    <td class="num">${field(r, `solar/${n}/power`, "dust", "frac")}</td></tr>`);
  return html`<section class="card"><h2>Power</h2><dl class="kv">
      <dt>loads</dt><dd>${field(r, t, "load_power_w", "w")}</dd>
      <dt>bus draw</dt><dd>${field(r, t, "bus_power_w", "w")} <small>loads and converter losses</small></dd>
      <dt>generation</dt><dd>${field(r, t, "generation_w", "w")} <small>the panels after their converter${
        p.umbilical ? ", and the umbilical" : ""}</small></dd>
      <dt>battery balance</dt><dd>${field(r, t, "net_battery_power_w", "w")} <small>${balanceWords(r)}</small></dd>
      <dt>bus voltage</dt><dd>${field(r, t, "bus_voltage_v", "v")}</dd>
      ${p.umbilical ? html`<dt>umbilical</dt><dd>${field(r, "umbilical/state", "connected", "conn")} ·
        ${field(r, "umbilical/state", "power_w", "w")}</dd>` : nothing}
    </dl>${p.panels.length ? html`<table><tr><th>panel</th><th class="num">power</th><th class="num">sun angle</th>
      <th class="num">dust</th></tr>${panels}</table>` : nothing}</section>`;
}

/** @param {string} r @param {Parts} p */
function radioCard(r, p) {
  if (!p.radios.length) return nothing;
  return html`<section class="card"><h2>Radio links</h2><table><tr><th>radio</th><th>link</th>
    <th class="num">rover east of it</th><th class="num">north of it</th></tr>${p.radios.map((n) => {
    const t = `radio/${n}/link`;
    return html`<tr><td>${n}</td><td>${field(r, t, "in_range", "range")}</td><td class="num">${field(r, t, "x_m", "m")}</td>
      <td class="num">${field(r, t, "y_m", "m")}</td></tr>`;
  })}</table></section>`;
}

/** @param {string} r @param {Parts} p */
function driveCard(r, p) {
  if (!p.drive) return nothing;
  const t = "drive/state";
  return html`<section class="card"><h2>Drive</h2><dl class="kv">
    <dt>status</dt><dd>${field(r, t, "status", "text")}</dd>
    <dt>position</dt><dd>${field(r, t, "x_m", "m")} east · ${field(r, t, "y_m", "m")} north ·
      ${field(r, t, "z_m", "m")} up <small>of the site's origin</small></dd>
    <dt>speed</dt><dd>${field(r, t, "speed_m_per_s", "mps")}</dd>
    <dt>heading</dt><dd>${field(r, t, "heading_deg", "deg")} <small>compass: 0° north, 90° east</small></dd>
    <dt>slope</dt><dd>${field(r, t, "grade_deg", "deg")} <small>uphill above 0</small></dd>
    <dt>power</dt><dd>${field(r, t, "power_w", "w")}</dd>
    <dt>to go</dt><dd>${field(r, t, "remaining_m", "m")} <small>driven ${field(r, t, "odometer_m", "m")}</small></dd></dl></section>`;
}

/** @param {string} r @param {string} n the rail's On / Off / Reset */
function railSwitch(r, n) {
  /** @param {string} action @param {string} label @param {Record<string, boolean>} body */
  const b = (action, label, body) => actionButton({action, label, rover: r, target: {rail: n},
                                                   run: () => mayCut(r, n, body) && send("PUT", `cmd/rail/${n}`, JSON.stringify(body), r, store.asCrew)});
  return html`${b("rail-on", "On", {on: true})} ${b("rail-off", "Off", {on: false})} ${b("rail-reset", "Reset", {reset: true})}`;
}

/**
 * Off on an essential rail (never shed: the flight computer's, the radio's) is asked first;
 * known from the rover file the console was given (`GET /api/rovers`), else not asked.
 * @param {string} r @param {string} n @param {Record<string, boolean>} body
 */
function mayCut(r, n, body) {
  const info = railInfo(r, n);
  if (body.on !== false || !info?.essential) return true;
  const loads = info.loads.length ? info.loads.join(", ") : "its loads";
  return confirm(`Switch off ${n} of ${r}? It is an essential rail, never shed: ${loads} lose power.`);
}

/** @param {Event} ev the stand-in box changed */
function standIn(ev) {
  store.asCrew = /** @type {HTMLInputElement} */ (ev.target).checked;
  redraw();
}

/** @param {string} r @param {Parts} p */
function pdmCard(r, p) {
  const solar = p.rails.find((n) => rail(r, n)?.current_limit_a === null);
  const rows = p.rails.map((n) => {
    const t = `rail/${n}/state`;
    const loads = p.loads.filter((l) => load(r, l)?.rail === n).map((l) => {
      const lt = `load/${l}/power`;
      return html`<tr class="load"><td class="wrap">${l} <small class="sev-warning">${field(r, lt, "faults", "faults")}</small></td>
        <td>${field(r, lt, "on", "onoff")}</td><td></td><td></td>
        <td class="num">${field(r, lt, "power_w", "num2")}</td><td></td><td></td></tr>`;
    });
    return html`<tr class="rail"><td>${n}</td><td>${field(r, t, "state", "text")}</td>
      <td class="num">${field(r, t, "voltage_v", "num2")}</td><td class="num">${field(r, t, "current_a", "num3")}</td>
      <td class="num">${field(r, t, "power_w", "num2")}</td><td class="num">${field(r, t, "current_limit_a", "limit")}</td>
      <td class="switch">${n === solar ? html`<small>solar panels' rail</small>`
        : railSwitch(r, n)}</td></tr>${loads}`;
  });
  return html`<section class="card"><h2>Power distribution (PDM)</h2><table class="pdm">
    <tr><th>rail / load</th><th>state</th><th class="num">V</th><th class="num">A</th><th class="num">W</th>
    <th class="num">limit A</th><th>switch</th></tr>${rows}</table>
    ${mayAct() ? html`<label class="check stand-in"><input type="checkbox" id="as-crew" .checked=${store.asCrew}
      @change=${standIn}> Standing in for the crew: these buttons count as the crew's actions (its response,
      the debrief)</label>` : nothing}
    <p class="help">A rail over its current limit trips: it stays off until Reset. ${solar
      ? `${solar} reads the panels' output, before its converter; the generation above is what reaches the bus.`
      : ""}</p></section>`;
}

/** The plots, and the span of sim time they show. */
function plotsCard() {
  /** @param {Event} ev */
  const pick = (ev) => {
    store.span = Number(/** @type {HTMLSelectElement} */ (ev.target).value);
    redraw();
  };
  return html`<section class="card plots"><h2>Plots <small>the last <select id="plot-span" aria-label="span of the plots"
      @change=${pick}>${SPANS.map(([s, label]) => html`<option value=${s} .selected=${s === store.span}>${label}</option>`)}
    </select> of sim time</small></h2><div id="charts"></div></section>`;
}

export const live = {
  name: "live",
  label: "Live",
  /** @param {{rover: string, parts: Parts}} ctx */
  render: ({rover: r, parts: p}) => html`<div class="grid live">
    <div class="col">${batteryCard(r)}${powerCard(r, p)}${radioCard(r, p)}${driveCard(r, p)}</div>
    <div class="col">${pdmCard(r, p)}${plotsCard()}</div>
    <div class="col">${dashboardCard(r)}${faultsCard(r, clearFault)}${eventsCard(r)}</div></div>`,
  /** @param {{rover: string}} ctx */
  enter: ({rover}) => {
    checkFaults(rover, true);
    return loadRovers();
  },
  /** @param {{rover: string}} ctx */
  tick: ({rover}) => checkFaults(rover),
};
