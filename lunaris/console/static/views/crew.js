// What the crew sees (SPEC 12b): the crew's dashboard as the bridge renders it now
// (`GET /api/rovers/<rover>/crew`): its alarms (/diagnostics), its readings (every topic the
// mapping publishes) and the controls it may call; beside them the faults the instructor put
// in effect, so the instructor sees what the crew has to diagnose from. Asked again every
// CREW_S seconds while the view shows.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {query} from "../api.js";
import {clockText, fieldLabel, num, partName, plainMessage} from "../format.js";
import {changed} from "../state.js";
import {checkFaults, faultsCard} from "../widgets.js";
import {clearFault} from "./live.js";

/**
 * What `GET /api/rovers/<rover>/crew` answers (lunaris/console/api.py, services.bridge.crew_view).
 * @typedef {{name: string, component: string, level: number, level_name: string, message: string,
 *   values: {key: string, value: string}[]}} CrewStatus
 * @typedef {{topic: string, type: string, key: string, message: Record<string, any> | null}} CrewTopic
 * @typedef {{service: string, type: string, key: string, write: string}} CrewControl
 * @typedef {{rover: string, view: "symptoms" | "full", t_s: number | null, diagnostics: CrewStatus[],
 *   topics: CrewTopic[], controls: CrewControl[]}} CrewView
 */
/** @template T @typedef {{ok: true, data: T} | {ok: false, message: string}} Result */

/** How often the crew's view is asked again, in seconds, while it shows. */
const CREW_S = 2;
/** The last answer by rover, and when it was asked (ms). */
const seen = /** @type {Record<string, Result<CrewView>>} */ ({});
const asked = /** @type {Record<string, number>} */ ({});

/** @param {string} rover */
async function load(rover) {
  asked[rover] = Date.now();
  seen[rover] = await query(`/api/rovers/${encodeURIComponent(rover)}/crew`);
  changed();
}

/** Each level of a status as the page says it, and its class. */
const LEVELS = /** @type {Record<string, [string, string]>} */ ({
  OK: ["OK", "st-on"], WARN: ["warning", "sev-warning"], ERROR: ["ERROR", "sev-critical"],
  STALE: ["no data", "sev-warning"]});

/** @param {CrewStatus[]} statuses the alarms first, then the parts that are OK in one line */
function alarms(statuses) {
  const bad = statuses.filter((s) => s.level_name !== "OK"), ok = statuses.filter((s) => s.level_name === "OK");
  return html`${bad.length ? html`<table><tr><th>part</th><th>state</th><th>what the dashboard says</th></tr>
    ${bad.map((s) => {
    const [said, cls] = LEVELS[s.level_name] ?? [s.level_name, "sev-warning"];
    return html`<tr data-component=${s.component} data-level=${s.level_name}><td>${partName(s.component)}</td>
      <td class=${cls}>${said}</td><td class="wrap">${plainMessage(s.message)}${s.values.length
      ? html`<br><small>${s.values.map((v) => plainMessage(v.value)).join(" · ")}</small>` : nothing}</td></tr>`;
  })}</table>` : html`<p class="none" id="crew-all-ok">No alarm: every part reads OK.</p>`}
    ${bad.length && ok.length ? html`<p class="help" id="crew-ok">OK: ${ok.map((s) => partName(s.component)).join(", ")}.</p>`
    : nothing}`;
}

/** A ROS BatteryState's status and health codes in words. */
const SUPPLY = ["status unknown", "charging", "discharging", "not charging", "full"];
const HEALTH = ["health unknown", "healthy", "overheating", "dead", "over-voltage", "failed", "cold",
                "watchdog timer expired", "safety timer expired"];
/** A topic's unit, from the end of its name. */
const UNITS = /** @type {[RegExp, string][]} */ ([[/_mv$/, "mV"], [/_ma$/, "mA"], [/_mw$/, "mW"], [/_w$/, "W"],
                                                   [/_j$/, "J"]]);

/** @param {number | null | undefined} v @param {number} digits */
const n = (v, digits) => (v === null || v === undefined || !Number.isFinite(v) ? "–" : v.toFixed(digits));

/** @param {CrewTopic} t what a topic's latest message says, in words */
function reading(t) {
  const m = t.message;
  if (m === null) return "no message yet";
  if (t.type.endsWith("/BatteryState")) {
    return `${n(m.percentage * 100, 1)} %, ${n(m.voltage, 2)} V, ${n(m.current, 2)} A, ${n(m.temperature, 1)} °C; `
      + `${SUPPLY[m.power_supply_status] ?? "status unknown"}, ${HEALTH[m.power_supply_health] ?? "health unknown"}`;
  }
  if (t.type.endsWith("/JointState")) {
    return (m.name ?? []).map((/** @type {string} */ k, /** @type {number} */ i) =>
      `${fieldLabel(k)} ${n(m.position?.[i], 2)}`).join(" · ");
  }
  if ("data" in m) {
    if (typeof m.data === "boolean") return m.data ? "yes" : "no";
    const unit = UNITS.find(([re]) => re.test(t.topic))?.[1] ?? "";
    if (typeof m.data !== "number") return String(m.data);
    const v = m.data, digits = Number.isInteger(v) || Math.abs(v) >= 100 ? 0 : 2;  // as a dashboard shows it
    return `${num(v, digits)} ${unit}`.trim();
  }
  return "a message";
}

/** @param {CrewTopic[]} topics every topic but /diagnostics, with its reading */
function readings(topics) {
  const shown = topics.filter((t) => !t.type.endsWith("/DiagnosticArray"));
  return html`<div class="events"><table><tr><th>topic</th><th>reads</th></tr>${shown.map((t) => html`<tr
    data-topic=${t.topic}><td><code>${t.topic}</code></td><td>${reading(t)}</td></tr>`)}</table></div>`;
}

/** @param {CrewControl} c what a control of the crew does, in words */
function does(c) {
  const rail = /\/cmd\/rail\/([^/]+)$/.exec(c.key)?.[1];
  if (rail && c.service.endsWith("/set_enabled")) return `switches rail ${rail} on or off`;
  if (rail && c.service.endsWith("/reset")) return `resets rail ${rail} (it trips again while the cause is there)`;
  if (c.key.endsWith("/input/drive/traverse")) return "stops the rover";
  return `writes ${c.key.replace(/^lunaris\/[^/]+\//, "")}`;
}

/** @param {CrewControl[]} controls */
function controlList(controls) {
  if (!controls.length) return html`<p>The crew's dashboard has no control of this rover.</p>`;
  return html`<table><tr><th>ROS 2 service</th><th>does</th></tr>${controls.map((c) => html`<tr data-service=${c.service}>
    <td><code>${c.service}</code></td><td>${does(c)}</td></tr>`)}</table>`;
}

/** @param {Result<CrewView> | undefined} res */
function alarmsCard(res) {
  if (res === undefined) return html`<section class="card" id="crew-alarms"><p>Asking the console…</p></section>`;
  if (!res.ok) {
    return html`<section class="card" id="crew-alarms"><p class="error">No view of the crew's dashboard:
      ${plainMessage(res.message)}</p></section>`;
  }
  const v = res.data;
  return html`<section class="card" id="crew-alarms" data-view=${v.view}><h2>The crew's alarms
      <small>${v.t_s === null ? "" : `sim time ${clockText(v.t_s)}`}</small></h2>
    <p class="help">${v.view === "symptoms"
    ? "What the crew's dashboard shows now (its diagnostics): the rover's own alarms and what its telemetry shows, never the faults you injected (below). The crew has to find the cause from these."
    : "The bridge shows the crew every fault in effect, injected ones included (crew view: full, for integration work)."}</p>
    ${alarms(v.diagnostics)}</section>`;
}

export const crew = {
  name: "crew",
  label: "Crew sees",
  /** @param {{rover: string}} ctx */
  render: ({rover}) => {
    const res = seen[rover];
    return html`<div class="grid two">
      <div class="col">${alarmsCard(res)}${faultsCard(rover, clearFault)}</div>
      <div class="col"><section class="card" id="crew-readings"><h2>The crew's readings</h2>
        <p class="help">Every topic the crew's dashboard receives, as it reads now.</p>
        ${res?.ok ? readings(res.data.topics) : nothing}</section>
        ${res?.ok ? html`<section class="card" id="crew-controls"><h2>What the crew can do from its dashboard</h2>
          ${controlList(res.data.controls)}</section>` : nothing}</div></div>`;
  },
  /** @param {{rover: string}} ctx */
  enter: ({rover}) => {
    checkFaults(rover, true);
    return load(rover);
  },
  /** @param {{rover: string}} ctx */
  tick: ({rover}) => {
    checkFaults(rover);
    if (Date.now() - (asked[rover] ?? 0) >= CREW_S * 1000) load(rover);
  },
};
