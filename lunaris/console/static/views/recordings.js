// Recordings: Start / Stop a recording of the session (MCAP), the list of recordings, each
// with its debrief report.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {post, query} from "../api.js";
import {dur, wallTime} from "../format.js";
import {changed, mayAct} from "../state.js";

/**
 * `GET /api/recordings`.
 * @typedef {{name: string, bytes: number, modified: number, report: boolean}} RecordingInfo
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

/** @param {Record<string, unknown>} body */
async function record(body) {
  await post("/api/recordings", body);
  await load();
}

/** @param {Recordings} r */
function list(r) {
  if (!r.recordings.length) return html`<p>No recording yet in ${r.folder ?? "the console's folder"}.</p>`;
  return html`<table><tr><th>recording</th><th class="num">size</th><th>made</th><th></th></tr>${r.recordings.map((x) => html`<tr>
    <td>${x.name}</td><td class="num">${(x.bytes / 1e6).toFixed(1)} MB</td><td>${wallTime(x.modified)}</td>
    <td><a href=${`/recordings/${encodeURIComponent(x.name)}/report`} target="_blank" rel="noopener">Open the report</a></td>
  </tr>`)}</table>`;
}

/** @param {Recording} rec */
function status(rec) {
  if (!rec.file) return nothing;
  return html`<p>${rec.running ? html`<b>Recording</b> to ${rec.file} for ${dur(Date.now() / 1000 - (rec.started ?? 0))}`
                               : `Last: ${rec.file}`}</p><div class="log">${(rec.lines ?? []).join("\n")}</div>`;
}

export const recordings = {
  name: "recordings",
  label: "Recordings",
  render: () => {
    const r = listed?.ok ? listed.data : null, rec = r?.recording ?? {file: null}, may = mayAct();
    const name = () => /** @type {HTMLInputElement | null} */ (document.getElementById("rec-name"))?.value ?? "";
    return html`<div class="grid two"><div class="col"><section class="card"><h2>Record the session</h2>
        <p class="help">Records every value and event of the twin for the debrief (MCAP: also opens in Foxglove and
          PlotJuggler).</p>
        <div class="row"><label>Name<input type="text" id="rec-name" value=${offered}></label>
          <button type="button" class="primary" id="rec-start" ?disabled=${!r || !!rec.running || !may}
            @click=${() => record({name: name()})}>Start recording</button>
          <button type="button" class="danger" id="rec-stop" ?disabled=${!rec.running || !may}
            @click=${() => record({action: "stop"})}>Stop</button></div>
        <div id="rec-status">${status(rec)}</div></section></div>
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
