"""The debrief as one HTML page (``lunaris report -o FILE.html``, the console's debrief): the
plots drawn by :mod:`lunaris.report_draw`, the score sheet as tables in words, every event with
who acted, and the other sessions of the recording a link away."""

from __future__ import annotations

import base64
import html
import time
import urllib.parse

from common.response import SessionResponse
from lunaris.report_draw import LANES, WHO, _lane, _marks, _t_since
from lunaris.report_session import Session
from lunaris.report_words import (
    KIND_WORDS,
    condition_words,
    event_words,
    fault_words,
    key_words,
    params_words,
)

__all__ = ["drawn_counts", "html_page"]



def _t(t: float | None) -> str:
    return "-" if t is None else f"{t:.1f}"


def _action_words(a) -> str:
    """A crew action in words: "40.0 s: rail off 5V_CH2" -> "at 40.0 s the crew switched rail
    5V_CH2 off"."""
    action = str(a.action)
    verb = {"rail off": f"switched rail {a.target} off", "rail on": f"switched rail {a.target} on",
            "rail reset": f"reset rail {a.target}"}.get(action)
    verb = verb or f"{action.replace('_', ' ')} {a.target}".strip()
    return f"at {a.t_s:.1f} s: {verb}" + ("" if a.accepted else f" - refused: {a.message}")


def _score_html(score: SessionResponse | None) -> str:
    """The score sheet as tables, in words: the faults with their times and the crew's actions,
    the expectations."""
    if score is None:
        return ""
    e = html.escape

    def fault_row(f) -> str:
        component, _, kind = f.fault.rpartition("/")
        effect = fault_words(component, kind)[1]
        acts = "<br>".join(e(_action_words(a)) for a in f.crew_actions) or "no response"
        state = "resolved" if f.resolved_t_s is not None else "open"
        return (f"<tr class='{state}' data-fault='{e(f.fault)}'>"
                f"<td><b>{e(key_words(f.key))}</b><br><small>{e(effect)}</small></td>"
                f"<td>{e(params_words(component, kind, f.params)) or '-'}</td>"
                f"<td>{e(WHO.get(f.injected_by, f.injected_by))}</td>"
                f"<td>{_t(f.injected_t_s)}{'<br><small>' + e(f.note) + '</small>' if f.note else ''}</td>"
                f"<td>{_t_since(f.first_symptom_t_s, f.injected_t_s)}<br>"
                f"<small>{e(f.symptom)}</small></td>"
                f"<td>{_t(f.first_crew_action_t_s)}</td>"
                f"<td>{_t_since(f.resolved_t_s, f.injected_t_s)}<br>"
                f"<small>{e(f.resolved_by)}</small></td>"
                f"<td>{acts}</td></tr>")
    faults = "\n".join(fault_row(f) for f in score.faults)
    expects = "\n".join(
        f"<tr class='{'met' if x.met else 'missed'}'><td>{e(x.label)}</td>"
        f"<td>{e(condition_words(x.condition))}</td>"
        f"<td>{x.within_s:g}</td><td>{_t(x.armed_t_s)}</td>"
        f"<td>{'met at ' + _t(x.at_t_s) if x.met else ('missed' if x.met is False else 'pending')}"
        f"</td><td>{e(x.detail)}</td></tr>" for x in score.expectations)
    whose = f"{e(score.trainee)}'s session" if score.trainee else "the session (no trainee named)"
    began = ("" if score.started_wall is None else " It began at "
             + time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(score.started_wall)) + ".")
    return f"""<h2>The crew's response: {whose} <small>({e(score.session)})</small></h2>
<h3>Faults ({len(score.faults)})</h3>
<p class="help">Times are seconds since the session's start; in brackets, how long after the fault
was put in.{began}</p>
<table><tr><th>fault</th><th>how strong</th><th>put in by</th><th>put in at [s]</th>
<th>the crew could first see it</th><th>the crew first acted</th><th>resolved</th>
<th>the crew's actions</th></tr>
{faults}
</table>
<h3>Expectations ({sum(1 for x in score.expectations if x.met)} of {len(score.expectations)} met)</h3>
<table><tr><th>expected of the crew</th><th>when</th><th>time allowed [s]</th><th>from [s]</th>
<th>outcome</th>
<th>detail</th></tr>
{expects}
</table>
"""


def drawn_counts(s: Session) -> dict[str, int]:
    """What the timeline draws, by lane (and the instructor's marks apart)."""
    marks = _marks(s)
    out = {name: sum(1 for e in marks if _lane(e) == name) for name in LANES}
    out["marks"] = sum(1 for e in marks if e.get("kind") == "mark")
    return out


def _sessions_nav(s: Session, sessions: list[tuple[str, str | None]]) -> str:
    """Every session of the recording, each trainee's report a link away (``?session=ID``: the
    console draws it; the command line names it)."""
    if len(sessions) < 2:
        return ""
    def item(sid: str, trainee: str | None) -> str:
        words = f"{html.escape(trainee or 'no trainee named')} - session {html.escape(sid)}"
        if sid == s.id:
            return f"<li><b>{words} (this report)</b></li>"
        return f'<li><a href="?session={urllib.parse.quote(sid)}">{words}</a></li>'
    items = "".join(item(sid, trainee) for sid, trainee in sessions)
    return (f"<nav><p>Sessions in this recording ({len(sessions)}); on the command line: "
            f"<code>lunaris report FILE --session ID</code></p><ul>{items}</ul></nav>")


def html_page(s: Session, title: str, png: bytes,
              sessions: list[tuple[str, str | None]] | None = None) -> str:
    """The report as one HTML page: the plots, the score sheet, every event with who acted;
    ``sessions`` (id, trainee) are the recording's, linked."""
    def when(e: dict) -> str:
        return "before the recording" if e.get("at_s") is None else f"{e['at_s']:.1f}"
    rows = "\n".join(
        f"<tr class='{html.escape(e.get('severity', ''))}{' before' if e.get('at_s') is None else ''}'"
        f" data-kind='{html.escape(e.get('kind', ''))}'>"
        f"<td>{when(e)}</td>"
        f"<td>{html.escape(WHO.get(e.get('actor') or '', e.get('actor') or ''))}</td>"
        f"<td>{html.escape(KIND_WORDS.get(e.get('kind', ''), e.get('kind', '').replace('_', ' ')))}</td>"
        f"<td>{html.escape(event_words(e))}</td></tr>"
        for e in s.events)
    n = drawn_counts(s)
    drawn = (f"On the timeline: {n['marks']} mark(s) of yours, {n['crew']} action(s) of the crew, "
             f"{n['faults and alarms']} fault(s) and alarm(s), {n['drill']} step(s) of the drill; each is "
             "also a line across the plots (a mark of yours dashed, in brown).")
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; }}
img {{ max-width: 100%; height: auto; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 2px 8px; border-bottom: 1px solid #ddd; }}
tr.warning td {{ color: #b36b00; }} tr.critical td {{ color: #c00; font-weight: bold; }}
tr.before td {{ color: #888; font-style: italic; }}
tr.met td, tr.resolved td {{ color: #1b5e20; }} tr.missed td, tr.open td {{ color: #b71c1c; }}
tr[data-kind="mark"] td {{ color: #6d4c41; font-weight: bold; }}
p.help {{ color: #555; }}
</style></head>
<body>
<h1>{html.escape(title)}</h1>
{_sessions_nav(s, sessions or [])}
<img alt="session plots" src="data:image/png;base64,{base64.b64encode(png).decode()}">
<p id="drawn">{html.escape(drawn)}</p>
{_score_html(s.score)}
<h2>Events ({len(s.events)})</h2>
<table><tr><th>time [s since the start]</th><th>who</th><th>what</th><th>in words</th></tr>
{rows}
</table>
</body></html>
"""
