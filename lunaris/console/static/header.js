// The top bar: the rovers of the session (state of charge, count of active faults, a lost
// link), the sim time with Pause / Resume, the link to the twin, who is signed in; and the
// views' tabs under it.

import {html, nothing} from "./vendor/lit-html/lit-html.js";
import {send} from "./api.js";
import {clockText, fmt} from "./format.js";
import {activeFaults, battery, clock, linkLost, pickRover, pickView, rovers, store} from "./state.js";
import {VIEWS} from "./views/index.js";
import {actionButton} from "./widgets.js";

export function roverTabs() {
  const all = rovers();
  if (!all.length) return html`<span>no rover yet</span>`;
  return all.map((r) => {
    const b = battery(r), f = activeFaults(r), critical = f.some((x) => x.severity === "critical");
    return html`<button type="button" data-rover-pick=${r} class=${r === store.rover ? "on" : ""}
        @click=${() => pickRover(r)}>${r} ${b ? fmt(b.soc, "pct") : ""}${f.length
        ? html`<span class="badge ${critical ? "critical" : ""}" title="active faults">${f.length}</span>` : nothing}${linkLost(r)
        ? html`<span class="badge lost" title="no clock tick of this rover lately">link lost</span>` : nothing}</button>`;
  });
}

/** The sim time, its speed, PAUSED, and Pause or Resume. */
export function clockBar() {
  const r = store.rover, c = r ? clock(r) : undefined;
  if (!r || !c) return nothing;
  return html`<span>sim time <b id="clock-t" data-key="clock" data-field="t_s">${clockText(c.t_s)}</b></span>
    <span id="clock-x" data-key="clock" data-field="time_scale">×${c.time_scale}</span>
    ${c.paused ? html`<span class="paused" data-key="clock" data-field="paused">PAUSED</span>` : nothing}
    ${c.paused
    ? actionButton({action: "clock-resume", label: "Resume", rover: r, run: () => send("PUT", "clock/control", '{"paused": false}', r)})
    : actionButton({action: "clock-pause", label: "Pause", rover: r, run: () => send("PUT", "clock/control", '{"paused": true}', r)})}`;
}

/** Whether the console reaches the twin (and the page the console). */
export function linkState() {
  if (store.streamError) return {cls: "link bad", text: store.streamError};
  if (store.connected === null) return {cls: "link wait", text: "connecting…"};
  return store.connected ? {cls: "link ok", text: "twin connected"}
    : {cls: "link bad", text: "twin not reachable: values are the last received"};
}

export function who() {
  const me = store.me;
  if (!me) return nothing;
  return html`${me.name} · ${me.role}${me.accounts ? html` <a href="/logout">sign out</a>` : nothing}`;
}

export function viewTabs() {
  return VIEWS.map((v) => html`<button type="button" data-view=${v.name} class=${v.name === store.view ? "on" : ""}
    @click=${() => pickView(v.name)}>${v.label}</button>`);
}
