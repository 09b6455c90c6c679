// The console's HTTP API as the page uses it: writes on the twin's keys, answered by the
// twin; queries; the answers shown on the answer line (under the views' tabs, above the view,
// which scrolls on its own: an answer covers nothing the instructor reads).

import {plainMessage} from "./format.js";
import {changed, store} from "./state.js";

/**
 * What the console answers to a write (`PUT`/`DELETE /api/rovers/<rover>/keys/<key>`,
 * `POST /api/scenarios`, `POST /api/recordings`).
 * `not applied` (HTTP 503 / 504): the write could not reach the service that owns the key (its
 * liveliness gone, the rover's link lost, the console not connected yet) or nothing answered in
 * time; the twin never applies it later.
 * @typedef {{verdict: "accepted" | "rejected" | "invalid" | "forbidden" | "not applied" | "no answer", message: string,
 *   event?: import("./types.js").Event | null}} Answer
 */

/**
 * The console no longer knows this page's user (signed out in another tab, removed from the
 * accounts, the console restarted): to the sign-in page, back to this view after it. The page
 * stayed as it was, "reconnecting" for ever, and an action said "undefined: sign in first".
 */
export function toSignIn() {
  location.assign(`/login?next=${encodeURIComponent(location.pathname + location.search + location.hash)}`);
}

/**
 * An answer's JSON, after the sign-in check.
 * @param {Response} res
 * @returns {Promise<any>}
 */
async function read(res) {
  if (res.status === 401) toSignIn();
  const data = await res.json();
  if (res.status === 401) data.verdict ??= "forbidden";
  return data;
}

/** The key's chunks, each made safe for a URL path (a name may hold any character). */
const path = (/** @type {string} */ tail) => tail.split("/").map(encodeURIComponent).join("/");

/**
 * A write on `lunaris/<rover>/<tail>`, the twin's answer shown.
 * @param {"PUT" | "DELETE"} method
 * @param {string} tail the key under lunaris/<rover>/
 * @param {string} [body] the payload, JSON
 * @param {string} [rover]
 * @param {boolean} [asCrew] the instructor standing in for the crew: counted as the crew's
 * @returns {Promise<Answer>}
 */
export async function send(method, tail, body, rover = store.rover ?? "", asCrew = false) {
  /** @type {Answer} */
  let data;
  try {
    const res = await fetch(`/api/rovers/${encodeURIComponent(rover)}/keys/${path(tail)}${asCrew ? "?as=crew" : ""}`, {
      method, headers: {"Content-Type": "application/json"}, body: method === "PUT" ? (body ?? "") : undefined});
    data = await read(res);
  } catch (err) {
    data = {verdict: "no answer", message: `the console did not answer (${err})`};
  }
  answer(data.verdict, plainMessage(data.message, tail));
  return data;
}

/**
 * A request to one of the console's own jobs (scenarios, recordings), its answer shown.
 * @param {string} url
 * @param {Record<string, unknown>} body
 * @returns {Promise<Answer>}
 */
export async function post(url, body) {
  /** @type {Answer} */
  let data;
  try {
    const res = await fetch(url, {method: "POST", headers: {"Content-Type": "application/json"},
                                  body: JSON.stringify(body)});
    data = await read(res);
  } catch (err) {
    data = {verdict: "no answer", message: `the console did not answer (${err})`};
  }
  answer(data.verdict, plainMessage(data.message));
  return data;
}

/**
 * A query: its data, or the reason there is none (with the status, and what the console sent
 * beside its reason: the faults of the owners that answered, with a 502).
 * @template T
 * @param {string} url
 * @returns {Promise<{ok: true, data: T} | {ok: false, message: string, status?: number, data?: Record<string, unknown>}>}
 */
export async function query(url) {
  try {
    const res = await fetch(url);
    const data = await read(res);
    return res.ok ? {ok: true, data}
      : {ok: false, message: String(data.message ?? res.statusText), status: res.status, data};
  } catch (err) {
    return {ok: false, message: `the console did not answer (${err})`};
  }
}

/** Each verdict as the page says it. */
export const WORDS = {accepted: "Accepted", rejected: "Refused by the twin", invalid: "Not sent",
               forbidden: "Not allowed", "not applied": "Not applied", "no answer": "No answer"};

/** How long an answer stays bright, then dimmed, on the answer line. */
const FRESH_MS = 12000;
/** Answers kept (the newest shown; the others stay for tools and tests, hidden). */
const KEPT = 4;

/**
 * Show an answer on the answer line: the newest in front, dimmed after a while. Built with DOM
 * nodes and text, never markup: the message holds the twin's words and names.
 * @param {string} verdict
 * @param {string} message
 */
export function answer(verdict, message) {
  const box = document.getElementById("answers");
  if (!box) return;
  const el = document.createElement("div"), head = document.createElement("b");
  const said = WORDS[/** @type {keyof typeof WORDS} */ (verdict)] ?? verdict;
  el.className = `answer ${String(verdict).replace(" ", "")}`;
  el.dataset.verdict = verdict;
  head.textContent = `${said}:`;
  el.append(head, " ", message.replace(new RegExp(`^${said}:\\s*`, "i"), ""));
  box.prepend(el);
  while (box.children.length > KEPT) box.lastElementChild?.remove();
  setTimeout(() => el.classList.add("old"), FRESH_MS);
}

/**
 * Run an action once at a time: its buttons wait (disabled) until the twin has answered.
 * @param {string} id what the action is and what it acts on
 * @param {() => unknown} run
 */
export async function act(id, run) {
  if (store.pending.has(id)) return;
  store.pending.add(id);
  changed();
  try {
    await run();
  } finally {
    store.pending.delete(id);
    changed();
  }
}
