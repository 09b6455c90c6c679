// The pieces every view is made of: a twin value, an action button, the active faults, the
// event log. Templates (lit-html): whatever a name or a message holds is written as text.

import {html, nothing} from "./vendor/lit-html/lit-html.js";
import {act} from "./api.js";
import {clockText, faultName, fmt, paramsText, partName, plainMessage, words} from "./format.js";
import {activeFaults, linkLost, mayAct, store, val} from "./state.js";

/** @typedef {import("./format.js").Format} Format */

/**
 * A twin value: `data-key` (the key under lunaris/<rover>/) and `data-field` name it for
 * tests and tools (SPEC 8a); a state's value gives its class (`st-on`, `in`, `out`). The
 * field must be one of the key's payload (types.js, generated from the twin's Structs).
 * @template {string} K
 * @param {string} rover
 * @param {K} tail
 * @param {keyof import("./types.js").Payload<K> & string} name
 * @param {Format} how
 * @param {{hidden?: boolean}} [opts]
 */
export function field(rover, tail, name, how, opts = {}) {
  const x = val(rover, tail)?.[name];
  const cls = how === "text" ? `st-${x}` : how === "range" ? (x ? "in" : "out") : nothing;
  return html`<span data-key=${tail} data-field=${name} data-fmt=${how} class=${cls}
    ?hidden=${!!opts.hidden}>${fmt(x, how)}</span>`;
}

/**
 * What an action acts on, as `data-*` attributes of its button (SPEC 8a).
 * @typedef {{rail?: string, component?: string, kind?: string, panel?: string, radio?: string,
 *   snapshot?: string, scale?: string, value?: string}} Target
 */

/**
 * A button that changes the twin: `data-action`, `data-rover` and its target; disabled for
 * an observer, and while the twin has not answered it.
 * @param {{action: string, label: unknown, run: () => unknown, rover?: string, target?: Target,
 *   cls?: string}} b
 */
export function actionButton({action, label, run, rover = store.rover ?? "", target = {}, cls = "act"}) {
  const id = JSON.stringify([action, rover, target]), may = mayAct();
  return html`<button type="button" class=${cls} data-action=${action} data-rover=${rover}
    data-rail=${target.rail ?? nothing} data-component=${target.component ?? nothing}
    data-kind=${target.kind ?? nothing} data-panel=${target.panel ?? nothing}
    data-radio=${target.radio ?? nothing} data-snapshot=${target.snapshot ?? nothing}
    data-scale=${target.scale ?? nothing} data-value=${target.value ?? nothing}
    title=${may ? nothing : "observers cannot change the twin"} ?disabled=${!may || store.pending.has(id)}
    @click=${() => act(id, run)}>${label}</button>`;
}

/** Who put a fault in effect, in words. */
const ORIGIN = /** @type {Record<string, string>} */ ({injected: "injected", derived: "raised by the twin"});

/**
 * The active faults of a rover; each injected one with its Clear button. Times are sim time.
 * @param {string} rover
 * @param {(component: string, kind: string) => unknown} clear
 */
export function faultsCard(rover, clear) {
  const pre = `lunaris/${rover}/`;
  const rows = activeFaults(rover).map((f) => {
    const name = (f.key.startsWith(pre) ? f.key.slice(pre.length) : f.key).replace(/^fault\//, "");
    const bits = name.split("/"), kind = bits.pop() ?? "", component = bits.join("/");
    const values = paramsText(component, kind, f.params);
    return html`<tr data-fault=${name}>
      <td class="sev-${f.severity ?? "warning"} wrap">${partName(component)}: ${faultName(component, kind)}<br>
        <small>${ORIGIN[f.origin] ?? words(f.origin)}${values ? ` · ${values}` : ""}</small></td>
      <td class="num">${clockText(f.since_t_s)}</td>
      <td class="end">${f.origin === "injected" ? actionButton({action: "fault-clear", label: "Clear", rover,
        target: {component, kind}, run: () => clear(component, kind)}) : nothing}</td></tr>`;
  });
  return html`<section class="card"><h2>Active faults</h2><div id="faults-list" class="faults-list">${rows.length
    ? html`<table><tr><th>fault</th><th class="num">since (sim time)</th><th></th></tr>${rows}</table>`
    : html`<p class="none">No active fault.</p>`}</div></section>`;
}

/** What an event is, in words (its kind). */
const KIND = /** @type {Record<string, string>} */ ({
  rejected: "refused", fault_injected: "fault injected", fault_cleared: "fault cleared", fault_raised: "alarm",
  fault_resolved: "alarm over", command: "command", input: "input", clock: "clock", session: "session",
  scenario: "drill", internal_error: "twin error"});

/** @param {import("./state.js").TwinEvent} e its message, in plain words, without repeating its kind */
const said = (e) => {
  const text = plainMessage(e.message, e.key);
  return e.kind === "fault_injected" || e.kind === "fault_cleared" ? text.replace(/^(injected|cleared) /, "") : text;
};

/** @param {string} rover the newest 120 of its events, newest first; times are sim time */
export function eventsCard(rover) {
  const evs = (store.events[rover] ?? []).slice(-120).reverse();
  return html`<section class="card"><h2>Event log <small>newest first · sim time</small></h2>
    <div id="events-list" class="events">${evs.length ? evs.map((e) => html`<div class="sev-${e.severity}" data-kind=${e.kind}>
      <span class="t">${clockText(e.t_s)}</span><b>${KIND[e.kind] ?? words(e.kind)}</b> ${said(e)}
      <small>[${e.source}]</small></div>`) : html`<p>No event yet.</p>`}</div></section>`;
}

/** @param {string} rover a banner while the console says the rover's link is lost */
export function linkBanner(rover) {
  return linkLost(rover)
    ? html`<div class="link-lost" role="alert" data-link="lost">Link to ${rover} lost: the values below are the
        last received, and nothing sent to it is applied until the link is back.</div>`
    : nothing;
}
