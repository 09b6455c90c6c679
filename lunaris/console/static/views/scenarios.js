// Scenarios (drills): the console's scenario files; Play (asking first when the drill resets
// the rover or restores a snapshot), Stop, the steps as they play, what the drill waits for,
// how it ended. Drills for a rover that is not in the session are shown, and cannot be played.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {post, query} from "../api.js";
import {clockText, conditionText, dur, plainMessage, triggerText, words} from "../format.js";
import {changed, mayAct, rovers} from "../state.js";

/**
 * `GET /api/scenarios`.
 * @typedef {{label: string, condition: string, within_s: number, met: boolean | null, met_t_s: number | null,
 *   deadline_t_s: number | null}} ExpectStatus
 * @typedef {{index: number, label: string, trigger: string, status: string, outcome: string,
 *   armed_t_s?: number | null, fired_t_s: number | null, detail?: string, expect?: ExpectStatus | null}} StepStatus
 * @typedef {{scenario: string, rover: string, t_rel_s: number, finished: boolean, end_reason: string,
 *   waiting: string, steps: StepStatus[]}} PlayStatus
 * @typedef {{file: string | null, running?: boolean, exit?: number | null, lines?: string[],
 *   status?: PlayStatus | null}} Playing
 * @typedef {{file: string, problems?: string[], name?: string, description?: string, rover?: string,
 *   steps?: number, time_scale?: number | null, start?: string, duration_s?: number | null}} ScenarioInfo
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

/** @param {ScenarioInfo} s Play, once the instructor has agreed to what the start does */
function ask(s) {
  const start = s.start ?? "";
  const resets = /reset/i.test(start), restores = /snapshot/i.test(start);
  if ((resets || restores) && !confirm(`Play "${s.name}" on ${s.rover}? ${resets
    ? `It starts from a reset: ${s.rover} goes back to its rover file, every injected fault is cleared and the clock goes back to 0.`
    : `It starts ${start}: ${s.rover} goes back to where the snapshot was saved.`}`)) return;
  play({file: s.file});
}

/** @param {string} text a problem of a scenario file ("steps[2].traverse.file: ...") in words */
const problem = (text) => plainMessage(text.replace(/^steps\[(\d+)\]\.?([\w.]*)/,
  (_, i, path) => `step ${Number(i) + 1}${path ? `, ${words(path.replace(/\./g, " "))}` : ""}`));

/** @param {ScenarioInfo} s @param {Playing} playing @param {string[]} here the rovers of the session */
function item(s, playing, here) {
  if (s.problems) {
    return html`<div class="scenario" data-scenario=${s.file}><b>${s.file}</b>
      <p class="error">This file cannot be played: ${s.problems.map(problem).join("; ")}</p></div>`;
  }
  const absent = !here.includes(s.rover ?? "");
  const why = absent ? `${s.rover} is not in this session` : !mayAct() ? "observers cannot play a drill"
    : playing.running ? "a drill is playing: stop it first" : "";
  return html`<div class="scenario" data-scenario=${s.file}>
    <div class="scenario-text"><b>${s.name}</b><p>${s.description}</p>
      <span class="pill">${s.rover}</span>${absent ? html` <span class="pill warn">not in this session</span>` : nothing}
      <span class="pill">${s.steps} steps</span>${s.time_scale ? html` <span class="pill">runs at ×${s.time_scale}</span>` : nothing}
      ${s.duration_s ? html`<span class="pill">${dur(s.duration_s)} of sim time</span>` : nothing}
      <span class="pill">starts ${s.start}</span></div>
    <button type="button" class="primary" data-play=${s.file} title=${why || nothing} ?disabled=${!!why}
      @click=${() => ask(s)}>Play</button></div>`;
}

/** What a step's status is, in words. */
const STATUS = /** @type {Record<string, string>} */ ({
  waiting: "waiting", armed: "watching", fired: "done", ramping: "ramping", done: "done",
  "timed out": "timed out", "not fired": "did not happen"});

/** What the twin said to a step's write, in words. */
const OUTCOME = /** @type {Record<string, string>} */ ({
  accepted: "accepted", rejected: "refused", sent: "sent", "no answer": "no answer", reached: "reached"});

/** @param {string | null | undefined} status @param {number | null} fired */
const stepClass = (status, fired) => (status === "timed out" || status === "not fired" ? "out" : fired !== null ? "in" : "");

/**
 * The notes the drill says for the instructor, by step (from its progress lines).
 * @param {string[]} lines
 * @returns {Map<number, string>}
 */
function notes(lines) {
  const out = new Map();
  let step = -1;
  for (const line of lines) {
    const s = /\] step (\d+)\//.exec(line);
    if (s) step = Number(s[1]) - 1;
    const n = /\]\s+note: (.*)$/.exec(line);
    if (n && step >= 0) out.set(step, n[1]);
  }
  return out;
}

/** @param {PlayStatus} st what the drill waits for now, in words */
function waiting(st) {
  if (st.finished) return "";
  const next = st.steps.find((r) => r.status === "waiting" || r.status === "armed");
  if (!next) return "Finishing…";
  const now = /\(now (.*?)\)/.exec(st.waiting)?.[1];
  const said = now ? now.split(", ").map((x) => conditionText(x.replace(" = ", " == "))).join(", ") : "";
  return `Waiting for step ${next.index + 1}, “${next.label}”: ${triggerText(next.trigger)}${said ? `. Now ${said}.` : "."}`;
}

/** @param {string[]} lines @returns {string} the last thing the drill's run said, as words */
function lastWords(lines) {
  const line = [...lines].reverse().find((l) => l.trim() && !/^\s*(summary|result|#|\d)/.test(l.trim())) ?? "";
  return line.replace(/^\[t\+\s*[\d.]+ s\]\s*/, "").replace(/^lunaris [\w ]+: /, "").trim();
}

/**
 * An expect step's score in words, with its times (drill time): met when and within how much of
 * its time, missed, or what it waits for. It read "met / met".
 * @param {StepStatus} r
 */
function expectWords(r) {
  const e = /** @type {ExpectStatus} */ (r.expect), armed = r.armed_t_s ?? null;
  if (e.met === true && e.met_t_s !== null) {
    return `met at ${clockText(e.met_t_s)}${armed === null ? "" : `, ${dur(e.met_t_s - armed)} of its ${dur(e.within_s)}`}`;
  }
  if (e.met === false) return `missed: not within ${dur(e.within_s)}`;
  return e.deadline_t_s !== null ? `watching, until ${clockText(e.deadline_t_s)}` : `${dur(e.within_s)} once armed`;
}

/** @param {StepStatus[]} steps the crew's score, once the drill has finished ("" without expectations) */
function score(steps) {
  const ex = steps.filter((r) => r.expect);
  if (!ex.length) return nothing;
  const met = ex.filter((r) => r.expect?.met === true).length;
  return html`<p id="sc-score" class=${met === ex.length ? "st-on" : "sev-critical"}><b>Expectations of the crew:
    ${met} of ${ex.length} met</b> (the Crew view and the debrief report give their times)</p>`;
}

/** @param {Playing} playing */
function progress(playing) {
  if (!playing.file) return html`<p class="help">No drill is playing.</p>`;
  const st = playing.status, lines = playing.lines ?? [];
  if (!st) {
    return playing.running ? html`<p>Starting ${playing.file}…</p>`
      : html`<p class="error">The drill ${playing.file} could not start: ${lastWords(lines) || "no reason given"}.</p>`;
  }
  const said = notes(lines);
  const stopped = st.end_reason === "interrupted" || st.end_reason.startsWith("stopped");  // (a new session)
  const how = st.finished ? (stopped ? "Stopped" : "Finished")
    : playing.running ? "Playing" : "Stopped";
  return html`<p><b>${how}</b>: “${st.scenario}” on ${st.rover}, ${dur(st.t_rel_s)} of sim time into the drill${
    st.finished && st.end_reason !== "interrupted" ? html`: ${st.end_reason}.` : "."}</p>
    ${st.finished ? score(st.steps) : html`<p class="help" id="sc-waiting">${waiting(st)}</p>`}
    ${!st.finished && !playing.running ? html`<p class="error">The drill stopped: ${lastWords(lines)}.</p>` : nothing}
    <table class="steps"><tr><th class="num">#</th><th>step</th><th>status</th><th class="num">at (drill time)</th></tr>
      ${st.steps.map((r) => html`<tr data-step=${r.index + 1} data-label=${r.label} data-status=${r.status}
          data-outcome=${r.outcome}>
        <td class="num">${r.index + 1}</td>
        <td class="wrap">${r.label}<br><small>${triggerText(r.trigger)}</small>${said.has(r.index) && r.fired_t_s !== null
          ? html`<br><small class="note">${said.get(r.index)}</small>` : nothing}</td>
        <td class="status ${stepClass(r.status, r.fired_t_s)}">${r.expect ? expectWords(r)
          : html`${STATUS[r.status] ?? words(r.status)}${r.outcome
          ? html`<br><small>${OUTCOME[r.outcome] ?? words(r.outcome)}</small>` : nothing}`}</td>
        <td class="num">${r.fired_t_s === null ? "" : clockText(r.fired_t_s)}</td></tr>`)}</table>`;
}

export const scenarios = {
  name: "scenarios",
  label: "Scenarios",
  render: () => {
    const playing = listed?.ok ? listed.data.playing : {file: null};
    let list;
    if (!listed) list = "loading…";
    else if (!listed.ok) list = html`<p class="error">${listed.message}</p>`;
    else if (!listed.data.scenarios.length) list = html`<p>No drill in the console's folder.</p>`;
    else {
      const here = rovers();
      list = listed.data.scenarios.map((s) => item(s, playing, here));
    }
    return html`<div class="grid two"><div class="col"><section class="card"><h2>Drills</h2>
        <p class="help">Each drill injects faults and changes inputs on its own, step by step, and waits for what
          the crew does.</p><div id="sc-list">${list}</div></section></div>
      <div class="col"><section class="card"><h2>Playing <span id="sc-stop">${playing.file && playing.running && mayAct()
        ? html`<button type="button" class="danger" id="sc-stop-btn" @click=${() => play({action: "stop"})}>Stop</button>`
        : nothing}</span></h2><div id="sc-play">${progress(playing)}</div></section></div></div>`;
  },
  enter: load,
  tick: load,
};
