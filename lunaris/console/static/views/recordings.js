// Recordings: Start / Stop a recording of the session (MCAP), the list of recordings, each
// with its debrief report and its file to download (for Foxglove or PlotJuggler).

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {answer, post, query} from "../api.js";
import {dur, nameProblem, num, wallTime} from "../format.js";
import {changed, mayAct} from "../state.js";

/**
 * `GET /api/recordings`.
 * @typedef {{name: string, bytes: number, modified: number, report: boolean, download?: string,
 *   report_url?: string}} RecordingInfo
 * @typedef {{file: string | null, running?: boolean, started?: number, lines?: string[]}} Recording
 * @typedef {{recordings: RecordingInfo[], recording: Recording, folder: string | null}} Recordings
 */

/** @type {{ok: true, data: Recordings} | {ok: false, message: string} | null} */
let listed = null;
/** The name offered for a new recording: the time the view was opened. */
let offered = "";

async function load() {
  listed = await query("/api/recordings");
  changed();
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
  return html`<table class="recordings"><tr><th>recording</th><th class="num">size</th><th>made</th><th></th></tr>${r.recordings.map((x) => {
    const file = x.download ?? `/recordings/${encodeURIComponent(x.name)}`;
    const report = x.report_url ?? `${file}/report`;
    return html`<tr data-recording=${x.name}><td class="wrap">${x.name}</td><td class="num">${(x.bytes / 1e6).toFixed(1)} MB</td>
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
      </section></div></div>`;
  },
  enter: () => {
    offered = `session-${new Date().toISOString().slice(0, 16).replace(/[-:T]/g, "")}`;
    return load();
  },
  tick: () => (listed?.ok && listed.data.recording.running ? load() : undefined),
};
