// Scenarios: the console's scenario files; Play, Stop, the step table as it plays, what it
// waits for, the summary.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {post, query} from "../api.js";
import {changed, mayAct} from "../state.js";

/**
 * `GET /api/scenarios`.
 * @typedef {{index: number, label: string, trigger: string, status: string, outcome: string,
 *   fired_t_s: number | null}} StepStatus
 * @typedef {{scenario: string, rover: string, t_rel_s: number, finished: boolean, end_reason: string,
 *   waiting: string, steps: StepStatus[]}} PlayStatus
 * @typedef {{file: string | null, running?: boolean, exit?: number | null, lines?: string[],
 *   status?: PlayStatus | null}} Playing
 * @typedef {{file: string, problems?: string[], name?: string, description?: string, rover?: string,
 *   steps?: number, time_scale?: number | null, start?: string}} ScenarioInfo
 * @typedef {{scenarios: ScenarioInfo[], playing: Playing}} Scenarios
 */

/** @type {{ok: true, data: Scenarios} | {ok: false, message: string} | null} */
let listed = null;

async function load() {
  listed = await query("/api/scenarios");
  changed();
}

/** @param {Record<string, unknown>} body */
async function play(body) {
  await post("/api/scenarios", body);
  await load();
}

/** @param {ScenarioInfo} s @param {Playing} playing */
function row(s, playing) {
  if (s.problems) return html`<tr><td>${s.file}</td><td colspan="3" class="error">${s.problems.join("; ")}</td></tr>`;
  return html`<tr><td><b>${s.name}</b><br><small>${s.description}</small><br><span class="pill">${s.rover}</span>
      <span class="pill">${s.steps} steps</span>${s.time_scale ? html` <span class="pill">×${s.time_scale}</span>` : nothing}
      <span class="pill">starts ${s.start}</span></td>
    <td><button type="button" class="primary" data-play=${s.file} ?disabled=${!!playing.running || !mayAct()}
      @click=${() => play({file: s.file})}>Play</button></td></tr>`;
}

/** @param {string | null | undefined} status @param {number | null} fired */
const stepClass = (status, fired) => (status === "timed out" || status === "not fired" ? "out" : fired !== null ? "in" : "");

/** @param {Playing} playing */
function progress(playing) {
  if (!playing.file) return html`<p class="help">No scenario is playing.</p>`;
  const st = playing.status;
  return html`<p>${playing.file}: ${playing.running ? html`<b>playing</b>` : `ended (exit ${playing.exit})`}</p>
    ${st ? html`<p><b>${st.scenario}</b> on ${st.rover} · t+${st.t_rel_s.toFixed(0)} s · ${st.finished ? st.end_reason : st.waiting}</p>
      <table><tr><th>#</th><th>step</th><th>when</th><th>status</th><th>answer</th><th class="num">at</th></tr>${st.steps.map((r) => html`<tr>
        <td>${r.index + 1}</td><td>${r.label}</td><td><small>${r.trigger}</small></td>
        <td class=${stepClass(r.status, r.fired_t_s)}>${r.status}</td><td>${r.outcome}</td>
        <td class="num">${r.fired_t_s === null ? "" : `${r.fired_t_s.toFixed(0)} s`}</td></tr>`)}</table>` : nothing}
    <div class="log" id="sc-log">${(playing.lines ?? []).slice(-60).join("\n")}</div>`;
}

export const scenarios = {
  name: "scenarios",
  label: "Scenarios",
  render: () => {
    const playing = listed?.ok ? listed.data.playing : {file: null};
    let list;
    if (!listed) list = "loading…";
    else if (!listed.ok) list = html`<p class="error">${listed.message}</p>`;
    else if (!listed.data.scenarios.length) list = html`<p>No scenario in the console's folder.</p>`;
    else list = html`<table>${listed.data.scenarios.map((s) => row(s, playing))}</table>`;
    return html`<div class="grid two"><div class="col"><section class="card"><h2>Scenarios</h2><div id="sc-list">${list}</div>
      </section></div>
      <div class="col"><section class="card"><h2>Playing <span id="sc-stop">${playing.file && playing.running && mayAct()
        ? html`<button type="button" class="danger" id="sc-stop-btn" @click=${() => play({action: "stop"})}>Stop</button>`
        : nothing}</span></h2><div id="sc-play">${progress(playing)}</div></section></div></div>`;
  },
  after: () => {
    const log = document.getElementById("sc-log");
    if (log) log.scrollTop = log.scrollHeight;
  },
  enter: load,
  tick: load,
};
