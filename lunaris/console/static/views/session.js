// Session: a new trainee's session (SPEC 12c: the running one ends, the twin starts again
// from its rover file or a snapshot, the plots and event log start empty) and the sessions of
// the day; pause, resume and speed the clock; reset the rover to its rover file; save and
// restore snapshots; ask the battery prediction.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {WORDS, answer, post, query, send} from "../api.js";
import {clockText, dayTime, dur, emptyWords, fmt, nameProblem, plainMessage, sessionName, wallTime} from "../format.js";
import {battery, changed, clock, mayAct, runningSession} from "../state.js";
import {actionButton, eventsCard, field, traineeWords} from "../widgets.js";

/** @typedef {import("../api.js").Answer} Answer */
/**
 * A session as the console lists it: the twin's, with the console's notes laid over
 * (lunaris/console/session_notes.py): voided, renamed (`journal_trainee`: the name it began with).
 * @typedef {import("../types.js").SessionInfo & {void?: boolean, journal_trainee?: string}} SessionInfo
 */
/** @typedef {import("../types.js").SnapshotInfo} SnapshotInfo */
/** @typedef {import("../types.js").Prediction} Prediction */
/** @typedef {import("../types.js").Percentiles} Percentiles */
/** @template T @typedef {{ok: true, data: T} | {ok: false, message: string}} Result */

/** What the twin answered to the last queries, by rover. */
const answers = {
  /** @type {Record<string, Result<SnapshotInfo[]>>} */
  snapshots: {},
  /** @type {Record<string, Result<Prediction> | "computing">} */
  prediction: {},
  /** @type {Record<string, Result<SessionInfo[]>>} */
  sessions: {},
  /** @type {Record<string, Answer>} the twin's answer to the last new trainee */
  started: {},
};

/** The running session whose list is shown, by rover, and when it was asked (ms). */
const listed = /** @type {Record<string, {id: string, at: number}>} */ ({});
/** How often the sessions list is asked again while the view shows it, in seconds. */
const SESSIONS_S = 10;

/** @param {string} rover */
async function loadSessions(rover) {
  listed[rover] = {id: runningSession(rover)?.id ?? "", at: Date.now()};
  answers.sessions[rover] = await query(`/api/rovers/${encodeURIComponent(rover)}/sessions`);
  changed();
}

/** @param {string} rover */
async function loadSnapshots(rover) {
  answers.snapshots[rover] = await query(`/api/rovers/${encodeURIComponent(rover)}/snapshots`);
  changed();
}

/** @param {string} rover */
async function predict(rover) {
  const value = (/** @type {string} */ id) => /** @type {HTMLInputElement | null} */ (document.getElementById(id))?.value ?? "";
  answers.prediction[rover] = "computing";
  changed();
  answers.prediction[rover] = await query(`/api/rovers/${encodeURIComponent(rover)}/prediction?hours=${
    encodeURIComponent(value("pr-h"))}&samples=${encodeURIComponent(value("pr-n"))}`);
  changed();
}

/** @param {number | undefined} x the clock's speed @returns {string} what it means */
const speedWords = (x) => (x === undefined ? "" : x === 1 ? "(real time: a simulated second every second)"
  : `(${x} simulated seconds every second)`);

/** @param {string} r */
function clockCard(r) {
  /** @param {Record<string, unknown>} body */
  const control = (body) => () => send("PUT", "clock/control", JSON.stringify(body), r);
  const other = () => {
    const v = /** @type {HTMLInputElement | null} */ (document.getElementById("scale"))?.value ?? "";
    return send("PUT", "clock/control", JSON.stringify({time_scale: v === "" ? null : Number(v)}), r);
  };
  return html`<section class="card"><h2>Simulated time</h2>
    <p>Sim time ${field(r, "clock", "t_s", "clock")}, at ${field(r, "clock", "time_scale", "x")}
      <small>${speedWords(clock(r)?.time_scale)}</small> ${field(r, "clock", "paused", "", {hidden: true})}</p>
    <div class="row">${actionButton({action: "clock-pause", label: "Pause", rover: r, run: control({paused: true})})}
      ${actionButton({action: "clock-resume", label: "Resume", rover: r, run: control({paused: false})})}
      ${[1, 2, 5, 10, 20, 50, 100].map((x) => actionButton({action: "clock-scale", label: `×${x}`, rover: r,
                                                           target: {scale: String(x)}, run: control({time_scale: x})}))}</div>
    <div class="row"><label>Other speed [×]<input type="number" id="scale" min="0.01" max="10000" step="any"></label>
      ${actionButton({action: "clock-scale", label: "Set", rover: r, target: {scale: ""}, run: other})}</div></section>`;
}

/** @param {string} r */
function resetCard(r) {
  const reset = () => confirm(`Reset ${r} to its rover file? Every injected fault is cleared and the clock goes back to 0.`)
    && send("PUT", "control/reset", "", r);
  return html`<section class="card"><h2>Start again</h2><p class="help">Puts ${r} back to its rover file: full stored
      energy, temperature, rails and inputs as at the start, every injected fault cleared, the clock at 0.</p>
    ${actionButton({action: "reset", label: `Reset ${r}`, rover: r, cls: "danger", run: reset})}</section>`;
}

/** @param {Percentiles} t @param {"p05" | "p50" | "p95"} p @param {number} horizon */
const within = (t, p, horizon) => (t[p] === null ? `more than ${dur(horizon)}` : dur(t[p]));

/** @param {Result<Prediction> | "computing" | undefined} res @param {string} r */
function prediction(res, r) {
  if (res === undefined) return nothing;
  if (res === "computing") return html`<p>Computing the futures…</p>`;
  if (!res.ok) return html`<p class="error">No prediction: ${plainMessage(res.message)}</p>`;
  const d = res.data, t = d.time_to_empty_s, s = d.soc_at_horizon, h = d.horizon_s;
  return html`<table><tr><th></th><th class="num">pessimistic</th><th class="num">typical</th><th class="num">optimistic</th></tr>
    <tr><td>time until the battery cuts off</td><td class="num">${within(t, "p05", h)}</td>
      <td class="num">${within(t, "p50", h)}</td><td class="num">${within(t, "p95", h)}</td></tr>
    <tr><td>charge after ${dur(h)}</td><td class="num">${fmt(s.p05, "pct")}</td><td class="num">${fmt(s.p50, "pct")}</td>
      <td class="num">${fmt(s.p95, "pct")}</td></tr></table>
    <p class="help" id="pr-empty">The battery cuts off when ${emptyWords(battery(r)) || "its charge reaches the rover's empty level, or its voltage under load falls below the cut-off of its battery management"}:
      whichever comes first (under a heavy draw the voltage can reach the cut-off with some charge left).
      Pessimistic: only 1 future in 20 does worse; optimistic: only 1 in 20 does better.</p>
    <p class="help">${d.samples} futures from sim time ${clockText(d.t_s)}, computed in ${d.computed_in_s.toFixed(1)} s.
      ${(d.notes ?? []).map((n) => plainMessage(n)).join(" ")}</p>`;
}

/** @param {string} r */
function predictionCard(r) {
  return html`<section class="card"><h2>Battery prediction</h2>
    <p class="help">Many possible futures of the rover from its state now, the inputs held as they are.</p>
    <div class="row"><label>hours ahead<input type="number" id="pr-h" min="0.1" max="168" step="any" value="8"></label>
      <label>futures to try<input type="number" id="pr-n" min="1" max="10000" value="1000"></label>
      <button type="button" class="act" id="predict" ?disabled=${answers.prediction[r] === "computing"}
        @click=${() => predict(r)}>Predict</button></div>
    <div id="prediction">${prediction(answers.prediction[r], r)}</div></section>`;
}

/** @param {Result<SnapshotInfo[]> | undefined} res @param {string} r */
function snapshotList(res, r) {
  if (res === undefined) return nothing;
  if (!res.ok) return html`<p class="error">${res.message}</p>`;
  if (!res.data.length) return html`<p>No snapshot yet.</p>`;
  /** @param {string} name */
  const restore = (name) => () => confirm(`Restore the snapshot "${name}" of ${r}? The twin goes back to where it was when it was saved.`)
    && send("PUT", `control/restore/${name}`, "", r);
  return html`<table><tr><th>name</th><th class="num">sim time</th><th>saved on</th><th></th></tr>${res.data.map((s) => html`<tr>
    <td>${s.name}</td><td class="num">${clockText(s.t_s)}</td><td>${wallTime(s.saved_at)}</td>
    <td>${actionButton({action: "snapshot-restore", label: "Restore", rover: r, target: {snapshot: s.name},
                        run: restore(s.name)})}</td></tr>`)}</table>`;
}

/** @param {string} r */
function snapshotsCard(r) {
  const save = async () => {
    const box = /** @type {HTMLInputElement | null} */ (document.getElementById("snap-name"));
    const name = box?.value.trim() ?? "", wrong = nameProblem(name, "snapshot", 64);
    box?.setAttribute("aria-invalid", String(!!wrong));
    if (wrong) {
      answer("invalid", wrong);
      return;
    }
    const res = await send("PUT", `control/snapshot/${name}`, "", r);
    await loadSnapshots(r);
    return res;
  };
  return html`<section class="card"><h2>Snapshots <button type="button" class="act" id="snap-refresh"
      @click=${() => loadSnapshots(r)}>Refresh</button></h2>
    <p class="help">A snapshot keeps the state of every service (stored energy, temperature, rails, inputs, faults, time)
      under a name; restoring it puts the twin back exactly there.</p>
    <div class="row"><label>Name <small>one word: letters, digits, - _ .</small><input type="text" id="snap-name"
        placeholder="before-storm" pattern="[A-Za-z0-9_.\-]{1,64}"></label>
      ${actionButton({action: "snapshot-save", label: "Save snapshot", rover: r, cls: "primary", run: save})}</div>
    <div id="snapshots">${snapshotList(answers.snapshots[r], r)}</div></section>`;
}

/** @param {string} id @returns {HTMLInputElement | HTMLSelectElement | null} */
const box = (id) => /** @type {HTMLInputElement | HTMLSelectElement | null} */ (document.getElementById(id));

/** @param {Answer | undefined} a the twin's answer, kept in the card */
const said = (a) => (a === undefined ? nothing : html`<p id="session-answer" class="said ${a.verdict.replace(" ", "")}"
  data-verdict=${a.verdict}><b>${WORDS[/** @type {keyof typeof WORDS} */ (a.verdict)] ?? a.verdict}:</b>
  ${plainMessage(a.message, "control/session")}</p>`);

/**
 * Why a name cannot be a trainee's, in the twin's words ("" when it can; the twin checks it
 * again: common.messages.trainee_problem): letters of any script, digits, spaces and - _ . ' &.
 * @param {string} name
 */
function traineeProblem(name) {
  const bad = [...new Set([...name].filter((c) => !/[\p{L}\p{N} \-_.'&]/u.test(c)))];
  if (!bad.length) return "";
  const said = bad.map((c) => (/\p{Cc}/u.test(c) ? "a control character" : `'${c}'`));
  return `a trainee's name is letters, digits, spaces and - _ . ' &; this one has ${[...new Set(said)].join(", ")}`;
}

/**
 * The drill playing on rover ``r`` now, by its name ("" when none): a new session stops it.
 * @param {string} r
 * @returns {Promise<string>}
 */
async function drillPlaying(r) {
  /** @type {Awaited<ReturnType<typeof query<{playing?: {running?: boolean, file?: string | null,
   *   status?: {scenario?: string, rover?: string} | null}}>>>} */
  const listed = await query("/api/scenarios");
  const playing = listed.ok ? listed.data.playing : undefined;
  if (!playing?.running || (playing.status?.rover && playing.status.rover !== r)) return "";
  return playing.status?.scenario || playing.file || "a drill";
}

/** @param {string} r the running session, and a new trainee's */
function traineeCard(r) {
  const s = runningSession(r), snaps = answers.snapshots[r];
  const start = async () => {
    const name = box("trainee-name")?.value.trim() ?? "", from = box("trainee-from")?.value ?? "";
    box("trainee-name")?.setAttribute("aria-invalid", String(!name));
    if (!name) {
      answer("invalid", "type the trainee's name (or the crew's) first");
      return;
    }
    const why = traineeProblem(name);  // before asking to end the running session for it
    if (why) {
      box("trainee-name")?.setAttribute("aria-invalid", "true");
      answer("invalid", `not sent: ${why}`);
      return;
    }
    const ending = s?.trainee ? `${s.trainee}'s session ends` : "The running session ends";
    const how = from ? `the twin is restored to the snapshot "${from}"` : "the twin goes back to its rover file";
    const drill = await drillPlaying(r);  // it belongs to the session that ends (SPEC 13a): said first
    const stops = drill ? `The drill "${drill}" stops first, and nothing more of it is scored. ` : "";
    if (!confirm(`${stops}Start ${name}'s session on ${r}? ${ending}; ${how}, every injected fault cleared, and the `
      + "plots and the event log start empty.")) return;
    const res = await send("PUT", "control/session", JSON.stringify(from ? {trainee: name, from_snapshot: from}
      : {trainee: name}), r);
    answers.started[r] = res;
    box("trainee-name")?.setAttribute("aria-invalid", String(res.verdict === "invalid"));
    const input = box("trainee-name");
    if (res.verdict === "accepted" && input) input.value = "";
    await loadSessions(r);
    return res;
  };
  return html`<section class="card" id="trainee-card"><h2>Trainee</h2>
    <p class="now" id="session-now" data-session=${s?.id ?? nothing}>${s
    ? html`Now: <b>${traineeWords(s)}</b> <small title=${`session ${s.id}`}>in the session begun ${sessionName(s.id)}</small>`
    : "The running session is not known yet."}</p>
    <p class="help">A new trainee's session ends the running one: the twin starts again, every injected fault
      cleared, and the plots, the event log and the journal start empty. Each session is kept apart for the debrief.</p>
    <div class="row"><label>Trainee or crew <small>letters, digits, spaces, - _ . ' &amp;</small>
        <input type="text" id="trainee-name" required maxlength="64" placeholder="Ana Silva"></label>
      <label>Start from <select id="trainee-from"><option value="">the rover file (a fresh rover)</option>${snaps?.ok
        ? snaps.data.map((x) => html`<option value=${x.name}>snapshot ${x.name} (sim time ${clockText(x.t_s)})</option>`)
        : nothing}</select></label>
      ${actionButton({action: "session-start", label: "New trainee", rover: r, cls: "primary", run: start})}</div>
    ${said(answers.started[r])}</section>`;
}

/** Whether the sessions voided are listed too (greyed, with Restore). */
let showVoided = false;

/**
 * Void, restore or rename a session (the console's note: the journal keeps it as it began).
 * @param {string} r @param {SessionInfo} x @param {"void" | "restore" | "rename"} action
 */
async function noteSession(r, x, action) {
  const who = x.trainee || "no trainee named";
  /** @type {Record<string, unknown>} */
  const body = {action};
  if (action === "rename") {
    const name = prompt(`A new name for the session of ${who} begun ${sessionName(x.id)} (the journal and the recordings keep "${
      x.journal_trainee ?? x.trainee}"):`, x.trainee);
    if (name === null || name.trim() === x.trainee) return;
    const why = traineeProblem(name.trim());
    if (!name.trim() || why) {
      answer("invalid", `not renamed: ${why || "type a name"}`);
      return;
    }
    body.trainee = name.trim();
  } else if (action === "void" && !confirm(`Void the session of ${who} begun ${sessionName(x.id)}? It is left out of the `
    + "day's list and of the debrief's choice of trainee; the journal and the recordings keep it, and Restore brings it back.")) {
    return;
  }
  await post(`/api/rovers/${encodeURIComponent(r)}/sessions/${encodeURIComponent(x.id)}`, body);
  await loadSessions(r);
}

/** @param {Result<SessionInfo[]> | undefined} res @param {string} r */
function sessionList(res, r) {
  if (res === undefined) return html`<p>Asking the journal…</p>`;
  if (!res.ok) return html`<p class="error">No list: ${plainMessage(res.message)}</p>`;
  if (!res.data.length) return html`<p>No session in the journal yet.</p>`;
  const running = runningSession(r)?.id, may = mayAct();
  const voided = res.data.filter((x) => x.void).length;
  const shown = [...res.data].reverse().filter((x) => showVoided || !x.void);
  return html`<table><tr><th>trainee</th><th>began on</th><th class="num">sim start</th><th class="num">sim end</th>
    <th class="num">events</th>${may ? html`<th></th>` : nothing}</tr>${shown.map((x) => html`<tr data-session=${x.id}
      data-trainee=${x.trainee} data-void=${x.void ? "true" : nothing} class=${x.void ? "void" : x.end_t_s === null ? "running" : ""}>
    <td class="wrap">${x.trainee || "(no trainee named)"}${x.void ? html` <b>(void)</b>` : nothing}${
      x.journal_trainee !== undefined && x.journal_trainee !== x.trainee
        ? html` <small class="renamed">(began as ${x.journal_trainee || "no trainee named"})</small>` : nothing}<br><small
      title="what lunaris report --session takes">${x.id}${x.from_snapshot ? ` · from snapshot ${x.from_snapshot}` : ""}</small></td>
    <td>${x.started_wall === null ? sessionName(x.id) : dayTime(x.started_wall)}</td>
    <td class="num">${clockText(x.start_t_s)}</td>
    <td class="num">${x.end_t_s === null ? html`<b>${x.id === running ? "running" : "not ended"}</b>` : clockText(x.end_t_s)}</td>
    <td class="num">${x.events ?? 0}</td>${may ? html`<td class="end"><button type="button" class="act" data-action="session-rename"
      @click=${() => noteSession(r, x, "rename")}>Rename</button> ${x.void
      ? html`<button type="button" class="act" data-action="session-restore" @click=${() => noteSession(r, x, "restore")}>Restore</button>`
      : html`<button type="button" class="act" data-action="session-void" @click=${() => noteSession(r, x, "void")}>Void</button>`}</td>`
    : nothing}</tr>`)}</table>
    ${voided ? html`<p class="help"><label><input type="checkbox" id="sessions-show-void" ?checked=${showVoided}
      @change=${(/** @type {Event} */ e) => { showVoided = /** @type {HTMLInputElement} */ (e.target).checked; changed(); }}>
      show the ${voided} session(s) voided</label> (a retry, a false start: left out of the list and of the debrief's choice,
      kept in the journal)</p>` : nothing}`;
}

/** @param {string} r */
function sessionsCard(r) {
  return html`<section class="card"><h2><span>Sessions <small>newest first</small></span> <button type="button" class="act"
      id="sessions-refresh" @click=${() => loadSessions(r)}>Refresh</button></h2>
    <div id="sessions">${sessionList(answers.sessions[r], r)}</div></section>`;
}

export const session = {
  name: "session",
  label: "Session",
  /** @param {{rover: string}} ctx */
  render: ({rover}) => html`<div class="grid two">
    <div class="col">${traineeCard(rover)}${sessionsCard(rover)}${clockCard(rover)}${resetCard(rover)}
      ${predictionCard(rover)}</div>
    <div class="col">${snapshotsCard(rover)}${eventsCard(rover)}</div></div>`,
  /** @param {{rover: string}} ctx */
  enter: ({rover}) => Promise.all([loadSnapshots(rover), loadSessions(rover)]),
  /** @param {{rover: string}} ctx the list again when the session changes, and every SESSIONS_S */
  tick: ({rover}) => {
    const last = listed[rover];
    if (!last || last.id !== (runningSession(rover)?.id ?? "") || Date.now() - last.at > SESSIONS_S * 1000) loadSessions(rover);
  },
};
