// Recordings: Start / Stop a recording of the session (MCAP), the list of recordings, each
// with its trainees' sessions, its debrief report and its file to download (for Foxglove or
// PlotJuggler); the debrief of one trainee's session, picked by recording and trainee, opened
// in the view (it takes seconds to draw the first time: the view says it is being prepared).

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {answer, post, query} from "../api.js";
import {dayTime, dur, nameProblem, num, plainMessage, sessionName, wallTime} from "../format.js";
import {changed, mayAct} from "../state.js";

/**
 * `GET /api/recordings`.
 * A session of a recording, with the console's notes laid over (void, renamed: session_notes.py).
 * @typedef {{id: string, trainee: string | null, rover: string, start_t_s: number | null,
 *   end_t_s: number | null, faults: number, void?: boolean, journal_trainee?: string | null}} RecordedSession
 * @typedef {{name: string, bytes: number, modified: number, report: boolean, download?: string,
 *   report_url?: string, sessions?: RecordedSession[] | null, sessions_url?: string}} RecordingInfo
 * @typedef {{file: string | null, running?: boolean, started?: number, lines?: string[]}} Recording
 * @typedef {{recordings: RecordingInfo[], recording: Recording, folder: string | null}} Recordings
 */

/** @type {{ok: true, data: Recordings} | {ok: false, message: string} | null} */
let listed = null;
/** The name offered for a new recording: the time the view was opened. */
let offered = "";
/** The sessions of each recording as the console read them, by recording ("reading" meanwhile). */
const sessions = /** @type {Record<string, RecordedSession[] | "reading" | {message: string}>} */ ({});
/** The recording and the session the instructor picked for the debrief ("" for the last). */
const picked = {name: "", session: ""};
/**
 * The debrief opened in the view: being prepared (since when, ms), shown, or why not.
 * @type {{name: string, session: string, who: string, url: string, state: "preparing" | "shown" | "failed",
 *   since: number, message?: string} | null}
 */
let debrief = null;

async function load() {
  listed = await query("/api/recordings");
  changed();
  if (!listed.ok) return;
  for (const x of listed.data.recordings) {
    if (x.sessions) sessions[x.name] = x.sessions;
  }
  // the others read one after the other (each is a `lunaris report` run: seconds for an hour)
  for (const x of listed.data.recordings) {
    if (sessions[x.name] !== undefined || x.name === listed.data.recording.file && listed.data.recording.running) continue;
    sessions[x.name] = "reading";
    changed();
    /** @type {{ok: true, data: {sessions: RecordedSession[]}} | {ok: false, message: string}} */
    const got = await query(x.sessions_url ?? `/api/recordings/${encodeURIComponent(x.name)}/sessions`);
    sessions[x.name] = got.ok ? got.data.sessions : {message: got.message};
    changed();
  }
}

/** @param {RecordedSession} s a session as the instructor names it: its trainee and when it began */
const sessionWords = (s) => `${s.trainee || "no trainee named"} (${s.id ? sessionName(s.id) : "before sessions"}${
  s.end_t_s !== null && s.start_t_s !== null ? `, ${dur(s.end_t_s - s.start_t_s)}` : ""})`;

/** @param {string} name the trainees of a recording, in the order their sessions began */
function trainees(name) {
  const got = sessions[name];
  if (got === undefined) return html`<small class="muted">–</small>`;
  if (got === "reading") return html`<small class="muted">reading the sessions…</small>`;
  if (!Array.isArray(got)) return html`<small class="error">${plainMessage(got.message)}</small>`;
  const kept = got.filter((s) => !s.void), voided = got.length - kept.length;
  if (!kept.length) return html`<small class="muted">no trainee session${voided ? ` (${voided} voided)` : ""}</small>`;
  return html`${kept.map((s, i) => html`${i ? ", " : ""}<span data-trainee=${s.trainee ?? ""} title=${
    `session ${s.id}`}>${s.trainee || "no trainee named"}</span>`)}${voided
    ? html` <small class="muted">(${voided} voided)</small>` : nothing}`;
}

/**
 * Open the debrief of a session: asked of the console (it draws it, seconds the first time),
 * the view saying it is being prepared meanwhile, then shown in the view.
 * @param {string} name the recording @param {string} session its session's id ("" for the last)
 */
async function openDebrief(name, session) {
  const got = sessions[name], s = Array.isArray(got) ? got.find((x) => x.id === session) : undefined;
  const who = s ? `${s.trainee || "no trainee named"}'s session` : "the last session";
  const url = `/recordings/${encodeURIComponent(name)}/report${session ? `?session=${encodeURIComponent(session)}` : ""}`;
  const mine = {name, session, who, url, state: /** @type {"preparing" | "shown" | "failed"} */ ("preparing"),
                since: Date.now(), message: ""};
  debrief = mine;
  changed();
  try {
    const res = await fetch(url);
    if (!res.ok) {
      const said = await res.json().catch(() => ({message: res.statusText}));
      mine.state = "failed";
      mine.message = String(said.message ?? res.statusText);
    } else {
      mine.state = "shown";  // drawn and kept: the frame below loads it at once
    }
  } catch (err) {
    mine.state = "failed";
    mine.message = `the console did not answer (${err})`;
  }
  if (debrief === mine) changed();
}

/** @param {RecordingInfo[]} saved the debrief card: pick a recording and a trainee's session, open its debrief */
function debriefCard(saved) {
  const ready = saved.filter((x) => !(listed?.ok && listed.data.recording.running && listed.data.recording.file === x.name));
  const name = ready.some((x) => x.name === picked.name) ? picked.name : (ready[0]?.name ?? "");
  const got = sessions[name], list = Array.isArray(got) ? got.filter((x) => !x.void) : [];
  const session = list.some((x) => x.id === picked.session) ? picked.session : (list.at(-1)?.id ?? "");
  const d = debrief;
  /** @param {Event} e */
  const pickRecording = (e) => {
    picked.name = /** @type {HTMLSelectElement} */ (e.target).value;
    picked.session = "";
    changed();
  };
  /** @param {Event} e */
  const pickSession = (e) => {
    picked.session = /** @type {HTMLSelectElement} */ (e.target).value;
    changed();
  };
  return html`<section class="card" id="debrief-card"><h2>Debrief</h2>
    <p class="help">The report of one trainee's session: what happened on a timeline (the faults, the crew's actions,
      your marks), how the crew responded to each fault, and the rover's battery, power and radio links.</p>
    ${ready.length ? html`<div class="row"><label>Recording<select id="debrief-recording" @change=${pickRecording}>${
      ready.map((x) => html`<option value=${x.name} ?selected=${x.name === name}>${x.name} (${dayTime(x.modified)})</option>`)}
      </select></label>
      <label>Trainee<select id="debrief-session" @change=${pickSession} ?disabled=${!list.length}>${list.length
        ? [...list].reverse().map((s) => html`<option value=${s.id} ?selected=${s.id === session}>${sessionWords(s)}</option>`)
        : html`<option value="">${got === "reading" ? "reading the sessions…" : "the last session"}</option>`}</select></label>
      <button type="button" class="primary" id="debrief-open" ?disabled=${d?.state === "preparing"}
        @click=${() => openDebrief(name, session)}>Open the debrief</button></div>`
    : html`<p>No recording to debrief yet.</p>`}
    ${d === null ? nothing : d.state === "preparing"
    ? html`<p class="preparing" id="debrief-preparing" role="status"><span class="spinner"></span>Preparing the report of
        ${d.who} in ${d.name}… ${dur((Date.now() - d.since) / 1000)} so far: the first time, drawing it takes a few
        seconds.</p>`
    : d.state === "failed" ? html`<p class="error" id="debrief-failed">No report of ${d.who} in ${d.name}: ${
      plainMessage(d.message ?? "")}</p>`
      : html`<p id="debrief-shown">The debrief of ${d.who} in ${d.name} <a href=${d.url} target="_blank"
          rel="noopener" data-link="debrief">open it in a tab of its own</a> (to print or keep).</p>
        <iframe id="debrief-frame" class="debrief" title=${`debrief of ${d.who}`} src=${d.url}></iframe>`}</section>`;
}

/** @param {string} name a recording under this name, once the name is one the console takes */
function start(name) {
  const wrong = nameProblem(name.trim().replace(/\.mcap$/, ""), "recording", 80);
  if (wrong) {
    answer("invalid", wrong);
    return undefined;
  }
  return record({name: name.trim()});
}

/** @param {Record<string, unknown>} body */
async function record(body) {
  await post("/api/recordings", body);
  await load();
}

/** @param {Recordings} r */
function list(r) {
  if (!r.recordings.length) return html`<p>No recording yet in ${r.folder ?? "the console's folder"}.</p>`;
  const now = r.recording.running ? r.recording.file : null;
  return html`<table class="recordings"><tr><th>recording</th><th>trainees</th><th class="num">size</th><th>made</th><th></th></tr>${r.recordings.map((x) => {
    const file = x.download ?? `/recordings/${encodeURIComponent(x.name)}`;
    const report = x.report_url ?? `${file}/report`;
    return html`<tr data-recording=${x.name}><td class="wrap">${x.name}</td><td class="wrap trainees">${trainees(x.name)}</td><td class="num">${(x.bytes / 1e6).toFixed(1)} MB</td>
      <td>${wallTime(x.modified)}</td>
      <td class="links">${x.name === now ? html`<small>being recorded: stop it to save it</small>` : html`<a href=${report}
        target="_blank" rel="noopener" data-link="report">Open the report</a>
        <a href=${file} download=${x.name} data-link="download" title="open in Foxglove or PlotJuggler">Download
          (MCAP)</a>`}</td></tr>`;
  })}</table>
  <p class="help">A downloaded recording opens in Foxglove or PlotJuggler: every value and event of the twin, in time.</p>`;
}

/** @param {string[]} lines the recorder's last lines @returns {{count: number, mb: number} | null} its progress */
function counted(lines) {
  for (const line of [...lines].reverse()) {
    const m = /(\d+) messages on \d+ channels[^;]*?(?:, ([\d.]+) MB|; ([\d.]+) MB)/.exec(line);
    if (m) return {count: Number(m[1]), mb: Number(m[2] ?? m[3])};
  }
  return null;
}

/** @param {Recording} rec @param {RecordingInfo[]} saved what is being (or was) recorded, in words */
function status(rec, saved) {
  if (!rec.file) return nothing;
  const lines = rec.lines ?? [], got = counted(lines);
  if (rec.running) {
    return html`<p><b>Recording</b> to ${rec.file} for ${dur(Date.now() / 1000 - (rec.started ?? 0))}${got
      ? `: ${num(got.count)} values and events so far (${got.mb.toFixed(1)} MB).` : ": starting…"}</p>`;
  }
  const file = saved.find((x) => x.name === rec.file);
  if (file) {
    return html`<p><b>Saved</b> ${rec.file}${got ? `: ${num(got.count)} values and events` : ""}, ${
      (file.bytes / 1e6).toFixed(1)} MB. Its report opens from the list.</p>`;
  }
  const last = [...lines].reverse().find((l) => l.trim()) ?? "";
  return html`<p class="error">The recording ${rec.file} stopped without saving: ${
    last.replace(/^lunaris [\w ]+: /, "") || "no reason given"}.</p>`;
}

/**
 * The offered name selected when the box is entered: typing replaces it (it was appended to).
 * @param {FocusEvent} e
 */
const selectAll = (e) => /** @type {HTMLInputElement} */ (e.target).select();

export const recordings = {
  name: "recordings",
  label: "Recordings",
  render: () => {
    const r = listed?.ok ? listed.data : null, rec = r?.recording ?? {file: null}, may = mayAct();
    const name = () => /** @type {HTMLInputElement | null} */ (document.getElementById("rec-name"))?.value ?? "";
    return html`<div class="grid two"><div class="col"><section class="card"><h2>Record the session</h2>
        <p class="help">Records every value and event of the twin for the debrief. Each recording has a report
          (plots and the event log) that opens here; the recording itself is an MCAP file in the console's folder${
          r?.folder ? html` (<code>${r.folder}</code>)` : nothing}, to download from the list and open in Foxglove or
          PlotJuggler.</p>
        <div class="row"><label>Name<input type="text" id="rec-name" value=${offered}
          @focus=${selectAll}></label>
          <button type="button" class="primary" id="rec-start" ?disabled=${!r || !!rec.running || !may}
            @click=${() => start(name())}>Start recording</button>
          <button type="button" class="danger" id="rec-stop" ?disabled=${!rec.running || !may}
            @click=${() => record({action: "stop"})}>Stop</button></div>
        <div id="rec-status">${status(rec, r?.recordings ?? [])}</div></section></div>
      <div class="col"><section class="card"><h2>Recordings <button type="button" class="act" id="rec-refresh"
          @click=${load}>Refresh</button></h2>
        <div id="rec-list">${!listed ? "loading…" : listed.ok ? list(listed.data) : html`<p class="error">${listed.message}</p>`}</div>
      </section></div></div>${r ? debriefCard(r.recordings) : nothing}`;
  },
  enter: () => {
    offered = `session-${new Date().toISOString().slice(0, 16).replace(/[-:T]/g, "")}`;
    return load();
  },
  tick: () => {
    if (debrief?.state === "preparing") changed();  // the seconds it has taken so far
    return listed?.ok && listed.data.recording.running ? load() : undefined;
  },
};
