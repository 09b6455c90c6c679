// The pieces every view is made of: a twin value, an action button, the active faults, the
// event log. Templates (lit-html): whatever a name or a message holds is written as text.

import {html, nothing} from "./vendor/lit-html/lit-html.js";
import {act, answer, query, send} from "./api.js";
import {clockText, dur, faultName, fmt, num, paramsText, partName, plainMessage, words} from "./format.js";
import {activeFaults, changed, dashboardAlarm, dashboardHearing, linkLost, mayAct, rovers, store, val} from "./state.js";

/** @typedef {import("./format.js").Format} Format */

/**
 * A twin value: `data-key` (the key under lunaris/<rover>/) and `data-field` name it for
 * tests and tools (SPEC 8a); a state's value gives its class (`st-on`, `in`, `out`). The
 * field must be one of the key's payload (types.js, generated from the twin's Structs).
 * @template {string} K
 * @param {string} rover
 * @param {K} tail
 * @param {keyof import("./types.js").Payload<K> & string} name
 * @param {Format} how
 * @param {{hidden?: boolean}} [opts]
 */
export function field(rover, tail, name, how, opts = {}) {
  const x = val(rover, tail)?.[name];
  const cls = how === "text" ? `st-${x}` : how === "range" ? (x ? "in" : "out") : nothing;
  return html`<span data-key=${tail} data-field=${name} data-fmt=${how} class=${cls}
    ?hidden=${!!opts.hidden}>${fmt(x, how)}</span>`;
}

/**
 * What an action acts on, as `data-*` attributes of its button (SPEC 8a).
 * @typedef {{rail?: string, component?: string, kind?: string, panel?: string, radio?: string,
 *   snapshot?: string, scale?: string, value?: string}} Target
 */

/**
 * A button that changes the twin: `data-action`, `data-rover` and its target; disabled for
 * an observer, and while the twin has not answered it.
 * @param {{action: string, label: unknown, run: () => unknown, rover?: string, target?: Target,
 *   cls?: string}} b
 */
export function actionButton({action, label, run, rover = store.rover ?? "", target = {}, cls = "act"}) {
  const id = JSON.stringify([action, rover, target]), may = mayAct();
  return html`<button type="button" class=${cls} data-action=${action} data-rover=${rover}
    data-rail=${target.rail ?? nothing} data-component=${target.component ?? nothing}
    data-kind=${target.kind ?? nothing} data-panel=${target.panel ?? nothing}
    data-radio=${target.radio ?? nothing} data-snapshot=${target.snapshot ?? nothing}
    data-scale=${target.scale ?? nothing} data-value=${target.value ?? nothing}
    title=${may ? nothing : "observers cannot change the twin"} ?disabled=${!may || store.pending.has(id)}
    @click=${() => act(id, run)}>${label}</button>`;
}

/** Who put a fault in effect, in words. */
const ORIGIN = /** @type {Record<string, string>} */ ({injected: "injected", derived: "raised by the twin"});

/**
 * What the faults service said when last asked for a rover's faults (`GET .../faults`): the
 * owners that did not answer, in its words (a 502), or why nobody answered at all.
 * @typedef {{missing: string[], unanswered: string}} FaultsCheck
 */
const checks = /** @type {Record<string, FaultsCheck>} */ ({});
const asking = new Set();
/** When each rover's faults were last asked for (ms). */
const asked = /** @type {Record<string, number>} */ ({});
/** How often the faults' owners are asked, in seconds, while a view shows the faults. */
const CHECK_S = 5;

/**
 * Ask the faults service for a rover's faults, to know which owners answer (the faults cards
 * say it): at once with `now`, else once every CHECK_S seconds (a view's tick).
 * @param {string} rover @param {boolean} [now]
 */
export async function checkFaults(rover, now = false) {
  if (asking.has(rover) || (!now && Date.now() - (asked[rover] ?? 0) < CHECK_S * 1000)) return;
  asking.add(rover);
  asked[rover] = Date.now();
  try {
    const res = await query(`/api/rovers/${encodeURIComponent(rover)}/faults`);
    const missing = !res.ok && Array.isArray(res.data?.missing) ? /** @type {string[]} */ (res.data.missing) : [];
    checks[rover] = {missing, unanswered: res.ok || missing.length ? "" : res.message};
  } finally {
    asking.delete(rover);
  }
  changed();
}

/** @param {string} rover @param {string} service @returns {boolean} its liveliness token is there */
const live = (rover, service) => (store.services[rover] ?? []).includes(service);

/** @param {FaultsCheck | undefined} c what is missing from the list, in the faults service's words */
function missingNote(c) {
  if (c?.missing.length) {
    return html`<div class="faults-missing" id="faults-missing" role="alert"><b>Not every part of the rover answered:</b>
      <ul>${c.missing.map((m) => html`<li>${plainMessage(m)}</li>`)}</ul>
      Faults of those parts may be missing below; the ones shown for them are the last known.</div>`;
  }
  if (c?.unanswered) {
    return html`<div class="faults-missing" id="faults-missing" role="alert"><b>The list could not be checked:</b>
      ${plainMessage(c.unanswered)}. The faults below are the last known.</div>`;
  }
  return nothing;
}

/** Clear an injected fault (the faults card's Clear, on the views that show it). @param {string} component @param {string} kind */
export const clearFault = (component, kind) => send("DELETE", `fault/${component}/${kind}`);

/**
 * The active faults of a rover; each injected one with its Clear button. Times are sim time.
 * A fault whose service does not answer is marked as the last known; the owners that did not
 * answer the faults service are named (never fewer faults without saying so).
 * @param {string} rover
 * @param {(component: string, kind: string) => unknown} clear
 */
export function faultsCard(rover, clear) {
  const pre = `lunaris/${rover}/`, check = checks[rover];
  const rows = activeFaults(rover).map((f) => {
    const name = (f.key.startsWith(pre) ? f.key.slice(pre.length) : f.key).replace(/^fault\//, "");
    const bits = name.split("/"), kind = bits.pop() ?? "", component = bits.join("/");
    const values = paramsText(component, kind, f.params);
    const stale = !live(rover, f.service);
    return html`<tr data-fault=${name} data-stale=${stale ? "true" : nothing}>
      <td class="sev-${f.severity ?? "warning"} wrap">${partName(component)}: ${faultName(component, kind)}<br>
        <small>${ORIGIN[f.origin] ?? words(f.origin)}${values ? ` · ${values}` : ""}</small>${stale
          ? html`<br><small class="sev-warning">last known: its ${f.service} service does not answer</small>` : nothing}</td>
      <td class="num">${clockText(f.since_t_s)}</td>
      <td class="end">${f.origin === "injected" ? actionButton({action: "fault-clear", label: "Clear", rover,
        target: {component, kind}, run: () => clear(component, kind)}) : nothing}</td></tr>`;
  });
  const incomplete = !!(check?.missing.length || check?.unanswered);
  return html`<section class="card"><h2>Active faults</h2>${missingNote(check)}<div id="faults-list" class="faults-list">${rows.length
    ? html`<table><tr><th>fault</th><th class="num">since (sim time)</th><th></th></tr>${rows}</table>`
    : html`<p class=${incomplete ? "" : "none"}>${incomplete ? "No active fault among the parts that answered." : "No active fault."}</p>`}</div>
  </section>`;
}

/** What an event is, in words (its kind). */
const KIND = /** @type {Record<string, string>} */ ({
  rejected: "refused", fault_injected: "fault injected", fault_cleared: "fault cleared", fault_raised: "alarm",
  fault_resolved: "alarm ended", command: "command", input: "input", clock: "clock", session: "session",
  scenario: "drill", internal_error: "twin error", mark: "mark", disk_full: "disk",
  delivery: "crew's dashboard"});

/** @param {import("./state.js").TwinEvent} e its message, in plain words, without repeating its kind */
const said = (e) => {
  if (e.kind === "session") return plainMessage(e.message.replace(/^session (?=\d{8}-\d{6}(\.\d{3})? )/, ""), e.key);
  const text = plainMessage(e.message, e.key);
  if (e.kind === "mark") return text.replace(/^mark: /, "");
  if (e.kind === "rejected") return text.replace(/^rejected: /, "");  // "refused rejected: ..." read twice
  if (e.kind === "fault_resolved") return text.replace(/^resolved /, "");  // "alarm ended resolved ..."
  return e.kind === "fault_injected" || e.kind === "fault_cleared" ? text.replace(/^(injected|cleared) /, "") : text;
};

/** @param {import("./state.js").Session} s who the session is of, in words */
export const traineeWords = (s) => (s.trainee ? s.trainee : s.trainee === "" ? "no trainee named" : "…");

/** @param {string} rover a mark on its session's timeline (`control/mark`): a `mark` event */
async function mark(rover) {
  const box = /** @type {HTMLInputElement | null} */ (document.getElementById("mark-text"));
  const text = box?.value.trim() ?? "";
  box?.setAttribute("aria-invalid", String(!text));
  if (!text) {
    answer("invalid", "type what to note first (e.g. crew isolated the rail)");
    return;
  }
  const res = await send("PUT", "control/mark", JSON.stringify({text}), rover);
  if (res.verdict === "accepted" && box) box.value = "";
  return res;
}

/** @param {string} rover the field and button that mark the timeline (not for observers) */
export function markRow(rover) {
  if (!mayAct()) return nothing;
  return html`<form class="row mark-row" @submit=${(/** @type {Event} */ e) => {
    e.preventDefault();
    /** @type {HTMLButtonElement | null} */ (document.querySelector(`[data-action="mark"][data-rover="${CSS.escape(rover)}"]`))?.click();
  }}><label>Note on the timeline, for the debrief<input type="text" id="mark-text" maxlength="500"
      placeholder="crew isolated the rail"></label>
    ${actionButton({action: "mark", label: "Mark", rover, run: () => mark(rover)})}</form>`;
}

/**
 * Who acted, when a person or a scenario did (the twin's own events say nothing more): the
 * crew's actions from its dashboard read apart from the instructor's own.
 * @param {import("./types.js").Event} e
 */
const byWhom = (e) => (e.actor && e.actor !== "twin" ? ` · by the ${e.actor}` : "");

/** The most of an event's words the log shows on its line (a mark may hold 500). */
const LOG_CHARS = 240;

/**
 * The newest 120 of its running session's events, newest first (times are sim time), and the
 * instructor's mark.
 * @param {string} rover
 */
export function eventsCard(rover) {
  const evs = (store.events[rover] ?? []).slice(-120).reverse(), s = store.sessions[rover];
  return html`<section class="card"><h2>Event log <small>${s?.trainee ? `${s.trainee}'s session · ` : ""}newest first · sim time</small></h2>
    ${markRow(rover)}<div id="events-list" class="events">${evs.length ? evs.map((e) => {
    const text = said(e), long = text.length > LOG_CHARS;  // a long mark: its start, the whole on hover
    return html`<div class="sev-${e.severity}" data-kind=${e.kind} data-actor=${e.actor ?? ""} title=${long ? text : nothing}>
      <span class="t">${clockText(e.t_s)}</span><b>${KIND[e.kind] ?? words(e.kind)}</b> ${long ? `${text.slice(0, LOG_CHARS - 1)}…` : text}
      <small>[${e.source}${byWhom(e)}]</small></div>`;
  }) : html`<p>No event yet.</p>`}</div></section>`;
}

/** @param {string} rover a banner while the console says the rover's link is lost, and why */
export function linkBanner(rover) {
  const link = store.links[rover];
  if (!linkLost(rover) || !link) return nothing;
  return html`<div class="link-lost" role="alert" data-link="lost">Link to ${rover} lost${link.reason
    ? `: ${link.reason}` : ""}. The values below are the last received, and nothing sent to it is applied until
    the link is back.</div>`;
}

/** A banner while the console has lost the twin's router (every rover's values are old). */
export function routerBanner() {
  const router = store.router;
  if (router?.state !== "lost") return nothing;
  return html`<div class="link-lost" role="alert" data-router="lost">Connection to the twin lost: ${router.message}.
    The values below are the last received; nothing can be sent until it is back.</div>`;
}

/** @param {number} t a wall time (s since 1970) as the time of day, e.g. 14:03:27 */
const timeOfDay = (t) => new Date(t * 1000).toLocaleTimeString("en-GB", {hour12: false});

/** The output flavours in the crew's words. */
const FLAVOUR = /** @type {Record<string, string>} */ ({ros2: "ROS 2 (DDS)", ros2dds: "ROS 2 via zenoh-bridge-ros2dds",
  rmw_zenoh: "ROS 2 on rmw_zenoh", json: "JSON"});

/**
 * Whether the crew's dashboard is receiving (SPEC 13d), from the bridge's `bridge/delivery`:
 * "receiving", "silent since …" and why, per flavour its readers, messages sent and failures.
 * @param {string} rover
 */
export function dashboardCard(rover) {
  const h = dashboardHearing(rover), rec = val(rover, "bridge/delivery");
  const said = h.state === "receiving" ? "receiving"
    : h.state === "silent" ? `silent since ${timeOfDay(h.since ?? 0)} (${dur(h.for_s)}): ${h.why}`
    : h.state === "none" ? "no dashboard has read the topics yet" : "no report from the bridge";
  const rows = (rec?.flavours ?? []).map((f) => html`<tr data-flavour=${f.flavour}><td>${FLAVOUR[f.flavour] ?? f.flavour}</td>
    <td class="num">${f.readers ?? "–"}</td><td class="num">${f.topics_read} of ${f.topics}</td><td class="num">${num(f.sent)}</td>
    <td class="num">${f.last_send_t_s === null ? "–" : clockText(f.last_send_t_s)}</td>
    <td class="num" title=${f.last_error || nothing}>${num(f.errors)}</td></tr>`);
  return html`<section class="card"><h2>Crew's dashboard</h2>
    <p class=${h.state === "silent" ? "sev-critical" : ""} data-key="bridge/delivery" data-field="receiving"
      data-dashboard=${h.state}>crew's dashboard: ${said}</p>
    ${rows.length ? html`<table><tr><th>output</th><th class="num">readers</th><th class="num">topics read</th>
      <th class="num">messages sent</th><th class="num">last sent (sim time)</th><th class="num">failed</th></tr>${rows}</table>`
    : nothing}</section>`;
}

/** An alarm for each rover whose crew's dashboard, receiving before, has heard nothing for 3 s in a session. */
export function dashboardBanners() {
  return rovers().filter(dashboardAlarm).map((rover) => {
    const h = dashboardHearing(rover);
    return html`<div class="link-lost" role="alert" data-dashboard-alarm=${rover}>The crew's dashboard on ${rover} has heard
      nothing since ${timeOfDay(h.since ?? 0)} (${dur(h.for_s)}): ${h.why}. The crew sees no new value or alarm; the
      values here are the twin's.</div>`;
  });
}
