// Lunaris console: the page. Live values come over server-sent events (/api/live); every
// action is a write on the twin's keys through the console's HTTP API, answered by the twin.
// Elements that show a twin value carry data-key (under lunaris/<rover>/) and data-field;
// controls carry data-action with data-rover and their target (SPEC 8a).
"use strict";

const S = {
  values: {}, events: {}, services: {}, history: {}, rover: null, view: "live", me: null, cat: null,
  connected: false, shape: "", bound: {}, charts: [], snapshots: [], prediction: null,
  scenarios: null, recordings: null, fetched: {},
};
const $ = (sel, root = document) => root.querySelector(sel);
const esc = (v) => String(v ?? "").replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c]));

// -- formatting --------------------------------------------------------------------------------

function dur(s) {
  if (s === null || s === undefined) return "–";
  if (s >= 3600) return `${Math.floor(s / 3600)} h ${String(Math.floor(s % 3600 / 60)).padStart(2, "0")} min`;
  if (s >= 60) return `${Math.floor(s / 60)} min ${String(Math.floor(s % 60)).padStart(2, "0")} s`;
  return `${s.toFixed(0)} s`;
}
function clockText(t) {
  const h = Math.floor(t / 3600), m = Math.floor(t % 3600 / 60), s = t % 60;
  return `${String(h).padStart(2, "0")}:${String(m).padStart(2, "0")}:${s.toFixed(1).padStart(4, "0")}`;
}
const FMT = {
  pct: (v) => `${(v * 100).toFixed(1)} %`, kj: (v) => `${(v / 1000).toFixed(1)} kJ`,
  v: (v) => `${v.toFixed(2)} V`, a: (v) => `${v.toFixed(2)} A`, w: (v) => `${v.toFixed(1)} W`,
  c: (v) => `${v.toFixed(1)} °C`, dur: dur, deg: (v) => `${v.toFixed(0)}°`, m: (v) => `${v.toFixed(1)} m`,
  mps: (v) => `${v.toFixed(2)} m/s`, frac: (v) => `${(v * 100).toFixed(0)} %`, s: (v) => `${v.toFixed(1)} s`,
  clock: clockText, x: (v) => `×${v}`, range: (v) => (v ? "IN RANGE" : "OUT OF RANGE"),
  onoff: (v) => (v ? "on" : "off"), ok: (v) => (v ? "operational" : "NOT OPERATIONAL"),
  conn: (v) => (v ? "connected" : "unplugged"), list: (v) => (v && v.length ? v.join(", ") : "none"),
  text: (v) => String(v).replace(/_/g, " "), limit: (v) => (v === null ? "–" : v.toFixed(1)),
  num3: (v) => v.toFixed(3), num2: (v) => v.toFixed(2), faults: (v) => (v && v.length ? v.join(", ") : ""),
};
function fmt(value, how) {
  if (value === undefined) return "–";
  if (value === null) return how === "dur" ? "not draining" : "–";
  const f = FMT[how];
  return f ? f(value) : String(value);
}
const key = (rover, tail) => `lunaris/${rover}/${tail}`;
const val = (rover, tail) => S.values[key(rover, tail)];

// -- what a rover has, from its keys -----------------------------------------------------------

function rovers() {
  const set = new Set(Object.keys(S.services));
  for (const k of Object.keys(S.values)) set.add(k.split("/")[1]);
  return [...set].sort();
}
function named(rover, head, tail) {
  const pre = `lunaris/${rover}/${head}/`, out = [];
  for (const k of Object.keys(S.values)) {
    if (k.startsWith(pre) && k.endsWith(`/${tail}`)) {
      const n = k.slice(pre.length, -tail.length - 1);
      if (!n.includes("/")) out.push(n);
    }
  }
  return out.sort();
}
function parts(rover) {
  const rails = named(rover, "rail", "state"), loads = named(rover, "load", "power");
  return {rails, loads, panels: named(rover, "solar", "power"), radios: named(rover, "radio", "link"),
          drive: !!val(rover, "drive/state"), umbilical: !!val(rover, "umbilical/state")};
}
function activeFaults(rover) {
  const pre = `lunaris/${rover}/faults/active/`, out = [];
  for (const [k, v] of Object.entries(S.values)) if (k.startsWith(pre)) out.push(...v.faults);
  return out.sort((a, b) => a.since_t_s - b.since_t_s || a.key.localeCompare(b.key));
}

// -- binding values to elements ------------------------------------------------------------------

function bind() {
  S.bound = {};
  for (const el of document.querySelectorAll("[data-key][data-field]")) {
    (S.bound[el.dataset.key] ||= []).push(el);
  }
  for (const tail of Object.keys(S.bound)) paint(tail);
}
function paint(tail) {
  const v = val(S.rover, tail);
  for (const el of S.bound[tail] || []) {
    const x = v ? v[el.dataset.field] : undefined;
    el.textContent = fmt(x, el.dataset.fmt);
    if (el.dataset.fmt === "text" || el.dataset.state !== undefined) el.className = `st-${x}`;
    if (el.dataset.fmt === "range") el.className = x ? "in" : "out";
  }
}

// -- the live stream -------------------------------------------------------------------------------

function connect() {
  const es = new EventSource("/api/live");
  es.onmessage = (m) => receive(JSON.parse(m.data));
  es.onerror = () => { setLink(false, "reconnecting to the console…"); };
}
function receive(msg) {
  if (msg.type === "link") { S.connected = msg.connected; setLink(msg.connected); return; }
  if (msg.type === "snapshot") {
    S.values = msg.values; S.services = msg.services; S.events = {}; S.history = {};
    for (const [r, h] of Object.entries(msg.history || {})) S.history[r] = h;
    S.connected = msg.connected; setLink(msg.connected);
  } else {
    Object.assign(S.values, msg.values);
    Object.assign(S.services, msg.services);
  }
  const fresh = [];
  for (const e of msg.events) {
    const rover = e.key.split("/")[1];
    (S.events[rover] ||= []).push(e);
    if (S.events[rover].length > 300) S.events[rover].shift();
    if (rover === S.rover) fresh.push(e);
  }
  if (!S.rover || !rovers().includes(S.rover)) S.rover = rovers()[0] || null;
  drawRovers();
  if (!S.rover) return;
  const shape = JSON.stringify([S.rover, S.view, parts(S.rover)]);
  if (msg.type === "snapshot" || shape !== S.shape) { render(); return; }
  const pre = `lunaris/${S.rover}/`;
  let faults = false;
  for (const k of Object.keys(msg.values)) {
    if (!k.startsWith(pre)) continue;
    const tail = k.slice(pre.length);
    if (tail.startsWith("faults/active/")) faults = true; else paint(tail);
  }
  if (faults) drawFaults();
  if (fresh.length) drawEvents();
  drawClock();
}
function setLink(ok, text) {
  const el = $("#link");
  el.className = `link ${ok ? "ok" : "bad"}`;
  el.textContent = text || (ok ? "twin connected" : "twin not reachable: values are the last received");
}

// -- the header --------------------------------------------------------------------------------------

function drawRovers() {
  const nav = $("#rovers");
  nav.innerHTML = rovers().map((r) => {
    const b = val(r, "battery/state"), f = activeFaults(r);
    const crit = f.some((x) => x.severity === "critical");
    const badge = f.length ? `<span class="badge ${crit ? "critical" : ""}" title="active faults">${f.length}</span>` : "";
    return `<button type="button" data-rover-pick="${esc(r)}" class="${r === S.rover ? "on" : ""}">${esc(r)} ` +
      `${b ? fmt(b.soc, "pct") : ""}${badge}</button>`;
  }).join("") || "<span>no rover yet</span>";
}
function drawClock() {
  const c = val(S.rover, "clock"), el = $("#clock");
  if (!c) { el.innerHTML = ""; el.dataset.shape = ""; return; }
  const r = esc(S.rover), shape = `${S.rover}/${c.paused}/${S.me?.may_act}`;
  if (el.dataset.shape !== shape) {  // rebuilt only when it changes: a button must stay put
    el.dataset.shape = shape;
    el.innerHTML = `<span>sim t <b id="clock-t" data-key="clock" data-field="t_s"></b></span>` +
      `<span id="clock-x" data-key="clock" data-field="time_scale"></span>` +
      (c.paused ? `<span class="paused" data-key="clock" data-field="paused">PAUSED</span>` : "") +
      (c.paused ? `<button type="button" class="act" data-action="clock-resume" data-rover="${r}">Resume</button>`
                : `<button type="button" class="act" data-action="clock-pause" data-rover="${r}">Pause</button>`);
    guard(el);
  }
  $("#clock-t").textContent = clockText(c.t_s);
  $("#clock-x").textContent = `×${c.time_scale}`;
}

// -- views ----------------------------------------------------------------------------------------------

function render() {
  if (!S.rover) return;
  S.shape = JSON.stringify([S.rover, S.view, parts(S.rover)]);
  for (const b of document.querySelectorAll("#views button")) b.classList.toggle("on", b.dataset.view === S.view);
  S.charts.forEach((c) => c.destroy()); S.charts = [];
  const main = $("#main");
  main.innerHTML = VIEWS[S.view](S.rover, parts(S.rover));
  main.dataset.rover = S.rover;
  bind(); drawFaults(); drawEvents(); drawClock(); guard(main);
  if (S.view === "live") charts();
  if (S.view === "faults") faultForm();
  if (S.view === "session") { loadSnapshots(); drawPrediction(); }
  if (S.view === "scenarios") loadScenarios();
  if (S.view === "recordings") loadRecordings();
}
function guard(root) {  // an observer's controls are disabled; the server refuses them anyway
  if (S.me && !S.me.may_act) {
    for (const b of root.querySelectorAll("[data-action]")) {
      b.disabled = true; b.title = "observers cannot change the twin";
    }
  }
}
const F = (tail, field, how, extra = "") => `<span data-key="${tail}" data-field="${field}" data-fmt="${how}" ${extra}>–</span>`;
const btn = (action, label, attrs, cls = "act") => `<button type="button" class="${cls}" data-action="${action}" data-rover="${esc(S.rover)}" ${attrs}>${label}</button>`;

function batteryCard() {
  const t = "battery/state";
  return `<section class="card"><h2>Battery</h2>
    <div class="big">${F(t, "soc", "pct")} <small>state of charge</small></div>
    <dl class="kv">
      <dt>energy</dt><dd>${F(t, "energy_j", "kj")} of ${F(t, "capacity_j", "kj")}</dd>
      <dt>voltage</dt><dd>${F(t, "voltage_v", "v")} <small>(open circuit ${F(t, "ocv_v", "v")})</small></dd>
      <dt>current</dt><dd>${F(t, "current_a", "a")} · ${F(t, "power_w", "w")}</dd>
      <dt>temperature</dt><dd>${F(t, "temperature_c", "c")}</dd>
      <dt>time to empty</dt><dd>${F(t, "time_to_empty_s", "dur")}</dd>
      <dt>status</dt><dd>${F(t, "operational", "ok")}</dd>
      <dt>faults</dt><dd>${F(t, "faults", "list")} <small>(code ${F(t, "fault_code", "")})</small></dd>
    </dl></section>`;
}
function powerCard(r, p) {
  const t = "power/summary";
  const panels = p.panels.map((n) => `<tr><td>${esc(n)}</td><td class="num">${F(`solar/${n}/power`, "power_w", "w")}</td>
    <td class="num">${F(`solar/${n}/power`, "sun_angle_deg", "deg")}</td><td class="num">${F(`solar/${n}/power`, "dust", "frac")}</td></tr>`).join("");
  return `<section class="card"><h2>Power</h2><dl class="kv">
      <dt>loads</dt><dd>${F(t, "load_power_w", "w")}</dd><dt>bus draw</dt><dd>${F(t, "bus_power_w", "w")}</dd>
      <dt>generation</dt><dd>${F(t, "generation_w", "w")}</dd><dt>net battery</dt><dd>${F(t, "net_battery_power_w", "w")}</dd>
      <dt>bus voltage</dt><dd>${F(t, "bus_voltage_v", "v")}</dd>
      ${p.umbilical ? `<dt>umbilical</dt><dd>${F("umbilical/state", "connected", "conn")} · ${F("umbilical/state", "power_w", "w")}</dd>` : ""}
    </dl>${p.panels.length ? `<table><tr><th>panel</th><th class="num">power</th><th class="num">sun</th><th class="num">dust</th></tr>${panels}</table>` : ""}</section>`;
}
function radioCard(r, p) {
  if (!p.radios.length) return "";
  const rows = p.radios.map((n) => { const t = `radio/${n}/link`;
    return `<tr><td>${esc(n)}</td><td>${F(t, "in_range", "range")}</td><td class="num">x ${F(t, "x_m", "m")}</td><td class="num">y ${F(t, "y_m", "m")}</td></tr>`; }).join("");
  return `<section class="card"><h2>Radio links</h2><table>${rows}</table></section>`;
}
function driveCard(r, p) {
  if (!p.drive) return "";
  const t = "drive/state";
  return `<section class="card"><h2>Drive</h2><dl class="kv">
    <dt>status</dt><dd>${F(t, "status", "text")}</dd>
    <dt>position</dt><dd>x ${F(t, "x_m", "m")} · y ${F(t, "y_m", "m")} · z ${F(t, "z_m", "m")}</dd>
    <dt>speed</dt><dd>${F(t, "speed_m_per_s", "mps")} · heading ${F(t, "heading_deg", "deg")} · grade ${F(t, "grade_deg", "deg")}</dd>
    <dt>power</dt><dd>${F(t, "power_w", "w")}</dd>
    <dt>to go</dt><dd>${F(t, "remaining_m", "m")} · odometer ${F(t, "odometer_m", "m")}</dd></dl></section>`;
}
function pdmCard(r, p) {
  const rows = p.rails.map((n) => {
    const t = `rail/${n}/state`;
    const loads = p.loads.filter((l) => (val(r, `load/${l}/power`) || {}).rail === n).map((l) => {
      const lt = `load/${l}/power`;
      return `<tr class="load"><td>${esc(l)}</td><td>${F(lt, "on", "onoff")}</td><td></td><td></td>
        <td class="num">${F(lt, "power_w", "num2")}</td><td></td><td>${F(lt, "faults", "faults")}</td></tr>`;
    }).join("");
    return `<tr class="rail"><td>${esc(n)}</td><td>${F(t, "state", "text")}</td><td class="num">${F(t, "voltage_v", "num2")}</td>
      <td class="num">${F(t, "current_a", "num3")}</td><td class="num">${F(t, "power_w", "num2")}</td><td class="num">${F(t, "current_limit_a", "limit")}</td>
      <td>${(val(r, t) || {}).current_limit_a === null ? "<small>panels' rail</small>"
        : `${btn("rail-on", "On", `data-rail="${esc(n)}"`)} ${btn("rail-off", "Off", `data-rail="${esc(n)}"`)} ${btn("rail-reset", "Reset", `data-rail="${esc(n)}"`)}`}</td></tr>${loads}`;
  }).join("");
  return `<section class="card"><h2>Power distribution (PDM)</h2><table>
    <tr><th>rail / load</th><th>state</th><th class="num">V</th><th class="num">A</th><th class="num">W</th><th class="num">limit A</th><th>switch</th></tr>${rows}</table></section>`;
}
const faultsCard = () => `<section class="card"><h2>Active faults</h2><div id="faults-list" class="faults-list"></div></section>`;
const eventsCard = () => `<section class="card"><h2>Event log <small>newest first</small></h2><div id="events-list" class="events"></div></section>`;

const VIEWS = {
  live: (r, p) => `<div class="grid live">
    <div class="col">${batteryCard()}${powerCard(r, p)}${radioCard(r, p)}${driveCard(r, p)}</div>
    <div class="col">${pdmCard(r, p)}<section class="card plots"><h2>Last minutes</h2><div id="charts"></div></section></div>
    <div class="col">${faultsCard()}${eventsCard()}</div></div>`,
  faults: (r, p) => `<div class="grid two"><div class="col"><section class="card"><h2>Inject or clear a fault</h2>
      <p class="help">Choose the part, the kind of fault and its value. The twin answers at once: accepted, or refused with the reason.</p>
      <div class="row"><label>Part of the rover <select id="f-comp"></select></label><label>Fault <select id="f-kind"></select></label></div>
      <p id="f-desc" class="help"></p><div id="f-params" class="row"></div>
      <div class="row" id="f-buttons"></div></section>
      <section class="card"><h2>Every fault the twin knows</h2><div id="f-catalogue"></div></section></div>
    <div class="col">${faultsCard()}${eventsCard()}</div></div>`,
  inputs: (r, p) => `<div class="grid two"><div class="col">
      <section class="card"><h2>Sun angle</h2><p class="help">Angle between the sun and the panels' normal (0° full sun, 90° edge-on).</p>
        <div class="row"><label>All panels [deg]<input type="number" id="sun-all" min="-360" max="360" step="1" value="${val(r, `solar/${p.panels[0]}/power`)?.sun_angle_deg ?? 60}"></label>
        ${btn("input-sun", "Set for all panels", "", "primary")}</div>
        ${p.panels.map((n) => `<div class="row"><label>Panel ${esc(n)} [deg]<input type="number" id="sun-${esc(n)}" min="-360" max="360" step="1"></label>
          ${btn("input-panel-sun", "Set", `data-panel="${esc(n)}"`)} ${btn("input-panel-sun-clear", "Back to the rover's angle", `data-panel="${esc(n)}"`)}
          <span>now ${F(`solar/${n}/power`, "sun_angle_deg", "deg")}</span></div>`).join("")}</section>
      <section class="card"><h2>Umbilical</h2><p>Now: ${F("umbilical/state", "connected", "conn")} ${F("umbilical/state", "power_w", "w")}</p>
        <div class="row">${btn("input-umbilical", "Plug in", 'data-value="true"', "primary")} ${btn("input-umbilical", "Unplug", 'data-value="false"')}</div></section></div>
    <div class="col"><section class="card"><h2>Rover position to each radio</h2>
      <p class="help">${p.drive ? "This rover drives: a radio with a site follows the drive, and the twin refuses a position typed for it." : "Distance and bearing from the radio to the rover."}</p>
      ${p.radios.map((n) => `<div class="row"><b>${esc(n)}</b><label>distance [m]<input type="number" id="pos-d-${esc(n)}" min="0" step="10" value="${Math.round(Math.hypot(val(r, `radio/${n}/link`)?.x_m || 0, val(r, `radio/${n}/link`)?.y_m || 0))}"></label>
        <label>bearing [deg]<input type="number" id="pos-a-${esc(n)}" min="-360" max="360" step="1" value="0"></label>
        ${btn("input-position", "Set", `data-radio="${esc(n)}"`)} ${F(`radio/${n}/link`, "in_range", "range")}</div>`).join("") || "<p>No radio.</p>"}</section>
      <section class="card"><h2>Drive</h2>${p.drive ? `<p class="help">Send the rover straight to a point of the site frame (x east, y north, z up), or stop it.</p>
        <div class="row"><label>x [m]<input type="number" id="tr-x" step="1" value="20"></label><label>y [m]<input type="number" id="tr-y" step="1" value="0"></label>
        <label>z [m]<input type="number" id="tr-z" step="0.5" value="0"></label><label>speed [m/s]<input type="number" id="tr-v" min="0" step="0.01" placeholder="max"></label>
        <label><span><input type="checkbox" id="tr-back"> and back</span></label></div>
        <div class="row">${btn("traverse-go", "Drive there", "", "primary")} ${btn("traverse-stop", "Stop the rover", "", "danger")}</div>
        <p>Now ${F("drive/state", "status", "text")} at x ${F("drive/state", "x_m", "m")}, y ${F("drive/state", "y_m", "m")}</p>`
        : "<p>This rover has no drive section: it does not drive.</p>"}</section></div></div>`,
  session: (r) => `<div class="grid two"><div class="col">
      <section class="card"><h2>Simulated time</h2><p>${F("clock", "t_s", "clock")} at ${F("clock", "time_scale", "x")} ${F("clock", "paused", "", "hidden")}</p>
        <div class="row">${btn("clock-pause", "Pause", "")} ${btn("clock-resume", "Resume", "")}
        ${[1, 2, 5, 10, 20, 50, 100].map((x) => btn("clock-scale", `×${x}`, `data-scale="${x}"`)).join(" ")}</div>
        <div class="row"><label>Other speed<input type="number" id="scale" min="0.01" max="10000" step="any"></label>${btn("clock-scale", "Set", 'data-scale=""')}</div></section>
      <section class="card"><h2>Start again</h2><p class="help">Puts ${esc(r)} back to its rover file: full stored energy, temperature, rails and inputs as at the start, every injected fault cleared, the clock at 0.</p>
        ${btn("reset", `Reset ${esc(r)}`, "", "danger")}</section>
      <section class="card"><h2>Battery prediction</h2><p class="help">Monte Carlo of the rover's futures from its state now, the inputs held.</p>
        <div class="row"><label>hours<input type="number" id="pr-h" min="0.1" max="168" step="any" value="8"></label><label>samples<input type="number" id="pr-n" min="1" max="10000" value="1000"></label>
        <button type="button" class="act" id="predict">Predict</button></div><div id="prediction"></div></section></div>
    <div class="col"><section class="card"><h2>Snapshots <button type="button" class="act" id="snap-refresh">Refresh</button></h2>
      <p class="help">A snapshot keeps the state of every service (stored energy, temperature, rails, inputs, faults, time) under a name; restoring it puts the twin back exactly there.</p>
      <div class="row"><label>Name<input type="text" id="snap-name" placeholder="before-storm" pattern="[A-Za-z0-9_.-]{1,64}"></label>${btn("snapshot-save", "Save snapshot", "", "primary")}</div>
      <div id="snapshots"></div></section>${eventsCard()}</div></div>`,
  scenarios: () => `<div class="grid two"><div class="col"><section class="card"><h2>Scenarios</h2><div id="sc-list">loading…</div></section></div>
    <div class="col"><section class="card"><h2>Playing <span id="sc-stop"></span></h2><div id="sc-play"><p class="help">No scenario is playing.</p></div></section></div></div>`,
  recordings: () => `<div class="grid two"><div class="col"><section class="card"><h2>Record the session</h2>
      <p class="help">Records every value and event of the twin for the debrief (MCAP: also opens in Foxglove and PlotJuggler).</p>
      <div class="row"><label>Name<input type="text" id="rec-name" value="session-${new Date().toISOString().slice(0, 16).replace(/[-:T]/g, "")}"></label>
      <button type="button" class="primary" id="rec-start">Start recording</button><button type="button" class="danger" id="rec-stop">Stop</button></div>
      <div id="rec-status"></div></section></div>
    <div class="col"><section class="card"><h2>Recordings <button type="button" class="act" id="rec-refresh">Refresh</button></h2><div id="rec-list">loading…</div></section></div></div>`,
};

// -- lists drawn from the latest values ----------------------------------------------------------------

function drawFaults() {
  const el = $("#faults-list");
  if (!el) return;
  const pre = `lunaris/${S.rover}/`;
  const rows = activeFaults(S.rover).map((f) => {
    const name = f.key.slice(pre.length).replace(/^fault\//, "");
    const params = Object.entries(f.params || {}).map(([k, v]) => `${k}=${v}`).join(" ");
    let clear = "";
    if (f.origin === "injected") {
      const bits = name.split("/"), kind = bits.pop();
      clear = btn("fault-clear", "Clear", `data-component="${esc(bits.join("/"))}" data-kind="${esc(kind)}"`);
    }
    return `<tr data-fault="${esc(name)}"><td class="sev-${f.severity} wrap">${esc(name)}<br><small>${esc(f.origin)}${params ? " · " + esc(params) : ""}</small></td>
      <td class="num">${f.since_t_s.toFixed(1)} s</td><td>${clear}</td></tr>`;
  }).join("");
  el.innerHTML = rows ? `<table><tr><th>fault</th><th class="num">since</th><th></th></tr>${rows}</table>`
                      : `<p class="none">No active fault.</p>`;
  guard(el);
}
function drawEvents() {
  const el = $("#events-list");
  if (!el) return;
  const evs = (S.events[S.rover] || []).slice(-120).reverse();
  el.innerHTML = evs.map((e) => `<div class="sev-${e.severity}" data-kind="${esc(e.kind)}"><span class="t">${e.t_s.toFixed(1)} s</span>` +
    `<b>${esc(e.kind.replace(/_/g, " "))}</b> ${esc(e.message)} <small>[${esc(e.source)}]</small></div>`).join("") || "<p>No event yet.</p>";
}

// -- plots of the last minutes --------------------------------------------------------------------------

function charts() {
  const box = $("#charts");
  if (!box || typeof uPlot === "undefined") return;
  const h = S.history[S.rover] ||= {t: [], soc: [], temperature_c: [], load_w: [], generation_w: []};
  const width = Math.max(280, box.clientWidth - 4);
  box.innerHTML = `<h3><span style="color:#1b7f3b">━ state of charge %</span> · <span style="color:#8e3fb0">━ battery temperature °C</span></h3>`;
  if (h.t.length < 2) { box.innerHTML = "<p class='help'>The plots start after a few seconds.</p>"; setTimeout(() => { if (S.view === "live" && !S.charts.length) render(); }, 3000); return; }
  const axis = (label, side) => ({label, side, size: 46, labelSize: 14, space: 18, stroke: "#5f6b7a", grid: {stroke: "#eef0f3"}});
  const clockAxis = {stroke: "#5f6b7a", grid: {stroke: "#eef0f3"}, size: 24,
    values: (u, vals) => vals.map((v) => new Date(v * 1000).toLocaleTimeString([], {hour: "2-digit", minute: "2-digit", second: "2-digit"}))};
  const pad = (u, lo, hi) => (lo === null || hi === null ? [0, 1] : lo === hi ? [lo - 1, hi + 1] : [lo - (hi - lo) * 0.05, hi + (hi - lo) * 0.05]);
  const soc = new uPlot({width, height: 100, legend: {show: false}, scales: {x: {time: true}, "%": {range: pad}, C: {range: pad}},
    series: [{}, {label: "state of charge %", stroke: "#1b7f3b", width: 2, scale: "%", points: {show: false}},
             {label: "temperature °C", stroke: "#8e3fb0", width: 1.5, scale: "C", points: {show: false}}],
    axes: [clockAxis, {...axis("%", 3), scale: "%"}, {...axis("°C", 1), scale: "C"}]},
    [h.t, h.soc, h.temperature_c], box);
  box.insertAdjacentHTML("beforeend", `<h3><span style="color:#c0262d">━ loads W</span> · <span style="color:#e0a800">━ generation W</span></h3>`);
  const pw = new uPlot({width, height: 100, legend: {show: false}, scales: {x: {time: true}, W: {range: pad}},
    series: [{}, {label: "loads W", stroke: "#c0262d", width: 1.5, scale: "W", points: {show: false}}, {label: "generation W", stroke: "#e0a800", width: 1.5, scale: "W", points: {show: false}}],
    axes: [clockAxis, {...axis("W", 3), scale: "W"}]},
    [h.t, h.load_w, h.generation_w], box);
  S.charts = [soc, pw];
}
function sample() {  // a point a second for every rover, drawn when its plots are shown
  const now = Date.now() / 1000;
  for (const r of rovers()) {
    const b = val(r, "battery/state"), p = val(r, "power/summary");
    if (!b) continue;
    const h = S.history[r] ||= {t: [], soc: [], temperature_c: [], load_w: [], generation_w: []};
    h.t.push(now); h.soc.push(b.soc * 100); h.temperature_c.push(b.temperature_c);
    h.load_w.push(p ? p.load_power_w : null); h.generation_w.push(p ? p.generation_w : null);
    if (h.t.length > 900) for (const k of Object.keys(h)) h[k].shift();
  }
  const h = S.history[S.rover];
  if (h && S.charts.length === 2) {
    S.charts[0].setData([h.t, h.soc, h.temperature_c]);
    S.charts[1].setData([h.t, h.load_w, h.generation_w]);
  }
}

// -- the fault form, built from the catalogue -------------------------------------------------------------

function faultForm() {
  if (!S.cat) return;
  const p = parts(S.rover), comps = S.cat.components;
  const names = {load: p.loads, rail: p.rails, solar: p.panels, radio: p.radios};
  const opts = Object.entries(comps).map(([c, spec]) => spec.named
    ? `<optgroup label="${esc(c)}">${(names[c] || []).map((n) => `<option value="${esc(c)}/${esc(n)}">${esc(c)} ${esc(n)}</option>`).join("")}</optgroup>`
    : `<option value="${esc(c)}">${esc(c)}</option>`).join("");
  const comp = $("#f-comp"), kind = $("#f-kind");
  comp.innerHTML = opts;
  const kinds = () => {
    const spec = comps[comp.value.split("/")[0]];
    kind.innerHTML = Object.entries(spec.kinds).map(([k, s]) => `<option value="${esc(k)}">${esc(k.replace(/_/g, " "))}</option>`).join("");
    params();
  };
  const params = () => {
    const c = comp.value.split("/")[0], spec = comps[c].kinds[kind.value];
    $("#f-desc").textContent = spec.description;
    $("#f-params").innerHTML = spec.params.map((q) => {
      const lo = q.ge ?? q.gt, hi = q.le ?? q.lt;
      const range = `${lo !== undefined ? (q.gt !== undefined ? "> " : "≥ ") + lo : ""}${lo !== undefined && hi !== undefined ? ", " : ""}${hi !== undefined ? (q.lt !== undefined ? "< " : "≤ ") + hi : ""}`;
      return `<label>${esc(q.name.replace(/_/g, " "))} <small>${esc(range)}${q.default !== null ? `, default ${q.default}` : ""}</small>
        <input type="number" step="any" data-param="${esc(q.name)}" ${lo !== undefined ? `min="${lo}"` : ""} ${hi !== undefined ? `max="${hi}"` : ""}></label>`;
    }).join("") || "<span class='help'>This fault takes no value.</span>";
    const attrs = `data-component="${esc(comp.value)}" data-kind="${esc(kind.value)}"`;
    $("#f-buttons").innerHTML = `${btn("fault-inject", "Inject", attrs, "primary")} ${btn("fault-clear", "Clear", attrs)}`;
    guard($("#f-buttons"));
  };
  comp.onchange = kinds; kind.onchange = params;
  kinds();
  $("#f-catalogue").innerHTML = `<table><tr><th>part</th><th>fault</th><th>effect</th></tr>${Object.entries(comps).map(([c, spec]) =>
    Object.entries(spec.kinds).map(([k, s]) => `<tr><td>${esc(c)}${spec.named ? " &lt;name&gt;" : ""}</td><td>${esc(k)}</td><td>${esc(s.description)}</td></tr>`).join("")).join("")}</table>`;
}
function faultBody() {
  const body = {};
  for (const el of document.querySelectorAll("#f-params [data-param]")) {
    if (el.value.trim() !== "") body[el.dataset.param] = Number(el.value);
  }
  return JSON.stringify(body);
}

// -- actions ------------------------------------------------------------------------------------------------

async function send(method, tail, body, rover = S.rover) {
  let res, data;
  try {
    res = await fetch(`/api/rovers/${encodeURIComponent(rover)}/keys/${tail}`, {
      method, headers: {"Content-Type": "application/json"}, body: method === "PUT" ? (body ?? "") : undefined});
    data = await res.json();
  } catch (err) {
    data = {verdict: "no answer", message: `the console did not answer (${err})`};
  }
  answer(data.verdict, data.message);
  return data;
}
function answer(verdict, message) {
  const box = $("#answers"), el = document.createElement("div");
  const words = {accepted: "Accepted", rejected: "Refused by the twin", invalid: "Not sent",
                 forbidden: "Not allowed", "no answer": "No answer"};
  el.className = `answer ${String(verdict).replace(" ", "")}`;
  el.dataset.verdict = verdict;
  el.innerHTML = `<b>${esc(words[verdict] || verdict)}:</b>${esc(message)}`;
  box.prepend(el);
  while (box.children.length > 4) box.lastChild.remove();
  setTimeout(() => el.remove(), 15000);
}
const num = (id) => { const v = $(id)?.value; return v === "" || v === undefined ? null : Number(v); };

const ACTIONS = {
  "rail-on": (d) => send("PUT", `cmd/rail/${d.rail}`, '{"on": true}'),
  "rail-off": (d) => send("PUT", `cmd/rail/${d.rail}`, '{"on": false}'),
  "rail-reset": (d) => send("PUT", `cmd/rail/${d.rail}`, '{"reset": true}'),
  "clock-pause": () => send("PUT", "clock/control", '{"paused": true}'),
  "clock-resume": () => send("PUT", "clock/control", '{"paused": false}'),
  "clock-scale": (d) => send("PUT", "clock/control", JSON.stringify({time_scale: d.scale ? Number(d.scale) : num("#scale")})),
  "fault-inject": (d) => send("PUT", `fault/${d.component}/${d.kind}`, faultBody()),
  "fault-clear": (d) => send("DELETE", `fault/${d.component}/${d.kind}`),
  "reset": (d) => confirm(`Reset ${d.rover} to its rover file? Every injected fault is cleared and the clock goes back to 0.`)
    && send("PUT", "control/reset", ""),
  "snapshot-save": async () => { const r = await send("PUT", `control/snapshot/${encodeURIComponent($("#snap-name").value.trim())}`, ""); loadSnapshots(); return r; },
  "snapshot-restore": (d) => confirm(`Restore the snapshot "${d.snapshot}" of ${d.rover}? The twin goes back to where it was when it was saved.`)
    && send("PUT", `control/restore/${encodeURIComponent(d.snapshot)}`, ""),
  "input-sun": () => send("PUT", "input/sun_angle", JSON.stringify({angle_deg: num("#sun-all")})),
  "input-panel-sun": (d) => send("PUT", `input/solar/${d.panel}/sun_angle`, JSON.stringify({angle_deg: num(`#sun-${d.panel}`)})),
  "input-panel-sun-clear": (d) => send("DELETE", `input/solar/${d.panel}/sun_angle`),
  "input-umbilical": (d) => send("PUT", "input/umbilical", JSON.stringify({connected: d.value === "true"})),
  "input-position": (d) => send("PUT", `input/radio/${d.radio}/position`,
    JSON.stringify({distance_m: num(`#pos-d-${d.radio}`), angle_deg: num(`#pos-a-${d.radio}`)})),
  "traverse-go": () => send("PUT", "input/drive/traverse", JSON.stringify({
    waypoints: [{x_m: num("#tr-x"), y_m: num("#tr-y"), z_m: num("#tr-z")}],
    speed_m_per_s: num("#tr-v"), return_to_start: $("#tr-back").checked})),
  "traverse-stop": () => send("DELETE", "input/drive/traverse"),
};

document.addEventListener("click", async (ev) => {
  const pick = ev.target.closest("[data-rover-pick]");
  if (pick) { S.rover = pick.dataset.roverPick; drawRovers(); render(); return; }
  const view = ev.target.closest("[data-view]");
  if (view) { S.view = view.dataset.view; render(); return; }
  const b = ev.target.closest("[data-action]");
  if (b && ACTIONS[b.dataset.action] && !b.disabled) {
    b.disabled = true;
    try { await ACTIONS[b.dataset.action](b.dataset); } finally { b.disabled = false; guard(b.parentElement || document); }
    return;
  }
  const id = ev.target.id;
  if (id === "snap-refresh") loadSnapshots();
  if (id === "predict") predict();
  if (id === "rec-start") record({name: $("#rec-name").value});
  if (id === "rec-stop") record({action: "stop"});
  if (id === "rec-refresh") loadRecordings();
  if (ev.target.dataset.play) playScenario({file: ev.target.dataset.play});
  if (id === "sc-stop-btn") playScenario({action: "stop"});
});

// -- session: snapshots and the prediction --------------------------------------------------------------------

async function loadSnapshots() {
  const el = $("#snapshots");
  if (!el) return;
  const res = await fetch(`/api/rovers/${encodeURIComponent(S.rover)}/snapshots`);
  const data = await res.json();
  if (!res.ok) { el.innerHTML = `<p class="error">${esc(data.message)}</p>`; return; }
  el.innerHTML = data.length ? `<table><tr><th>name</th><th class="num">sim t</th><th>saved</th><th></th></tr>${data.map((s) =>
    `<tr><td>${esc(s.name)}</td><td class="num">${clockText(s.t_s)}</td><td>${new Date(s.saved_at * 1000).toLocaleString()}</td>
     <td>${btn("snapshot-restore", "Restore", `data-snapshot="${esc(s.name)}"`)}</td></tr>`).join("")}</table>` : "<p>No snapshot yet.</p>";
  guard(el);
}
async function predict() {
  const el = $("#prediction");
  el.innerHTML = "<p>Computing the futures…</p>";
  const res = await fetch(`/api/rovers/${encodeURIComponent(S.rover)}/prediction?hours=${num("#pr-h")}&samples=${num("#pr-n")}`);
  S.prediction = {ok: res.ok, data: await res.json()};
  drawPrediction();
}
function drawPrediction() {
  const el = $("#prediction");
  if (!el || !S.prediction) return;
  const {ok, data} = S.prediction;
  if (!ok) { el.innerHTML = `<p class="error">No prediction: ${esc(data.message)}</p>`; return; }
  const t = data.time_to_empty_s, s = data.soc_at_horizon;
  el.innerHTML = `<table><tr><th></th><th class="num">5 %</th><th class="num">median</th><th class="num">95 %</th></tr>
    <tr><td>time to empty</td><td class="num">${t.p05 === null ? "beyond" : dur(t.p05)}</td><td class="num">${t.p50 === null ? "beyond" : dur(t.p50)}</td><td class="num">${t.p95 === null ? "beyond" : dur(t.p95)}</td></tr>
    <tr><td>charge at ${dur(data.horizon_s)}</td><td class="num">${fmt(s.p05, "pct")}</td><td class="num">${fmt(s.p50, "pct")}</td><td class="num">${fmt(s.p95, "pct")}</td></tr></table>
    <p class="help">${data.samples} futures from sim t ${data.t_s.toFixed(0)} s, in ${data.computed_in_s.toFixed(1)} s. ${esc((data.notes || []).join(" "))}</p>`;
}

// -- scenarios and recordings ----------------------------------------------------------------------------------

async function loadScenarios() {
  const res = await fetch("/api/scenarios");
  S.scenarios = await res.json();
  drawScenarios();
}
function drawScenarios() {
  const list = $("#sc-list");
  if (!list || !S.scenarios) return;
  const playing = S.scenarios.playing || {};
  list.innerHTML = `<table>${S.scenarios.scenarios.map((s) => s.problems
    ? `<tr><td>${esc(s.file)}</td><td colspan="3" class="error">${esc(s.problems.join("; "))}</td></tr>`
    : `<tr><td><b>${esc(s.name)}</b><br><small>${esc(s.description)}</small><br><span class="pill">${esc(s.rover)}</span>
       <span class="pill">${s.steps} steps</span>${s.time_scale ? ` <span class="pill">×${s.time_scale}</span>` : ""}
       <span class="pill">starts ${esc(s.start)}</span></td>
       <td><button type="button" class="primary" data-play="${esc(s.file)}" ${playing.running || !S.me?.may_act ? "disabled" : ""}>Play</button></td></tr>`).join("")}</table>`
    || "<p>No scenario in the console's folder.</p>";
  const box = $("#sc-play");
  if (!playing.file) return;
  const st = playing.status;
  $("#sc-stop").innerHTML = playing.running && S.me?.may_act ? `<button type="button" class="danger" id="sc-stop-btn">Stop</button>` : "";
  const steps = st ? `<p><b>${esc(st.scenario)}</b> on ${esc(st.rover)} · t+${st.t_rel_s.toFixed(0)} s · ${esc(st.finished ? st.end_reason : st.waiting)}</p>
    <table><tr><th>#</th><th>step</th><th>when</th><th>status</th><th>answer</th><th class="num">at</th></tr>${st.steps.map((r) =>
    `<tr><td>${r.index + 1}</td><td>${esc(r.label)}</td><td><small>${esc(r.trigger)}</small></td><td class="${r.status === "timed out" || r.status === "not fired" ? "out" : r.fired_t_s !== null ? "in" : ""}">${esc(r.status)}</td>
     <td>${esc(r.outcome)}</td><td class="num">${r.fired_t_s === null ? "" : r.fired_t_s.toFixed(0) + " s"}</td></tr>`).join("")}</table>` : "";
  box.innerHTML = `<p>${esc(playing.file)}: ${playing.running ? "<b>playing</b>" : `ended (exit ${playing.exit})`}</p>${steps}
    <div class="log" id="sc-log">${esc(playing.lines.slice(-60).join("\n"))}</div>`;
  const log = $("#sc-log"); log.scrollTop = log.scrollHeight;
}
async function playScenario(body) {
  const res = await fetch("/api/scenarios", {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)});
  const data = await res.json();
  answer(data.verdict, data.message);
  loadScenarios();
}
async function loadRecordings() {
  const res = await fetch("/api/recordings");
  S.recordings = await res.json();
  const list = $("#rec-list"), st = $("#rec-status");
  if (!list) return;
  const r = S.recordings;
  list.innerHTML = r.recordings.length ? `<table><tr><th>recording</th><th class="num">size</th><th>made</th><th></th></tr>${r.recordings.map((x) =>
    `<tr><td>${esc(x.name)}</td><td class="num">${(x.bytes / 1e6).toFixed(1)} MB</td><td>${new Date(x.modified * 1000).toLocaleString()}</td>
     <td><a href="/recordings/${encodeURIComponent(x.name)}/report" target="_blank" rel="noopener">Open the report</a></td></tr>`).join("")}</table>`
    : `<p>No recording yet in ${esc(r.folder || "the console's folder")}.</p>`;
  const rec = r.recording;
  st.innerHTML = rec.file ? `<p>${rec.running ? `<b>Recording</b> to ${esc(rec.file)} for ${dur(Date.now() / 1000 - rec.started)}` : `Last: ${esc(rec.file)}`}</p>
    <div class="log">${esc(rec.lines.join("\n"))}</div>` : "";
  $("#rec-start").disabled = rec.running || !S.me?.may_act;
  $("#rec-stop").disabled = !rec.running || !S.me?.may_act;
}
async function record(body) {
  const res = await fetch("/api/recordings", {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)});
  const data = await res.json();
  answer(data.verdict, data.message);
  loadRecordings();
}

// -- start -----------------------------------------------------------------------------------------------------

async function start() {
  S.me = await (await fetch("/api/me")).json();
  S.cat = await (await fetch("/api/catalogue")).json();
  $("#who").innerHTML = `${esc(S.me.name)} · ${esc(S.me.role)}${S.me.accounts ? ' <a href="/logout">sign out</a>' : ""}`;
  $("#observer").hidden = S.me.may_act;
  connect();
  setInterval(sample, 1000);
  setInterval(() => {
    if (S.view === "scenarios") loadScenarios();
    if (S.view === "recordings" && S.recordings?.recording?.running) loadRecordings();
  }, 1000);
  window.addEventListener("resize", () => { if (S.view === "live") render(); });
}
start();
