// The crew: what it sees (SPEC 12b), whether its dashboard is receiving at all (SPEC 13d, from
// the bridge's bridge/delivery), the crew's dashboard as the bridge renders it now
// (`GET /api/rovers/<rover>/crew`): its alarms (/diagnostics), its readings (every topic the
// mapping publishes) and the controls it may call; how it responds (SPEC 12d, `GET
// /api/rovers/<rover>/response`): each fault of the session with its first symptom, the
// crew's actions and its resolution, the drill's expectations met or missed; beside them the
// faults the instructor put in effect. Asked again as soon as an event of the rover comes (a
// fault injected, an alarm raised, the crew's call answered), and every CREW_S seconds while
// the view shows (what telemetry alone changes). The instructor marks the session's timeline from
// here too (a Mark for the debrief, as above the Session view's event log).

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {query} from "../api.js";
import {clockText, dur, faultName, fieldLabel, num, partName, plainMessage, words} from "../format.js";
import {changed, store} from "../state.js";
import {checkFaults, clearFault, dashboardCard, faultsCard, markRow} from "../widgets.js";

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

/**
 * What `GET /api/rovers/<rover>/response` answers (lunaris/console/response.py,
 * common.response.LiveResponse): the crew's response in the running session (SPEC 12d).
 * @typedef {{t_s: number, action: string, target: string, accepted: boolean, message?: string}} CrewAction
 * @typedef {{key: string, fault: string, injected_t_s: number, first_symptom_t_s: number | null,
 *   first_crew_action_t_s: number | null, resolved_t_s: number | null, crew_actions: CrewAction[],
 *   symptom: string, active: boolean, since_injection_s: number | null, crew_acted: boolean,
 *   response_s: number | null, resolved_by: string}} LiveFault
 * @typedef {{label: string, met: boolean | null, at_t_s: number | null, within_s: number,
 *   deadline_t_s: number | null, scenario: string, detail: string}} Expectation
 * @typedef {{rover: string, session: string, trainee: string | null, t_s: number | null,
 *   faults: LiveFault[], expectations: Expectation[]}} LiveResponse
 */

/** How often the crew's view and response are asked again, in seconds, while they show. */
const CREW_S = 2;
/** The last answers by rover, and when they were asked (ms). */
const seen = /** @type {Record<string, Result<CrewView>>} */ ({});
const responses = /** @type {Record<string, Result<LiveResponse>>} */ ({});
const asked = /** @type {Record<string, number>} */ ({});
/** The rover's newest event when the view was last asked: a newer one asks again at once. */
const heard = /** @type {Record<string, object | undefined>} */ ({});

/** @param {string} rover @returns {object | undefined} the newest event of the rover the page holds */
const newest = (rover) => store.events[rover]?.at(-1);

/** @param {string} rover */
async function load(rover) {
  asked[rover] = Date.now();
  heard[rover] = newest(rover);
  const r = encodeURIComponent(rover);
  [seen[rover], responses[rover]] = await Promise.all([query(`/api/rovers/${r}/crew`), query(`/api/rovers/${r}/response`)]);
  changed();
}

/** @param {number} t a sim time, kept on one line */
const at = (t) => html`<span class="t">${clockText(t)}</span>`;

/** @param {CrewAction} a one action of the crew, in words */
const actionWords = (a) => `${clockText(a.t_s)} ${words(a.action)} ${a.target}${a.accepted ? "" : " (refused)"}`;

/** @param {LiveFault} f */
function faultRow(f) {
  const bits = f.fault.split("/"), kind = bits.pop() ?? "", component = bits.join("/");
  const acted = f.first_crew_action_t_s !== null;
  return html`<tr data-fault=${f.fault} data-acted=${String(acted)} data-resolved=${String(f.resolved_t_s !== null)}>
    <td class="wrap">${partName(component)}: ${faultName(component, kind)}<br><small>injected ${clockText(f.injected_t_s)}${
      f.active && f.since_injection_s !== null ? ` · ${dur(f.since_injection_s)} ago` : ""}</small></td>
    <td class="wrap">${f.first_symptom_t_s === null ? html`<span class="muted">nothing yet</span>`
      : html`${at(f.first_symptom_t_s)}<br><small>${plainMessage(f.symptom)}</small>`}</td>
    <td class="wrap">${acted ? html`<b class="st-on">acted</b>${f.response_s === null ? "" : ` ${dur(f.response_s)} after the symptom`}
      <br><small>${f.crew_actions.map(actionWords).join(" · ")}</small>`
      : f.active ? html`<span class="t ${f.first_symptom_t_s !== null ? "sev-warning" : "muted"}">not yet</span>`
        : html`<span class="t muted">no response</span>`}</td>
    <td class="wrap">${f.resolved_t_s === null ? (f.active ? "in effect" : "cleared")
      : html`${at(f.resolved_t_s)}${f.resolved_by ? html`<br><small>${plainMessage(f.resolved_by)}</small>` : nothing}`}</td></tr>`;
}

/** @param {Expectation} e @param {number | null} now */
function expectationRow(e, now) {
  const state = e.met === true ? html`<b class="st-on">met</b> at ${e.at_t_s === null ? "–" : at(e.at_t_s)}`
    : e.met === false ? html`<b class="sev-critical">missed</b>`
      : e.deadline_t_s !== null && now !== null ? html`waiting: ${dur(Math.max(0, e.deadline_t_s - now))} left`
        : html`not started`;
  return html`<tr data-expectation=${e.label} data-met=${String(e.met)}><td class="wrap">${e.label}${e.detail
    ? html`<br><small>${plainMessage(e.detail)}</small>` : nothing}</td><td class="num">${dur(e.within_s)}</td><td>${state}</td></tr>`;
}

/** @param {Result<LiveResponse> | undefined} res the crew's response in the running session */
function responseCard(res) {
  if (res === undefined) return nothing;
  if (!res.ok) {
    return html`<section class="card" id="crew-response"><h2>The crew's response</h2>
      <p class="error">Not known: ${plainMessage(res.message)}</p></section>`;
  }
  const v = res.data;
  return html`<section class="card" id="crew-response"><h2>The crew's response <small>${v.trainee ? `${v.trainee}'s session`
    : "this session"}</small></h2>
    <p class="help">Each fault injected in this session: when the crew could first see it, whether and when it acted,
      when it was resolved; and the drill's expectations as they are met or missed.</p>
    ${v.faults.length ? html`<table><tr><th>fault</th><th>first symptom</th><th>crew</th><th>resolved</th></tr>
      ${v.faults.map((f) => faultRow(f))}</table>` : html`<p id="crew-no-fault">No fault injected in this session yet.</p>`}
    ${v.expectations.length ? html`<table class="expect"><tr><th>expected of the crew</th><th class="num">within</th><th></th></tr>
      ${v.expectations.map((e) => expectationRow(e, v.t_s))}</table>` : nothing}</section>`;
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
  if (t.type.endsWith("/Odometry")) {  // where the rover is and where it heads, as a dashboard shows it
    const p = m.pose?.pose?.position ?? {}, q = m.pose?.pose?.orientation ?? {};
    const yaw = Math.atan2(2 * ((q.w ?? 1) * (q.z ?? 0) + (q.x ?? 0) * (q.y ?? 0)),
                           1 - 2 * ((q.y ?? 0) ** 2 + (q.z ?? 0) ** 2)) * 180 / Math.PI;
    return `x ${n(p.x, 1)} m, y ${n(p.y, 1)} m, z ${n(p.z, 1)} m; yaw ${n(yaw, 0)}° from east`;
  }
  if ("data" in m) {
    if (typeof m.data === "boolean") return m.data ? "yes" : "no";
    if (Array.isArray(m.data)) return m.data.map((/** @type {unknown} */ v) => (typeof v === "number" ? num(v, 2) : String(v))).join(" · ");
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

/**
 * @param {string} rover a note on the session's timeline while watching the crew (`control/mark`:
 * a `mark` event, drawn on the debrief's timeline); none for observers
 */
function markCard(rover) {
  const row = markRow(rover);
  return row === nothing ? nothing : html`<section class="card" id="crew-mark"><h2>Mark for the debrief</h2>${row}
    <p class="help">What you note here is on the session's timeline, in the debrief of this trainee.</p></section>`;
}

export const crew = {
  name: "crew",
  label: "Crew",
  /** @param {{rover: string}} ctx */
  render: ({rover}) => {
    if (asked[rover] !== undefined && newest(rover) !== heard[rover]) load(rover);  // an event came
    const res = seen[rover];
    return html`<div class="grid two">
      <div class="col">${markCard(rover)}${dashboardCard(rover)}${alarmsCard(res)}${responseCard(responses[rover])}${faultsCard(rover, clearFault)}</div>
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
