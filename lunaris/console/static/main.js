// Lunaris console: the page. Live values come over server-sent events (/api/live); every
// action is a write on the twin's keys through the console's HTTP API, answered by the twin.
// Elements that show a twin value carry data-key (under lunaris/<rover>/) and data-field;
// controls carry data-action with data-rover and their target (SPEC 8a).
//
// Modules: state.js (the state, and what a rover has), stream.js (the live stream into the
// state), api.js (writes, queries, answers), format.js (units), widgets.js (a value, an
// action button, the faults and events cards), header.js (the top bar), charts.js (uPlot),
// views/*.js (one a view, listed in views/index.js), types.js (the twin's payloads, generated
// by `python -m lunaris.console.types`). Templates are lit-html's (vendor/): nothing a name
// or a message holds is ever read as markup.

import {html, render} from "./vendor/lit-html/lit-html.js";
import {keyed} from "./vendor/lit-html/directives/keyed.js";
import {syncCharts, updateCharts} from "./charts.js";
import {clockBar, linkState, roverTabs, traineeBar, viewTabs, who} from "./header.js";
import {changed, followAddress, fromAddress, onChange, parts, store} from "./state.js";
import {connect} from "./stream.js";
import {VIEWS} from "./views/index.js";
import {dashboardBanners, linkBanner, routerBanner} from "./widgets.js";

/** @typedef {import("./views/index.js").View} View */
/** @typedef {import("./views/index.js").ViewContext} ViewContext */

/** @param {string} id */
const byId = (id) => /** @type {HTMLElement} */ (document.getElementById(id));

/** The view shown and the rover it shows (`enter` runs when either changes). */
let shown = "";

/** @returns {{view: View, ctx: ViewContext} | null} */
function current() {
  if (!store.rover) return null;
  const view = VIEWS.find((v) => v.name === store.view) ?? VIEWS[0];
  return {view, ctx: {rover: store.rover, parts: parts(store.rover)}};
}

function draw() {
  render(roverTabs(), byId("rovers"));
  render(traineeBar(), byId("trainee"));
  render(clockBar(), byId("clock"));
  render(viewTabs(), byId("views"));
  render(who(), byId("who"));
  const link = byId("link"), state = linkState();
  link.className = state.cls;
  link.textContent = state.text;
  link.title = state.title;
  byId("observer").hidden = !store.me || store.me.may_act;
  const main = byId("main"), now = current();
  if (!now) {
    render(html`<p class="waiting" id="waiting">${waitingWords()}</p>`, main);
    return;
  }
  const {view, ctx} = now, which = `${ctx.rover}\n${view.name}`;
  if (which !== shown) {
    shown = which;
    view.enter?.(ctx);
  }
  main.dataset.rover = ctx.rover;
  render(html`${routerBanner()}${linkBanner(ctx.rover)}${dashboardBanners()}${keyed(which, view.render(ctx))}`, main);
  view.after?.(ctx);
  syncCharts(document.getElementById("charts"), ctx.rover);
}

/** What the page says while it has no rover to show: the console's own words on the twin. */
function waitingWords() {
  const router = store.router;
  if (!router) return "Connecting to the console…";
  const said = router.message.charAt(0).toUpperCase() + router.message.slice(1);
  if (router.state === "connected") return `${said}: no rover has answered yet (are the twin's services running?)`;
  return `${said}.`;
}

function everySecond() {
  updateCharts();
  changed();  // what time alone changes: how long the crew's dashboard has been silent
  const now = current();
  now?.view.tick?.(now.ctx);
}

async function start() {
  store.me = await (await fetch("/api/me")).json();
  store.cat = await (await fetch("/api/catalogue")).json();
  byId("main").replaceChildren();
  fromAddress();
  onChange(draw);
  connect();
  changed();
  setInterval(everySecond, 1000);
  window.addEventListener("resize", changed);
  window.addEventListener("popstate", followAddress);
}

start();
