// What every view of the console must be, checked in the browser (tests/console/page_checks.py
// runs these functions in the page; see its docstring).

/** Controls outside the viewport's width or hidden sideways in a box that clips them; elements
 * sticking out of their card; a page that scrolls sideways. */
function layout() {
  const slack = 1, vw = document.documentElement.clientWidth, out = [];
  const visible = (e) => { const r = e.getBoundingClientRect(), s = getComputedStyle(e);
    return r.width > 0 && r.height > 0 && s.visibility !== "hidden"; };
  const name = (e) => { let s = e.tagName.toLowerCase(); if (e.id) s += "#" + e.id;
    for (const a of ["data-action", "data-view", "data-play", "data-param", "data-key", "data-field", "data-rail"])
      if (e.hasAttribute(a)) s += `[${a}="${e.getAttribute(a)}"]`;
    const t = (e.innerText || e.value || "").trim().slice(0, 30); return t ? `${s} "${t}"` : s; };
  const clips = (e) => { const s = getComputedStyle(e); return s.overflowX !== "visible"; };
  if (document.documentElement.scrollWidth > vw + slack)
    out.push(`the page scrolls sideways: ${document.documentElement.scrollWidth} px wide in ${vw}`);
  for (const c of document.querySelectorAll("button, input, select, [data-action]")) {
    if (!visible(c) || c.closest("[hidden]")) continue;
    const r = c.getBoundingClientRect();
    if (r.left < -slack || r.right > vw + slack)
      out.push(`${name(c)} at x ${Math.round(r.left)}..${Math.round(r.right)}: outside the viewport (${vw} px)`);
    for (let a = c.parentElement; a && a !== document.body; a = a.parentElement) {
      if (!clips(a)) continue;
      const b = a.getBoundingClientRect();
      if (r.left < b.left - slack || r.right > b.right + slack)
        out.push(`${name(c)} at x ${Math.round(r.left)}..${Math.round(r.right)}: hidden sideways in ${name(a)} ` +
                 `(${Math.round(b.left)}..${Math.round(b.right)})`);
    }
  }
  for (const card of document.querySelectorAll(".card")) {
    if (!visible(card)) continue;
    const b = card.getBoundingClientRect();
    if (card.scrollWidth > card.clientWidth + slack)
      out.push(`${name(card)} "${card.querySelector("h2")?.innerText ?? ""}": its content is ${card.scrollWidth} px wide in ${card.clientWidth}`);
    for (const e of card.querySelectorAll("*")) {
      if (!visible(e)) continue;
      const r = e.getBoundingClientRect();
      let scrolled = false;
      for (let a = e.parentElement; a && a !== card; a = a.parentElement)
        if (["auto", "scroll"].includes(getComputedStyle(a).overflowY)) scrolled = true;
      if (r.left < b.left - slack || r.right > b.right + slack
          || (!scrolled && (r.top < b.top - slack || r.bottom > b.bottom + slack)))
        out.push(`${name(e)} (${Math.round(r.left)}..${Math.round(r.right)} x ${Math.round(r.top)}..${Math.round(r.bottom)}) ` +
                 `overflows its card "${card.querySelector("h2")?.innerText ?? ""}" (${Math.round(b.left)}..${Math.round(b.right)} x ` +
                 `${Math.round(b.top)}..${Math.round(b.bottom)})`);
    }
  }
  return [...new Set(out)];
}

/** Controls smaller than `min` px either way (a checkbox's label counts for it). */
function touch(min) {
  const out = [];
  for (const c of document.querySelectorAll("button, input, select, [data-action]")) {
    const s = getComputedStyle(c);
    if (c.closest("[hidden]") || s.display === "none" || s.visibility === "hidden") continue;
    const target = c.type === "checkbox" || c.type === "radio" ? (c.closest("label") ?? c) : c;
    const r = target.getBoundingClientRect();
    if (r.width === 0 && r.height === 0) continue;
    if (r.height < min - 0.5 || r.width < min - 0.5)
      out.push(`${c.tagName.toLowerCase()}${c.id ? "#" + c.id : ""}${c.dataset.action ? `[data-action="${c.dataset.action}"]` : ""} ` +
               `"${(c.innerText || c.value || "").trim().slice(0, 20)}": ${Math.round(r.width)} x ${Math.round(r.height)} px`);
  }
  return out;
}

/** Elements of the view that show (cut by the viewport and the boxes that scroll them) under an answer. */
function covered() {
  const cut = (a, b) => ({left: Math.max(a.left, b.left), right: Math.min(a.right, b.right),
                          top: Math.max(a.top, b.top), bottom: Math.min(a.bottom, b.bottom)});
  const some = (r) => r.right > r.left && r.bottom > r.top;
  const view = {left: 0, top: 0, right: innerWidth, bottom: innerHeight};
  const out = [];
  for (const ans of document.querySelectorAll('#answers .answer')) {
    const a = ans.getBoundingClientRect();
    if (!a.width) continue;
    for (const e of document.querySelectorAll('#main .card, #main .card *')) {
      let seen = cut(e.getBoundingClientRect(), view);  // what of it shows: cut by the boxes that scroll it
      for (let p = e.parentElement; p && some(seen); p = p.parentElement)
        if (getComputedStyle(p).overflowY !== 'visible') seen = cut(seen, p.getBoundingClientRect());
      if (some(seen) && some(cut(seen, a)))
        out.push(`${e.closest('.card').querySelector('h2')?.innerText ?? ''} ${e.tagName} under "${ans.textContent}"`);
    }
  }
  return out;
}
