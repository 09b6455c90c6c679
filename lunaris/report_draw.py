"""The debrief's figure for one session (``lunaris report``; the page around it:
:mod:`lunaris.report_page`): drawn with matplotlib's Agg backend (no display needed).

One figure against the time since the session's start (simulated time; a restore within the
session goes on from where it was): what happened (the session's events in lanes: faults, crew
and instructor actions - rail commands, inputs, clock changes -, resets, restores and
snapshots, the scenario's steps), **the score sheet** under it (each fault injected: from its
injection to its resolution, its first symptom, the crew's actions, accepted or refused, and
its resolution; each expectation of the scenario from when it was armed to its deadline, met or
missed: :mod:`common.response`), state of charge, battery voltage and current, battery
temperature, the power of each load, generation against the load, and each radio link in and
out of range. Alarm thresholds are drawn where the rover file defines them. Every event is a
mark across the plots (the instructor's marks dashed); labels are placed so that they never
overlap, and those that find no room are counted (the HTML table has them all); once the figure
is laid out, a label that would run past its axes' right edge is moved to end inside it. Every
label and table speaks in words (:mod:`lunaris.report_words`): fault names and strengths from
the catalogue, event kinds, scenario conditions; the timeline's lanes are the drill, the
instructor (marks, actions), the crew's actions, the faults and alarms. Events replayed from
before the recording started are listed as such, not drawn. A rover that drove also gets its path in the site
frame, coloured by the drive's power.
"""

from __future__ import annotations

from common.response import SessionResponse
from lunaris.report_session import Session
from lunaris.report_words import (
    event_words,
    key_words,
)

__all__ = ["draw", "fault_line", "keep_inside", "moved", "place_labels", "score_rows"]

MARK_KINDS = {"fault_injected", "fault_cleared", "fault_raised", "fault_resolved", "rejected", "command",
              "input", "clock", "session", "scenario", "mark"}
# The timeline's lanes, top to bottom: who or what each shows (:func:`_lane`).
LANES = ("drill", "instructor", "crew", "faults and alarms")
LANE_COLOUR = {"drill": "tab:purple", "instructor": "tab:brown", "crew": "tab:green"}
SEVERITY_COLOUR = {"info": "tab:blue", "warning": "tab:orange", "critical": "tab:red"}
MARK_COLOUR = "tab:brown"
MOVED_M = 0.05  # a path narrower than this in x and y is a parked rover: no path drawn
LABEL_CHARS = 60  # the most of an event's words a timeline label shows
WHO = {"scenario": "the drill", "twin": "the rover", "instructor": "instructor", "crew": "crew"}


def _marks(s: Session) -> list[dict]:
    """The events drawn: those of the recording (not replayed from before it), of a mark kind."""
    return [e for e in s.events if e.get("kind") in MARK_KINDS and e.get("at_s") is not None]


def _lane(e: dict) -> str:
    """Where an event goes on the timeline: the drill's steps; the instructor's marks, actions
    and the session's start; the crew's actions (refused ones too); the faults and alarms."""
    kind, actor = e.get("kind", ""), e.get("actor") or ""
    if kind == "scenario":
        return "drill"
    if actor == "crew" and kind in ("command", "input", "rejected", "clock"):
        return "crew"
    if kind in ("mark", "session", "command", "input", "clock"):
        return "instructor"
    return "faults and alarms"


def _short(s: Session, e: dict) -> str:
    """An event's label on the timeline, in words."""
    kind = e.get("kind", "")
    if kind == "scenario":
        text = str(e.get("message", "")).split(": ", 1)[-1]
    else:
        text = event_words(e)
        if kind == "mark":
            text = f"mark: {text}"
        elif kind == "fault_injected":
            text = f"+ {text}"
        elif kind == "fault_cleared":
            text = f"cleared: {text}"
        elif kind == "fault_resolved":
            text = f"ended: {text}"
        elif kind == "rejected":
            text = f"refused: {text}"
    return text if len(text) <= LABEL_CHARS else text[:LABEL_CHARS - 1] + "…"


def place_labels(marks: list[tuple[float, str]], span_s: float, width_chars: float,
                 rows: int, t0: float = 0.0) -> tuple[list[tuple[float, str, int]], int]:
    """Labels that do not overlap: ``(time, text)`` marks on an axis from ``t0``, ``span_s``
    wide, that holds ``width_chars`` characters, each put on the first of ``rows`` rows where it fits; the
    labels placed ``(where it begins, text, row)`` and how many found no room. A label that
    would run past the axis's end begins early enough to end there (it was cut off)."""
    per_char = span_s / max(1.0, width_chars)
    ends = [float("-inf")] * rows
    placed, dropped = [], 0
    for t, text in sorted(marks):
        start = max(t0, min(t, t0 + span_s - (len(text) + 1) * per_char))
        for row in range(rows):
            if start >= ends[row]:
                ends[row] = start + (len(text) + 2) * per_char
                placed.append((start, text, row))
                break
        else:
            dropped += 1
    return placed, dropped


def moved(s: Session) -> bool:
    """Whether the rover drove in the session: its path is drawn (a parked rover's one point
    drew a path and a colour bar)."""
    xs, ys = s.path[0], s.path[1]
    return bool(xs) and (max(xs) - min(xs) > MOVED_M or max(ys) - min(ys) > MOVED_M)


def draw(s: Session, title: str):
    """The debrief figure of one rover (a matplotlib Figure, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drove = moved(s)
    radios = sorted(s.radios)
    rows = score_rows(s.score)
    ratios = ([1.3, 0.3 + 0.22 * max(1, len(rows)), 1, 1, 1, 1, 1]
              + ([0.25 + 0.2 * len(radios)] if radios else []) + ([2.2] if drove else []))
    fig, all_axes = plt.subplots(len(ratios), 1, figsize=(13, 4 * sum(ratios) + 1),
                                 constrained_layout=True, gridspec_kw={"height_ratios": ratios})
    n_time = 7 + (1 if radios else 0)
    axes = list(all_axes[:n_time])  # against time
    for ax in axes[1:]:
        ax.sharex(axes[0])
    ax_tl, ax_score, ax_soc, ax_vi, ax_temp, ax_loads, ax_gen = axes[:7]
    b = s.battery
    ax_soc.plot(b["soc"][0], [x * 100 for x in b["soc"][1]], color="tab:green")
    ax_soc.set_ylabel("state of charge [%]")
    ax_vi.plot(*b["voltage_v"], color="tab:blue", label="voltage")
    ax_vi.set_ylabel("battery voltage [V]", color="tab:blue")
    ax_i = ax_vi.twinx()
    ax_i.plot(*b["current_a"], color="tab:red", label="current", linewidth=0.8)
    ax_i.set_ylabel("battery current [A]", color="tab:red")
    ax_temp.plot(*b["temperature_c"], color="tab:purple")
    ax_temp.set_ylabel("battery temperature [C]")
    for ax, name in ((ax_soc, "soc"), (ax_temp, "temperature")):
        for value, label in s.thresholds.get(name, []):
            ax.axhline(value, color="tab:red" if "cut" in label or "depleted" in label else "tab:orange",
                       linewidth=1.0, linestyle="--", alpha=0.8)
            ax.annotate(label, xy=(1.0, value), xycoords=("axes fraction", "data"), xytext=(-4, 2),
                        textcoords="offset points", ha="right", fontsize="x-small", color="tab:red")
    for name, series in sorted(s.loads.items()):
        ax_loads.plot(*series, label=name, linewidth=0.8)
    ax_loads.set_ylabel("load power [W]")
    if s.loads:
        ax_loads.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    for name, series in sorted(s.panels.items()):
        ax_gen.plot(*series, label=f"solar {name}", linewidth=0.8)
    if s.umbilical[0]:
        ax_gen.plot(*s.umbilical, label="umbilical", linewidth=0.8)
    ax_gen.plot(*s.summary["generation_w"], label="generation (total)", color="black")
    ax_gen.plot(*s.summary["load_power_w"], label="loads (total)", color="tab:gray", linestyle="--")
    ax_gen.set_ylabel("power [W]")
    ax_gen.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    if radios:
        _draw_radios(axes[7], s, radios)
    axes[-1].set_xlabel("time since the start of the session [s of simulated time]")
    t0, t1 = s.span_s
    t1 = max(t1, t0 + 1e-3)
    marks = [e for e in _marks(s) if t0 <= e["at_s"] <= t1 + 1.0]
    for ax in (*axes[2:7], ax_i):
        ax.ticklabel_format(axis="y", useOffset=False)
    axes[0].set_xlim(t0, t1)
    _draw_score(ax_score, s, rows)
    for ax in axes[2:]:
        ax.grid(True, alpha=0.3)
        for e in marks:
            mark = e.get("kind") == "mark"
            ax.axvline(e["at_s"], color=_colour(e), alpha=0.9 if mark else 0.5,
                       linewidth=1.6 if mark else 1.0,
                       linestyle="--" if mark else ":" if e.get("kind") in ("rejected", "scenario") else "-")
    _draw_timeline(ax_tl, s, marks, t0, t1 - t0)
    if drove:
        _draw_path(fig, all_axes[-1], s)
    before = sum(1 for e in s.events if e.get("at_s") is None)
    fig.suptitle(title + (f" ({before} event(s) from before the recording: in the table)" if before else ""))
    keep_inside(fig, (ax_tl, ax_score))
    return fig


def keep_inside(fig, axes) -> None:
    """Every label of ``axes`` moved, once the figure is laid out, to end inside its axes: a
    label near the right edge was cut (its length in characters is only a guess of its width)."""
    fig.canvas.draw()  # the layout, and each text's size
    for ax in axes:
        box = ax.get_window_extent()
        x0, x1 = ax.get_xlim()
        per_px = (x1 - x0) / max(1.0, box.width)
        for text in ax.texts:
            if text.get_transform() != ax.transData:
                continue
            ext = text.get_window_extent()
            shift_px = min(0.0, box.x1 - 2 - ext.x1) or max(0.0, box.x0 + 2 - ext.x0)
            if shift_px:
                x, y = text.get_position()
                text.set_position((x + shift_px * per_px, y))


def score_rows(score: SessionResponse | None) -> list[tuple[str, object]]:
    """The rows of the score sheet: ``("fault", FaultResponse)`` then ``("expect", Expectation)``."""
    if score is None:
        return []
    return [("fault", f) for f in score.faults] + [("expect", e) for e in score.expectations]


def _after(a: float | None, b: float | None) -> str:
    """How long after ``b`` ``a`` came, in words ("12 s later", "2 s before")."""
    if a is None or b is None:
        return ""
    d = a - b
    return "at once" if abs(d) < 0.05 else f"{abs(d):.1f} s {'later' if d > 0 else 'before'}"


def fault_line(f) -> str:
    """One fault of the score sheet in a sentence: when the crew could see it, when it acted,
    whether it was resolved."""
    seen = (f"seen {_after(f.first_symptom_t_s, f.injected_t_s)}" if f.first_symptom_t_s is not None
            else "no symptom seen")
    base = f.first_symptom_t_s if f.first_symptom_t_s is not None else f.injected_t_s
    acted = (f"crew acted {_after(f.first_crew_action_t_s, base)} ({len(f.crew_actions)} action(s))"
             if f.crew_actions else "no response from the crew")
    done = (f"resolved {f.resolved_t_s - f.injected_t_s:.1f} s after injection" if f.resolved_t_s is not None
            else "not resolved")
    return f"{seen}; {acted}; {done}"


def _since(a: float | None, b: float | None) -> str:
    """How long after ``b`` (or before: a crew acting ahead of the symptom) ``a`` came."""
    return "-" if a is None or b is None else f"{a - b:+.1f} s"


def _t_since(a: float | None, b: float | None) -> str:
    """``a`` and how long after ``b`` it came; ``-`` alone when there is no ``a``."""
    return "-" if a is None else f"{a:.1f} ({_since(a, b)})"


def _draw_score(ax, s: Session, rows: list[tuple[str, object]]) -> None:
    """The score sheet under the timeline: a row per fault (its life from injection to
    resolution, its first symptom, each crew action, its resolution) and per expectation
    (armed to its deadline, met or missed)."""
    from matplotlib.lines import Line2D

    from common.response import Expectation, FaultResponse

    n = max(1, len(rows))
    ax.set_ylim(-0.5, n - 0.5)
    ax.invert_yaxis()
    ax.grid(True, axis="x", alpha=0.3)
    t_end = s.span_s[1]
    labels = []
    for y, (what, item) in enumerate(rows):
        if what == "fault":
            assert isinstance(item, FaultResponse)
            f = item
            labels.append(key_words(f.key)[:44])
            x0 = s.x(f.injected_t_s)
            x1 = s.x(f.resolved_t_s) if f.resolved_t_s is not None else t_end
            ax.broken_barh([(x0, max(1e-3, x1 - x0))], (y - 0.18, 0.36),
                           color="#c8e6c9" if f.resolved_t_s is not None else "#ffcdd2")
            ax.plot([x0], [y], marker="|", color="black", markersize=14)
            if f.first_symptom_t_s is not None:
                ax.plot([s.x(f.first_symptom_t_s)], [y], marker="D", color="tab:orange", markersize=6)
            for a in f.crew_actions:
                ax.plot([s.x(a.t_s)], [y], marker="^" if a.accepted else "x", markersize=7,
                        color="tab:green" if a.accepted else "tab:red")
            if f.resolved_t_s is not None:
                ax.plot([x1], [y], marker="s", color="tab:green", markersize=6)
            ax.text(x0, y - 0.26, fault_line(f), fontsize="x-small", va="bottom", clip_on=True)
        else:
            assert isinstance(item, Expectation)
            e = item
            labels.append(("expect: " + e.label)[:34])
            if e.armed_t_s is not None and e.deadline_t_s is not None:
                a0, a1 = s.x(e.armed_t_s), s.x(e.deadline_t_s)
                ax.broken_barh([(a0, max(1e-3, a1 - a0))], (y - 0.18, 0.36), color="#e1d5f0")
            if e.met and e.at_t_s is not None:
                at = s.x(e.at_t_s)
                ax.plot([at], [y], marker="o", color="tab:green", markersize=8)
                took = "" if e.armed_t_s is None else f" in {e.at_t_s - e.armed_t_s:.1f} s"
                ax.text(at, y - 0.26, f"met{took} (allowed {e.within_s:g} s)", fontsize="x-small",
                        va="bottom", color="tab:green", clip_on=True)
            else:
                at = s.x(e.deadline_t_s) if e.deadline_t_s is not None else t_end
                word = "missed" if e.met is False else "pending"
                ax.plot([at], [y], marker="X", color="tab:red", markersize=8)
                ax.text(at, y - 0.26, f"{word} (allowed {e.within_s:g} s)", fontsize="x-small",
                        va="bottom", ha="right", color="tab:red", clip_on=True)
    ax.set_yticks(range(len(rows)), labels, fontsize="small")
    faults = sum(1 for w, _ in rows if w == "fault")
    expects = [item for w, item in rows if w == "expect"]
    met = sum(1 for e in expects if getattr(e, "met", False))
    ax.set_title(f"the crew's response: {faults} fault(s); {met} of {len(expects)} expectation(s) met"
                 if rows else "the crew's response: no fault injected, no expectation in this session",
                 fontsize="medium", loc="left")
    if rows:
        ax.legend(handles=[
            Line2D([], [], marker="D", color="tab:orange", linestyle="", label="crew could first see it"),
            Line2D([], [], marker="^", color="tab:green", linestyle="", label="crew action"),
            Line2D([], [], marker="x", color="tab:red", linestyle="", label="crew action refused"),
            Line2D([], [], marker="s", color="tab:green", linestyle="", label="resolved"),
            Line2D([], [], marker="o", color="tab:green", linestyle="", label="met"),
            Line2D([], [], marker="X", color="tab:red", linestyle="", label="missed")],
            loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="x-small")


def _colour(e: dict) -> str:
    if e.get("kind") == "mark":
        return MARK_COLOUR
    return LANE_COLOUR.get(_lane(e)) or SEVERITY_COLOUR.get(e.get("severity", ""), "gray")


def _draw_timeline(ax, s: Session, marks: list[dict], t0: float, span_s: float) -> None:
    """The session's events in lanes (the drill, the instructor's marks and actions, the crew's
    actions, the faults and alarms), each label on a row where it overlaps no other; a mark of
    the instructor's drawn as a flag."""
    rows = 3
    ax.set_ylim(0, len(LANES) * rows)
    ax.set_yticks([(len(LANES) - 1 - i) * rows + rows / 2 for i in range(len(LANES))],
                  [name.replace(" and ", "\nand ") for name in LANES])
    ax.tick_params(axis="y", length=0)
    ax.grid(True, axis="x", alpha=0.3)
    dropped = 0
    for i, name in enumerate(LANES):
        base = (len(LANES) - 1 - i) * rows
        ax.axhline(base, color="#dddddd", linewidth=0.8)
        lane = [e for e in marks if _lane(e) == name]
        for e in lane:
            mark = e.get("kind") == "mark"
            ax.plot([e["at_s"]], [base + 0.35], marker="v" if mark else "|", color=_colour(e),
                    markersize=9 if mark else 8)
        placed, lost = place_labels([(e["at_s"], _short(s, e)) for e in lane], span_s, 150, rows, t0)
        dropped += lost
        colours = {_short(s, e): _colour(e) for e in lane}
        for t, text, row in placed:
            ax.text(t, base + rows - 0.6 - row * 0.95, text, fontsize="x-small", va="center",
                    color=colours[text], clip_on=True,
                    fontweight="bold" if text.startswith("mark: ") else "normal")
    ax.set_title("what happened" + (f" ({dropped} more label(s) without room: see the event table)"
                                    if dropped else ""), fontsize="medium", loc="left")


def _draw_radios(ax, s: Session, radios: list[str]) -> None:
    """Each radio link in range (green) or out (red), as bars over time."""
    for i, name in enumerate(radios):
        ts, vs = s.radios[name]
        spans: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
        for k in range(len(ts)):
            end = ts[k + 1] if k + 1 < len(ts) else ts[k] + 0.5
            spans[vs[k] > 0.5].append((ts[k], max(1e-3, end - ts[k])))
        ax.broken_barh(spans[True], (i + 0.15, 0.7), color="tab:green", alpha=0.7)
        ax.broken_barh(spans[False], (i + 0.15, 0.7), color="tab:red", alpha=0.8)
    ax.set_yticks([i + 0.5 for i in range(len(radios))], [f"{r} link" for r in radios])
    ax.set_ylim(0, len(radios))
    ax.set_title("radio links: green in range, red out of range", fontsize="small", loc="left")


def _draw_path(fig, ax, s: Session) -> None:
    """The path in the site frame, each position coloured by the drive's power then (the
    hottest drawn last, so a grade driven both ways shows the climb)."""
    xs, ys, power = s.path
    order = sorted(range(len(xs)), key=power.__getitem__)
    dots = ax.scatter([xs[i] for i in order], [ys[i] for i in order], c=[power[i] for i in order],
                      cmap="plasma", s=10, linewidths=0)
    fig.colorbar(dots, ax=ax, label="drive power [W]")
    ax.plot(xs[:1], ys[:1], marker="o", color="tab:green", linestyle="", label="first position")
    ax.plot(xs[-1:], ys[-1:], marker="s", color="black", linestyle="", label="last position")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x, east [m]")
    ax.set_ylabel("y, north [m]")
    ax.set_title("path in the site frame, coloured by the drive's power", fontsize="medium")
    ax.legend(loc="upper left", fontsize="small")
    ax.grid(True, alpha=0.3)
