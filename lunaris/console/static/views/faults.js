// Faults: inject or clear any fault of the catalogue. The form is built from the catalogue
// the console serves (part, kind, its values with their ranges), so a new kind of fault
// appears here without a change to the page.

import {html, nothing} from "../vendor/lit-html/lit-html.js";
import {keyed} from "../vendor/lit-html/directives/keyed.js";
import {answer, send} from "../api.js";
import {faultEffect, faultName, paramWords, partName, plainNumber, PART_WORDS, words} from "../format.js";
import {redraw, store} from "../state.js";
import {actionButton, checkFaults, clearFault, eventsCard, faultsCard} from "../widgets.js";

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

/**
 * A share typed as a percentage, as the page shows it once injected ("dust cover 50 %"): the
 * form said "Dust cover" with 0 to 1, and an instructor's 50 was refused. The catalogue's hint
 * ("0 to 1: 0.25 takes a quarter ...") read in percent.
 * @param {string} hint
 */
const percentHint = (hint) => hint.replace(/^0 to 1: ([0-9.]+)/, (_, x) => `0 to 100: ${plainNumber(Number(x) * 100)}`);

/** @param {number | undefined} v @param {number} k */
const scaled = (v, k) => (v === undefined ? v : v * k);

/** @param {string} component @param {string} kind @param {CatalogueParam} q one value of the form */
function param(component, kind, q) {
  const w = paramWords(component, kind, q.name);
  const pct = w?.unit === "fraction", k = pct ? 100 : 1;
  const unit = pct ? " [%]" : w?.unit ? ` [${w.unit}]` : "";
  const shown = {...q, ge: scaled(q.ge, k), gt: scaled(q.gt, k), le: scaled(q.le, k), lt: scaled(q.lt, k)};
  const limits = range(shown), hint = w?.hint ? (pct ? percentHint(w.hint) : w.hint) : limits;
  const label = `${w?.label ?? words(q.name)}${unit}`;
  return html`<label>${label}
    <small>${hint}${q.default !== null ? `; empty: ${plainNumber(q.default * k)}` : ""}</small>
    <input type="number" step="any" data-param=${q.name} data-scale=${k} data-label=${label}
      data-range=${limits} min=${shown.ge ?? shown.gt ?? nothing} max=${shown.le ?? shown.lt ?? nothing}></label>`;
}

/** @param {HTMLElement} from an element of the form @returns {HTMLInputElement[]} its values */
const inputs = (from) => /** @type {HTMLInputElement[]} */ (
  [...from.closest("section")?.querySelectorAll("#f-params input[data-param]") ?? []]);

/**
 * What is wrong with a value typed, in words ("" when nothing is), before anything is sent: text
 * where a number goes (the browser hands the page nothing for it: it was sent as no value, and
 * the twin answered "extra heat is missing"), a number out of the form's range.
 * @param {HTMLElement} from
 */
function problem(from) {
  for (const input of inputs(from)) {
    if (input.validity.badInput) return `${input.dataset.label} must be a number`;
    if (input.validity.rangeOverflow || input.validity.rangeUnderflow) {
      return `${input.dataset.label} must be ${input.dataset.range} (got ${input.value})`;
    }
  }
  return "";
}

/** @param {string} rover @param {{component: string, kind: string}} target */
function inject(rover, target) {
  const from = /** @type {HTMLElement} */ (document.getElementById("f-buttons"));
  const why = problem(from);
  if (why) return answer("invalid", `not sent: ${why}`);
  return send("PUT", `fault/${target.component}/${target.kind}`, body(from), rover);
}

/** @param {HTMLElement} from an element of the form @returns {string} its values as the JSON body */
function body(from) {
  /** @type {Record<string, number>} */
  const out = {};
  for (const input of inputs(from)) {
    if (input.value.trim() !== "") out[input.dataset.param ?? ""] = Number(input.value) / Number(input.dataset.scale ?? 1);
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
      run: () => inject(rover, target)})}
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
  /** @param {{rover: string}} ctx */
  enter: ({rover}) => checkFaults(rover, true),
  /** @param {{rover: string}} ctx */
  tick: ({rover}) => checkFaults(rover),
};
