// Faults: inject or clear any fault of the catalogue. The form is built from the catalogue
// the console serves (part, kind, its values with their ranges), so a new kind of fault
// appears here without a change to the page.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {keyed} from "../vendor/lit-html/directives/keyed.js";
import {send} from "../api.js";
import {faultEffect, faultName, paramWords, partName, plainNumber, PART_WORDS, words} from "../format.js";
import {redraw, store} from "../state.js";
import {actionButton, eventsCard, faultsCard} from "../widgets.js";
import {clearFault} from "./live.js";

/** @typedef {import("../state.js").Parts} Parts */
/** @typedef {import("../state.js").Catalogue} Catalogue */
/** @typedef {import("../state.js").CatalogueParam} CatalogueParam */

/** The part and kind chosen in the form (the part as `load/imu`, or `battery`). */
const form = {component: "", kind: ""};

/** @param {Catalogue} cat @param {Parts} p @returns {string[]} every part the form offers */
function components(cat, p) {
  /** @type {Record<string, string[]>} */
  const names = {load: p.loads, rail: p.rails, solar: p.panels, radio: p.radios};
  return Object.entries(cat.components).flatMap(([c, spec]) => (spec.named ? (names[c] ?? []).map((n) => `${c}/${n}`) : [c]));
}

/** A bound this large is only a guard against nonsense: it is not worth saying. */
const HUGE = 1e6;

/** @param {CatalogueParam} q its range in words: "0 to 1", "above 0", "1 or more" */
function range(q) {
  const lo = q.ge ?? q.gt, hi = q.le ?? q.lt;
  const top = hi !== undefined && hi < HUGE ? hi : undefined;
  if (lo !== undefined && top !== undefined && q.ge !== undefined && q.le !== undefined) {
    return `${plainNumber(lo)} to ${plainNumber(top)}`;
  }
  const out = [];
  if (lo !== undefined) out.push(q.gt !== undefined ? `above ${plainNumber(lo)}` : `${plainNumber(lo)} or more`);
  if (top !== undefined) out.push(q.lt !== undefined ? `below ${plainNumber(top)}` : `at most ${plainNumber(top)}`);
  return out.join(", ");
}

/** @param {string} component @param {string} kind @param {CatalogueParam} q one value of the form */
function param(component, kind, q) {
  const w = paramWords(component, kind, q.name);
  const unit = w?.unit && w.unit !== "fraction" ? ` [${w.unit}]` : "";
  const hint = w?.hint ?? range(q);
  return html`<label>${w?.label ?? words(q.name)}${unit}
    <small>${hint}${q.default !== null ? `; empty: ${plainNumber(q.default)}` : ""}</small>
    <input type="number" step="any" data-param=${q.name} min=${q.ge ?? q.gt ?? nothing} max=${q.le ?? q.lt ?? nothing}></label>`;
}

/** @param {HTMLElement} from an element of the form @returns {string} its values as the JSON body */
function body(from) {
  /** @type {Record<string, number>} */
  const out = {};
  const box = from.closest("section")?.querySelector("#f-params");
  for (const el of box?.querySelectorAll("input[data-param]") ?? []) {
    const input = /** @type {HTMLInputElement} */ (el);
    if (input.value.trim() !== "") out[input.dataset.param ?? ""] = Number(input.value);
  }
  return JSON.stringify(out);
}

/** @param {string} rover @param {Parts} p */
function faultForm(rover, p) {
  const cat = store.cat;
  if (!cat) return html`<p class="help">Loading the catalogue…</p>`;
  const all = components(cat, p);
  if (!all.includes(form.component)) form.component = all[0] ?? "";
  const spec = cat.components[form.component.split("/")[0]];
  const kinds = spec ? Object.keys(spec.kinds) : [];
  if (!kinds.includes(form.kind)) form.kind = kinds[0] ?? "";
  const kind = spec?.kinds[form.kind];
  const target = {component: form.component, kind: form.kind};
  /** @param {Event} ev */
  const pickComponent = (ev) => { form.component = /** @type {HTMLSelectElement} */ (ev.target).value; redraw(); };
  /** @param {Event} ev */
  const pickKind = (ev) => { form.kind = /** @type {HTMLSelectElement} */ (ev.target).value; redraw(); };
  /** @param {string} c */
  const option = (c) => html`<option value=${c} .selected=${c === form.component}>${partName(c)}</option>`;
  return html`
    <div class="row"><label>Part of the rover <select id="f-comp" @change=${pickComponent}>${Object.entries(cat.components)
      .map(([c, s]) => (s.named ? html`<optgroup label=${`${PART_WORDS[c] ?? words(c)}s`}>${all.filter((x) => x.startsWith(`${c}/`))
        .map(option)}</optgroup>` : option(c)))}</select></label>
      <label>Fault <select id="f-kind" @change=${pickKind}>${kinds.map((k) => html`<option value=${k}
        .selected=${k === form.kind}>${faultName(form.component, k)}</option>`)}</select></label></div>
    <p id="f-desc" class="help">${kind ? faultEffect(form.component, form.kind, kind.description) : ""}</p>
    <div id="f-params" class="row">${keyed(`${form.component}\n${form.kind}`, kind?.params.length
      ? kind.params.map((q) => param(form.component, form.kind, q))
      : html`<span class="help">This fault takes no value.</span>`)}</div>
    <div class="row" id="f-buttons">${actionButton({action: "fault-inject", label: "Inject", rover, target, cls: "primary",
      run: () => send("PUT", `fault/${target.component}/${target.kind}`, body(/** @type {HTMLElement} */ (document.getElementById("f-buttons"))), rover)})}
      ${actionButton({action: "fault-clear", label: "Clear", rover, target, run: () => clearFault(target.component, target.kind)})}</div>`;
}

/** @param {Catalogue | null} cat every fault the twin knows */
function catalogueTable(cat) {
  if (!cat) return nothing;
  return html`<table class="catalogue"><tr><th>part</th><th>fault</th><th>what it does</th></tr>${Object.entries(cat.components)
    .map(([c, spec]) => Object.entries(spec.kinds).map(([k, s]) => html`<tr><td>${PART_WORDS[c] ?? words(c)}${spec.named
      ? html` <small>(each)</small>` : nothing}</td><td>${faultName(c, k)}</td>
      <td class="wrap">${faultEffect(c, k, s.description)}</td></tr>`))}</table>`;
}

export const faults = {
  name: "faults",
  label: "Faults",
  /** @param {{rover: string, parts: Parts}} ctx */
  render: ({rover, parts}) => html`<div class="grid two"><div class="col"><section class="card"><h2>Inject or clear a fault</h2>
      <p class="help">Choose the part, the kind of fault and its value. The twin answers at once: accepted, or refused
        with the reason.</p>${faultForm(rover, parts)}</section>${faultsCard(rover, clearFault)}</div>
    <div class="col">${eventsCard(rover)}<section class="card"><h2>Every fault the twin knows</h2>
      <div id="f-catalogue">${catalogueTable(store.cat)}</div></section></div></div>`,
};
