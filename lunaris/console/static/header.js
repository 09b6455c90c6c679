// The top bar: the rovers of the session (state of charge, count of active faults, a lost
// link), the chosen rover's trainee and session, the sim time with Pause / Resume, the link to the twin, who is signed in; and the
// views' tabs under it.

import {html, nothing} from "./vendor/lit-html/lit-html.js";
import {send} from "./api.js";
import {clockText, fmt, sessionName} from "./format.js";
import {activeFaults, battery, clock, linkLost, pickRover, pickView, rovers, runningSession, store} from "./state.js";
import {VIEWS} from "./views/index.js";
import {actionButton, traineeWords} from "./widgets.js";

export function roverTabs() {
  const all = rovers();
  if (!all.length) return html`<span>no rover yet</span>`;
  return all.map((r) => {
    const b = battery(r), f = activeFaults(r), critical = f.some((x) => x.severity === "critical");
    return html`<button type="button" data-rover-pick=${r} class=${r === store.rover ? "on" : ""}
        @click=${() => pickRover(r)}>${r} ${b ? fmt(b.soc, "pct") : ""}${f.length
        ? html`<span class="badge ${critical ? "critical" : ""}" title="active faults">${f.length}</span>` : nothing}${linkLost(r)
        ? html`<span class="badge lost" title=${store.links[r]?.reason ?? ""}>link lost</span>` : nothing}</button>`;
  });
}

/** Whose session runs on the chosen rover (SPEC 12c), and its id. */
export function traineeBar() {
  const r = store.rover, s = r ? runningSession(r) : undefined;
  if (!r || !s) return nothing;
  return html`${s.trainee ? html`<span class="label">trainee</span> ` : nothing}<b id="trainee-now" data-session=${s.id}
    data-trainee=${s.trainee ?? nothing}>${traineeWords(s)}</b> <small title=${`session ${s.id} (what lunaris report --session takes)`}
    >session of ${sessionName(s.id)}</small>`;
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

/**
 * Where the console is with the twin (and the page with the console), for the top bar: a short
 * text, its class, and the console's own words as the element's title.
 * @returns {{cls: string, text: string, title: string}}
 */
export function linkState() {
  const router = store.router;
  if (store.streamError) return {cls: "link bad", text: store.streamError, title: "the page lost the console itself"};
  if (router?.state === "waiting") {
    return {cls: "link wait", text: `waiting for the twin at ${router.endpoint}`, title: router.message};
  }
  if (router?.state === "lost" || (router === null && store.connected === false)) {
    return {cls: "link bad", text: "connection to the twin lost", title: router?.message ?? ""};
  }
  if (router?.state === "connected" || store.connected) {
    return {cls: "link ok", text: "twin connected", title: router?.message ?? ""};
  }
  return {cls: "link wait", text: "connecting…", title: ""};
}

export function who() {
  const me = store.me;
  if (!me) return nothing;
  // signing out is a POST (a GET could be made by any link or image of another page)
  return html`${me.name} · ${me.role}${me.accounts ? html` <form class="sign-out" method="post" action="/logout"><button
    type="submit" id="sign-out">sign out</button></form>` : nothing}`;
}

export function viewTabs() {
  return VIEWS.map((v) => html`<button type="button" data-view=${v.name} class=${v.name === store.view ? "on" : ""}
    @click=${() => pickView(v.name)}>${v.label}</button>`);
}
