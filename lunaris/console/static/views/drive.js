// The map's drive panel: load a shipped traverse (`GET /api/traverses?rover=`, its plan from
// where the rover is in words, sent with `POST /api/rovers/<rover>/traverse`), or enter
// waypoints by hand (a small table, or a click on the map; sent on `input/drive/traverse`),
// and stop the rover. What would be sent is previewed on the map (`preview`) until it is sent;
// then the map draws the route the drive follows (`drive/route`).

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {answer, post, query, send} from "../api.js";
import {dur, num, plainMessage} from "../format.js";
import {changed, drive, mayAct, redraw, route, umbilical} from "../state.js";
import {actionButton, field} from "../widgets.js";

/** @typedef {{x_m: number, y_m: number, z_m: number, speed_m_per_s?: number | null}} Point */

/**
 * `GET /api/traverses?rover=ID` (lunaris/console/drive.py).
 * @typedef {{rover: string, from: string, length_m: number | null, duration_s: number | null,
 *   problems: string[]}} Plan
 * @typedef {{file: string, folder: string, name?: string, description?: string,
 *   speed_m_per_s?: number | null, return_to_start?: boolean, waypoints?: Point[], problems: string[],
 *   plan?: Plan}} TraverseInfo
 * @typedef {{traverses: TraverseInfo[], folders: string[], plan_missing?: string}} Traverses
 */

/** A waypoint typed by hand: the text of its boxes (empty: not given). */
/** @typedef {{x: string, y: string, z: string}} Row */

/** The panel's state, by rover: what is chosen and typed survives a redraw and a change of view. */
const panels = /** @type {Record<string, Panel>} */ ({});

/**
 * @typedef {{mode: "file" | "hand", listed: {ok: true, data: Traverses} | {ok: false, message: string} | null,
 *   file: string, speed: string, back: boolean | null, rows: Row[], handSpeed: string, handBack: boolean,
 *   sent: boolean, touched: boolean, loading: boolean}} Panel
 */

/** @param {string} rover @returns {Panel} */
function panel(rover) {
  return (panels[rover] ||= {mode: "file", listed: null, file: "", speed: "", back: null,
                              rows: [], handSpeed: "", handBack: false, sent: false, touched: false,
                              loading: false});
}

/** @param {Panel} p the instructor changed what would be sent: it is previewed again */
function edited(p) {
  p.sent = false;
  p.touched = true;
}

/** @param {string} rover the traverse files, with their plans from where the rover is now */
export async function loadTraverses(rover) {
  const p = panel(rover);
  if (p.loading) return;
  p.loading = true;
  try {
    p.listed = await query(`/api/traverses?rover=${encodeURIComponent(rover)}`);
  } finally {
    p.loading = false;
  }
  const offered = p.listed.ok ? p.listed.data.traverses.filter((t) => !t.problems.length) : [];
  if (!offered.some((t) => t.file === p.file)) {
    p.file = (offered.find((t) => !t.plan?.problems.length) ?? offered[0])?.file ?? "";
  }
  changed();
}

// -- the numbers of a plan, as the page works them out for a preview ---------------------------

/** @param {string} text @returns {number | null} a number typed, or null (empty or not a number) */
function typed(text) {
  const t = text.trim();
  if (t === "") return null;
  const v = Number(t);
  return Number.isFinite(v) ? v : null;
}

/**
 * The points driven through, in order, from `from`: the waypoints and, when the traverse comes
 * back, the same waypoints in reverse and `from` again (as the drive plans it).
 * @param {Point} from @param {Point[]} waypoints @param {boolean} back
 * @returns {Point[]}
 */
export function pathOf(from, waypoints, back) {
  const out = [from, ...waypoints];
  if (back && waypoints.length) out.push(...waypoints.slice(0, -1).reverse(), from);
  return out;
}

/**
 * The length along the ground [m] and the duration [s] (null when a leg's speed is not known
 * here: the rover's top speed) of waypoints driven from `from`.
 * @param {Point} from @param {Point[]} waypoints @param {number | null} speed the traverse's
 * @param {boolean} back
 */
export function lengthAndDuration(from, waypoints, speed, back) {
  const speeds = waypoints.map((w) => w.speed_m_per_s ?? speed);
  const legs = waypoints.map((w, i) => ({to: w, v: speeds[i]}));
  if (back) {
    for (let j = waypoints.length - 1; j >= 0; j--) legs.push({to: j > 0 ? waypoints[j - 1] : from, v: speeds[j]});
  }
  let here = from, length = 0, duration = /** @type {number | null} */ (0);
  for (const leg of legs) {
    const d = Math.hypot(leg.to.x_m - here.x_m, leg.to.y_m - here.y_m, leg.to.z_m - here.z_m);
    length += d;
    duration = duration === null || leg.v === null || leg.v <= 0 ? null : duration + d / leg.v;
    here = leg.to;
  }
  return {length, duration};
}

/** @param {number} m a distance as a person says it: "8.5 m", "340 m", "6.8 km" */
export function metres(m) {
  const km = m / 1000;
  if (m >= 1000) return `${num(km, m >= 10000 || Number.isInteger(km) ? 0 : 1)} km`;
  return m < 10 && !Number.isInteger(m) ? `${num(m, 1)} m` : `${num(m)} m`;
}

/**
 * A plan in words: "340 m there and back, about 57 min at 0.1 m/s".
 * @param {number | null} length @param {number | null} duration @param {number | null} speed @param {boolean} back
 */
function planWords(length, duration, speed, back) {
  if (length === null) return "";
  const how = back ? " there and back" : "";
  const time = duration === null ? ", at the rover's top speed" : `, about ${dur(duration)}`;
  return `${metres(length)}${how}${time}${speed !== null ? ` at ${num(speed, 2)} m/s` : ""}`;
}

/** @param {string} rover @returns {Point | null} where the rover is (site frame) */
function here(rover) {
  const d = drive(rover);
  return d ? {x_m: d.x_m, y_m: d.y_m, z_m: d.z_m} : null;
}

// -- what is previewed on the map --------------------------------------------------------------

/**
 * @typedef {{waypoints: Point[], back: boolean, what: string, problems: string[]}} Preview
 */

/** @param {string} rover @returns {TraverseInfo | undefined} the traverse file chosen */
function chosen(rover) {
  const p = panel(rover);
  return p.listed?.ok ? p.listed.data.traverses.find((t) => t.file === p.file && !t.problems.length) : undefined;
}

/**
 * The waypoints typed by hand, and what is wrong with them, in words.
 * @param {Panel} p @param {Point | null} from
 * @returns {{waypoints: Point[], problems: string[]}}
 */
function handWaypoints(p, from) {
  /** @type {Point[]} */
  const out = [];
  /** @type {string[]} */
  const problems = [];
  for (const [i, row] of p.rows.entries()) {
    const x = typed(row.x), y = typed(row.y), z = typed(row.z);
    if (x === null || y === null) {
      problems.push(`waypoint ${i + 1}: give how far east and north of the site's origin it is, in metres`);
      continue;
    }
    out.push({x_m: x, y_m: y, z_m: z ?? out[out.length - 1]?.z_m ?? from?.z_m ?? 0});
  }
  if (!p.rows.length) problems.push("add a waypoint first (or click on the map)");
  return {waypoints: out, problems};
}

/**
 * What the panel would send, to draw on the map before it is sent (null: nothing to show, or
 * just sent: the map then shows the drive's own route).
 * @param {string} rover
 * @returns {Preview | null}
 */
export function preview(rover) {
  const p = panel(rover), from = here(rover);
  // Just sent, or nothing chosen yet while the map shows a route: the route, alone.
  if (p.sent || !from || (!p.touched && route(rover)?.waypoints.length)) return null;
  if (p.mode === "file") {
    const t = chosen(rover);
    if (!t?.waypoints?.length) return null;
    return {waypoints: t.waypoints, back: p.back ?? !!t.return_to_start, what: t.name ?? t.file,
            problems: t.plan?.problems ?? []};
  }
  const {waypoints, problems} = handWaypoints(p, from);
  if (!waypoints.length) return null;
  return {waypoints, back: p.handBack, what: "the waypoints typed", problems};
}

/** @param {string} rover @returns {boolean} a click on the map adds a waypoint */
export const clicksAddWaypoints = (rover) => panel(rover).mode === "hand" && mayAct();

/**
 * A waypoint where the instructor clicked on the map (hand mode).
 * @param {string} rover @param {number} x @param {number} y site frame [m]
 */
export function addWaypoint(rover, x, y) {
  const p = panel(rover);
  const z = typed(p.rows[p.rows.length - 1]?.z ?? "") ?? drive(rover)?.z_m ?? 0;
  p.rows.push({x: String(x), y: String(y), z: String(Math.round(z * 10) / 10)});
  edited(p);
  redraw();
}

// -- sending ----------------------------------------------------------------------------------

/** @param {string} rover */
async function sendFile(rover) {
  const p = panel(rover), t = chosen(rover);
  if (!t) return undefined;
  /** @type {Record<string, unknown>} */
  const body = {file: t.file};
  const speed = typed(p.speed);
  if (speed !== null) body.speed_m_per_s = speed;
  if (p.back !== null) body.return_to_start = p.back;
  const res = await post(`/api/rovers/${encodeURIComponent(rover)}/traverse`, body);
  if (res.verdict === "accepted") [p.sent, p.touched] = [true, false];
  await loadTraverses(rover);
  return res;
}

/** @param {string} rover */
async function sendHand(rover) {
  const p = panel(rover), {waypoints, problems} = handWaypoints(p, here(rover));
  if (problems.length) {
    answer("invalid", `${problems.join("; ")}: nothing sent`);
    return undefined;
  }
  const speed = typed(p.handSpeed);
  const res = await send("PUT", "input/drive/traverse", JSON.stringify({
    waypoints: waypoints.map(({x_m, y_m, z_m}) => ({x_m, y_m, z_m})), speed_m_per_s: speed,
    return_to_start: p.handBack}), rover);
  if (res.verdict === "accepted") [p.sent, p.touched] = [true, false];
  return res;
}

// -- the panel --------------------------------------------------------------------------------

/** @param {string} rover @param {Panel} p the choice of a traverse file, its words and Send */
function fileForm(rover, p) {
  const listed = p.listed;
  if (!listed) return html`<p class="help">Loading the traverse files…</p>`;
  if (!listed.ok) return html`<p class="error">No traverse files: ${plainMessage(listed.message)}</p>`;
  const all = listed.data.traverses, good = all.filter((t) => !t.problems.length), t = chosen(rover);
  const from = here(rover);
  /** @param {Event} ev */
  const pick = (ev) => {
    p.file = /** @type {HTMLSelectElement} */ (ev.target).value;
    p.speed = "";
    p.back = null;
    edited(p);
    redraw();
  };
  const speed = typed(p.speed), back = p.back ?? !!t?.return_to_start;
  const changedByHand = speed !== null || p.back !== null;
  let said = "";
  /** @type {string[]} */
  let problems = [];
  if (t && from) {
    if (!changedByHand && t.plan) {
      said = planWords(t.plan.length_m, t.plan.duration_s, t.speed_m_per_s ?? null, back);
      problems = t.plan.problems;
    } else {
      const {length, duration} = lengthAndDuration(from, t.waypoints ?? [], speed ?? t.speed_m_per_s ?? null, back);
      said = planWords(length, duration, speed ?? t.speed_m_per_s ?? null, back);
    }
  }
  return html`
    <div class="row"><label>Traverse file <select id="tr-file" @change=${pick}>${good.map((x) => html`<option
        value=${x.file} .selected=${x.file === p.file}>${x.name ?? x.file}</option>`)}</select></label></div>
    ${t ? html`<p id="tr-about"><b>${t.name}</b>: ${t.description} <small>(${t.file}, ${t.waypoints?.length ?? 0}
        waypoints)</small></p>
      <p id="tr-plan" class=${problems.length ? "error" : ""}>${said ? html`If sent now, from where the rover is: <b>${said}</b>.` : nothing}
        ${problems.length ? html`<br>The drive would refuse it as the file is: ${problems.map((x) => plainMessage(x)).join("; ")}.`
          : nothing}${!t.plan && listed.data.plan_missing ? html`<br><small>${plainMessage(listed.data.plan_missing)}</small>`
          : nothing}</p>` : html`<p class="help">No traverse file to offer.</p>`}
    <div class="row"><label>speed [m/s] <small>${t?.speed_m_per_s ? `file: ${t.speed_m_per_s}` : "file: top speed"}</small>
        <input type="number" id="tr-file-speed" min="0" step="0.01" .value=${p.speed}
        placeholder=${t?.speed_m_per_s ? String(t.speed_m_per_s) : "top speed"}
        @input=${(/** @type {Event} */ ev) => { p.speed = /** @type {HTMLInputElement} */ (ev.target).value; edited(p); changed(); }}></label>
      <label class="check"><input type="checkbox" id="tr-file-back" .checked=${back}
        @change=${(/** @type {Event} */ ev) => { p.back = /** @type {HTMLInputElement} */ (ev.target).checked; edited(p); changed(); }}>
        and back</label>
      ${actionButton({action: "traverse-send", label: "Send this traverse", rover, cls: "primary",
                      run: () => sendFile(rover)})}</div>
    ${listed.data.traverses.length > good.length ? html`<p class="help">Not offered: ${all.filter((x) => x.problems.length)
      .map((x) => `${x.file} (${x.problems.map((m) => plainMessage(m)).join("; ")})`).join(", ")}.</p>` : nothing}`;
}

/** @param {string} rover @param {Panel} p the waypoints typed by hand, and Send */
function handForm(rover, p) {
  const from = here(rover), {waypoints, problems} = handWaypoints(p, from);
  const speed = typed(p.handSpeed);
  const sum = from && waypoints.length && !problems.length
    ? lengthAndDuration(from, waypoints, speed, p.handBack) : null;
  /** @param {Row} row @param {keyof Row} k @param {string} label */
  const box = (row, k, label) => html`<input type="number" step="any" aria-label=${label} .value=${row[k]}
    @input=${(/** @type {Event} */ ev) => { row[k] = /** @type {HTMLInputElement} */ (ev.target).value; edited(p); changed(); }}>`;
  return html`
    <p class="help">In metres from the site's origin: east, north, and up (height). Click on the map to add one there.</p>
    <table class="waypoints" id="wp-table"><tr><th class="num">#</th><th>east [m]</th><th>north [m]</th><th>up [m]</th><th></th></tr>
      ${p.rows.map((row, i) => html`<tr data-waypoint=${i + 1}><td class="num">${i + 1}</td><td>${box(row, "x", `waypoint ${i + 1} east`)}</td>
        <td>${box(row, "y", `waypoint ${i + 1} north`)}</td><td>${box(row, "z", `waypoint ${i + 1} up`)}</td>
        <td class="end"><button type="button" class="act" data-remove=${i + 1} title="remove this waypoint"
          @click=${() => { p.rows.splice(i, 1); edited(p); redraw(); }}>Remove</button></td></tr>`)}
    </table>
    <div class="row"><button type="button" class="act" id="wp-add" @click=${() => {
        const last = p.rows[p.rows.length - 1];
        const d = drive(rover);
        p.rows.push(last ? {...last} : {x: d ? String(Math.round(d.x_m)) : "0", y: d ? String(Math.round(d.y_m)) : "0",
                                       z: d ? String(Math.round(d.z_m * 10) / 10) : "0"});
        edited(p);
        redraw();
      }}>Add a waypoint</button>
      <label>speed [m/s]<input type="number" id="wp-speed" min="0" step="0.01" placeholder="top speed" .value=${p.handSpeed}
        @input=${(/** @type {Event} */ ev) => { p.handSpeed = /** @type {HTMLInputElement} */ (ev.target).value; edited(p); changed(); }}></label>
      <label class="check"><input type="checkbox" id="wp-back" .checked=${p.handBack}
        @change=${(/** @type {Event} */ ev) => { p.handBack = /** @type {HTMLInputElement} */ (ev.target).checked; edited(p); changed(); }}>
        and back</label></div>
    <p id="wp-plan" class=${problems.length && p.rows.length ? "error" : ""}>${sum
      ? html`If sent now, from where the rover is: <b>${planWords(sum.length, sum.duration, speed, p.handBack)}</b>.`
      : p.rows.length ? `${problems.join("; ")}.` : ""}</p>
    <div class="row">${actionButton({action: "traverse-go", label: "Drive through these waypoints", rover, cls: "primary",
                                     run: () => sendHand(rover)})}</div>`;
}

/** What the drive's status means, in words ("The rover is ..."). */
const STATUS = /** @type {Record<string, string>} */ ({
  parked: "parked", driving: "driving", power_limited: "driving, slowed: its drive is at its power limit",
  unpowered: "halted: its drive has no power", arrived: "at the end of its route"});

/** @param {string} rover what the rover does now, in words */
function nowWords(rover) {
  const d = drive(rover), r = route(rover), u = umbilical(rover);
  if (!d) return nothing;
  const status = d.status ?? (d.moving ? "driving" : "parked");
  const going = r?.waypoints.length && (status === "driving" || status === "power_limited" || status === "unpowered")
    ? html`, ${field(rover, "drive/state", "remaining_m", "m")} to go` : nothing;
  return html`<p id="drive-now">The rover is <b data-status=${status}>${STATUS[status] ?? status.replace(/_/g, " ")}</b>${going}, at
    ${field(rover, "drive/state", "x_m", "m")} east and ${field(rover, "drive/state", "y_m", "m")} north of the origin.
    ${u?.connected ? html`<span class="sev-warning">The umbilical is plugged in${u.cable_m !== null && u.cable_m !== undefined
      ? `: driving farther than ${metres(u.cable_m)} from the plug pulls it out` : ": unplug it before driving"}.</span>` : nothing}</p>`;
}

/**
 * The drive panel of a rover: what it does now, Stop, a traverse file or waypoints by hand.
 * @param {string} rover @param {boolean} drives the rover has a drive
 */
export function drivePanel(rover, drives) {
  if (!drives) {
    return html`<section class="card" id="drive-panel"><h2>Drive</h2><p>This rover has no drive section: it does not
      drive.</p></section>`;
  }
  const p = panel(rover);
  /** @param {"file" | "hand"} mode @param {string} label */
  const tab = (mode, label) => html`<button type="button" class=${p.mode === mode ? "tab on" : "tab"} data-drive-mode=${mode}
    aria-pressed=${p.mode === mode ? "true" : "false"} @click=${() => { p.mode = mode; edited(p); redraw(); }}>${label}</button>`;
  const d = drive(rover);
  return html`<section class="card" id="drive-panel"><h2>Drive ${actionButton({action: "traverse-stop",
      label: "Stop the rover", rover, cls: "danger", run: () => send("DELETE", "input/drive/traverse", undefined, rover)})}</h2>
    ${nowWords(rover)}
    <div class="tabs" role="group" aria-label="how to give the route">${tab("file", "A traverse file")}${tab("hand", "Waypoints by hand")}</div>
    ${p.mode === "file" ? fileForm(rover, p) : handForm(rover, p)}
    <p class="help">${preview(rover) ? "The dashed line on the map is what would be sent." : d && route(rover)?.waypoints.length
      ? "The map shows the route the rover follows." : ""} A new traverse replaces the one being driven.</p></section>`;
}
