"""``lunaris report FILE.mcap -o OUT.png|OUT.html``: a recorded session, drawn for the debrief.

One figure per rover against the time since the start of the recording (simulated time,
continued across a reset or a restore, which are marked): what happened (a timeline of the
session's events in lanes: faults, crew and instructor actions - rail commands, inputs,
clock changes -, the session's resets, restores and snapshots, and the scenario's steps),
state of charge, battery voltage and current, battery temperature, the power of each load,
generation (each solar panel, the umbilical and the total) against the load, and each radio
link in and out of range. Alarm thresholds are drawn where the rover file defines them
(``max_c`` and ``cutoff_c`` on the temperature, each rail's ``shed_below_soc`` and
``depleted_soc`` on the state of charge). Every event is a mark across the plots; labels are
placed so that they never overlap, and those that find no room are counted (the HTML table
has them all). Events replayed from before the recording started are listed as such, not
drawn. A rover that drove also gets its path in the site frame, coloured by the drive's
power. Drawn with matplotlib's Agg backend: no display needed.
"""

from __future__ import annotations

import argparse
import base64
import html
import io
import struct
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from common import keys
from lunaris.client.events import EventWindow, event_identity

__all__ = ["Session", "add_arguments", "draw", "load_session", "main"]

MARK_KINDS = {"fault_injected": "+", "fault_cleared": "-", "fault_raised": "!",
              "fault_resolved": "ok ", "rejected": "x ", "command": "", "input": "", "clock": "",
              "session": "", "scenario": ""}
# The timeline's lanes, top to bottom: which event kinds each shows.
LANES = (("scenario", ("scenario",)), ("session", ("session",)),
         ("actions", ("command", "input", "clock")),
         ("faults", ("fault_injected", "fault_cleared", "fault_raised", "fault_resolved", "rejected")))
LANE_COLOUR = {"scenario": "tab:purple", "session": "black", "actions": "tab:green"}
SEVERITY_COLOUR = {"info": "tab:blue", "warning": "tab:orange", "critical": "tab:red"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap", help="a recording made by lunaris record")
    p.add_argument("-o", "--output", metavar="OUT", default=None,
                   help="OUT.png or OUT.html (default: FILE with .png)")
    p.add_argument("--rover", metavar="ID", help="the rover to draw (needed when several were recorded)")
    p.add_argument("--rover-file", metavar="FILE",
                   help="the rover's definition, for its alarm thresholds (default: config/rovers by id)")


Series = tuple[list[float], list[float]]


@dataclass
class Session:
    """The time series of one rover, by sim time [s]."""

    rover: str
    battery: dict[str, Series] = field(default_factory=lambda: defaultdict(lambda: ([], [])))
    loads: dict[str, Series] = field(default_factory=lambda: defaultdict(lambda: ([], [])))
    panels: dict[str, Series] = field(default_factory=lambda: defaultdict(lambda: ([], [])))
    summary: dict[str, Series] = field(default_factory=lambda: defaultdict(lambda: ([], [])))
    umbilical: Series = field(default_factory=lambda: ([], []))
    path: tuple[list[float], list[float], list[float]] = field(default_factory=lambda: ([], [], []))
    radios: dict[str, Series] = field(default_factory=lambda: defaultdict(lambda: ([], [])))
    events: list[dict] = field(default_factory=list)  # each with "at_s": its recording time, or None
    thresholds: dict[str, list[tuple[float, str]]] = field(default_factory=dict)  # plot -> (value, label)
    # the timeline: recording time = sim time + offset, the offset changing with each epoch
    offset_s: float | None = None
    epoch: int | None = None
    last_s: float = 0.0

    @property
    def span_s(self) -> tuple[float, float]:
        ts = self.battery["soc"][0] or self.summary["load_power_w"][0]
        return (min(ts), max(ts)) if ts else (0.0, 0.0)

    def at(self, t_s: float) -> float:
        """The recording time [s since its start] of a sim time of the current epoch."""
        if self.offset_s is None:
            self.offset_s = -t_s
        return t_s + self.offset_s

    def on_clock(self, t_s: float, epoch: int) -> None:
        """A reset or a restore goes on from where the recording was, not back in time."""
        if self.epoch is not None and epoch != self.epoch:
            self.offset_s = self.last_s - t_s
        self.epoch = epoch
        self.last_s = max(self.last_s, self.at(t_s))


def _add(series: Series, t: float, v: float | None) -> None:
    if v is not None:
        series[0].append(t)
        series[1].append(float(v))


def load_session(path: Path) -> dict[str, Session]:
    """Every rover's series from a recording (raises ValueError if it is not an MCAP file)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    sessions: dict[str, Session] = {}
    seen_events = EventWindow()
    with open(path, "rb") as f:
        try:
            messages = list(make_reader(f).iter_messages(log_time_order=True))
        except (McapError, ValueError, EOFError, struct.error) as exc:
            raise ValueError(f"{path} is not a readable MCAP file: {exc}") from None
    for _schema, channel, message in messages:
        try:
            rover, parts = keys.split(channel.topic)
        except ValueError:
            continue
        fam = keys.telemetry_family(parts)
        family = "event" if parts[:1] == ["event"] and len(parts) <= 2 else (
            fam.name if fam is not None else None)  # events: the journal's key and each service's
        if family is None:
            continue
        try:
            v = msgspec.json.decode(message.data)
        except msgspec.DecodeError:
            continue
        if not isinstance(v, dict):
            continue
        s = sessions.setdefault(rover, Session(rover))
        t_sim = float(v.get("t_s", 0.0))
        if family == "clock":
            s.on_clock(t_sim, int(v.get("epoch", 0)))
        if family == "event":
            if seen_events.first(event_identity(rover, v)):  # once: journal's key, service's, replays
                at = s.at(t_sim) if s.offset_s is not None else None
                # replayed from the caches: older than the recording's first tick
                v["at_s"] = at if at is not None and at >= -1e-9 and s.epoch is not None else None
                s.events.append(v)
            continue
        if s.offset_s is None and family != "clock":
            continue  # before the first tick: no place on the timeline yet
        t = s.at(t_sim)
        if t > s.last_s + 2.0 or t < -1e-9:
            continue  # a straggler of the epoch before a reset
        if family == "battery/state":
            for name in ("soc", "voltage_v", "current_a", "temperature_c", "power_w"):
                _add(s.battery[name], t, v.get(name))
        elif family == "load/*/power":
            _add(s.loads[parts[1]], t, v.get("power_w"))
        elif family == "solar/*/power":
            _add(s.panels[parts[1]], t, v.get("power_w"))
        elif family == "power/summary":
            for name in ("load_power_w", "generation_w", "net_battery_power_w"):
                _add(s.summary[name], t, v.get(name))
        elif family == "umbilical/state":
            _add(s.umbilical, t, v.get("power_w"))
        elif family == "drive/state":
            if None not in (v.get("x_m"), v.get("y_m"), v.get("power_w")):
                for series, name in zip(s.path, ("x_m", "y_m", "power_w"), strict=True):
                    series.append(float(v[name]))
        elif family == "radio/*/link":
            _add(s.radios[parts[1]], t, 1.0 if v.get("in_range") else 0.0)
    for s in sessions.values():
        s.events.sort(key=lambda e: (e["at_s"] is not None, e["at_s"] or 0.0, e.get("t_s", 0.0)))
    return sessions


def add_thresholds(s: Session, rover_file: str | None) -> str:
    """The rover file's alarm thresholds on the plots; a note of where they came from."""
    from lunaris.client import ToolError
    from lunaris.scenario import find_rover

    try:
        rover, note = find_rover(s.rover, rover_file)
    except ToolError as exc:
        return f"thresholds not drawn: {exc}"
    if rover is None:
        return f"thresholds not drawn: {note}"
    th = rover.battery.thermal
    s.thresholds["temperature"] = [(th.max_c, f"alarm {th.max_c:g} C"),
                                   (th.cutoff_c, f"cut-off {th.cutoff_c:g} C")]
    soc = [(r.shed_below_soc * 100, f"{r.name} shed") for r in rover.rails if r.shed_below_soc is not None]
    if rover.battery.depleted_soc > 0:
        soc.append((rover.battery.depleted_soc * 100, "depleted"))
    s.thresholds["soc"] = soc
    return "thresholds " + note.replace("names checked against", "from")


def _marks(s: Session) -> list[dict]:
    """The events drawn: those of the recording (not replayed from before it), of a mark kind."""
    return [e for e in s.events if e.get("kind") in MARK_KINDS and e.get("at_s") is not None]


def _short(s: Session, e: dict) -> str:
    kind = e.get("kind", "")
    if kind == "scenario":
        return str(e.get("message", "")).split(": ", 1)[-1][:48]
    if kind in ("command", "input", "clock", "session"):
        return str(e.get("message", ""))[:40]
    name = e.get("key", "").removeprefix(keys.rover_prefix(s.rover) + "/").removeprefix("fault/")
    return f"{MARK_KINDS.get(kind, '')}{name}"


def place_labels(marks: list[tuple[float, str]], span_s: float, width_chars: float,
                 rows: int) -> tuple[list[tuple[float, str, int]], int]:
    """Labels that do not overlap: ``(time, text)`` marks on an axis ``span_s`` wide that holds
    ``width_chars`` characters, each put on the first of ``rows`` rows where it fits; the
    labels placed ``(time, text, row)`` and how many found no room."""
    per_char = span_s / max(1.0, width_chars)
    ends = [float("-inf")] * rows
    placed, dropped = [], 0
    for t, text in sorted(marks):
        for row in range(rows):
            if t >= ends[row]:
                ends[row] = t + (len(text) + 2) * per_char
                placed.append((t, text, row))
                break
        else:
            dropped += 1
    return placed, dropped


def draw(s: Session, title: str):
    """The debrief figure of one rover (a matplotlib Figure, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drove = len(s.path[0]) > 0
    radios = sorted(s.radios)
    ratios = [1.3, 1, 1, 1, 1, 1] + ([0.25 + 0.2 * len(radios)] if radios else []) + ([2.2] if drove else [])
    fig, all_axes = plt.subplots(len(ratios), 1, figsize=(13, 4 * sum(ratios) + 1),
                                 constrained_layout=True, gridspec_kw={"height_ratios": ratios})
    n_time = 6 + (1 if radios else 0)
    axes = list(all_axes[:n_time])  # against time
    for ax in axes[1:]:
        ax.sharex(axes[0])
    ax_tl, ax_soc, ax_vi, ax_temp, ax_loads, ax_gen = axes[:6]
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
        _draw_radios(axes[6], s, radios)
    axes[-1].set_xlabel("time since the start of the recording [s of simulated time]")
    t0, t1 = s.span_s
    t1 = max(t1, t0 + 1e-3)
    marks = [e for e in _marks(s) if t0 <= e["at_s"] <= t1 + 1.0]
    for ax in (*axes[1:6], ax_i):
        ax.ticklabel_format(axis="y", useOffset=False)
    axes[0].set_xlim(t0, t1)
    for ax in axes[1:]:
        ax.grid(True, alpha=0.3)
        for e in marks:
            ax.axvline(e["at_s"], color=_colour(e), alpha=0.5, linewidth=1.0,
                       linestyle=":" if e.get("kind") in ("rejected", "scenario") else "-")
    _draw_timeline(ax_tl, s, marks, t1 - t0)
    if drove:
        _draw_path(fig, all_axes[-1], s)
    before = sum(1 for e in s.events if e.get("at_s") is None)
    fig.suptitle(title + (f" ({before} event(s) from before the recording: in the table)" if before else ""))
    return fig


def _colour(e: dict) -> str:
    kind = e.get("kind", "")
    lane = next((name for name, kinds in LANES if kind in kinds), "faults")
    return LANE_COLOUR.get(lane) or SEVERITY_COLOUR.get(e.get("severity", ""), "gray")


def _draw_timeline(ax, s: Session, marks: list[dict], span_s: float) -> None:
    """The session's events in lanes, each label on a row where it overlaps no other."""
    rows = 3
    ax.set_ylim(0, len(LANES) * rows)
    ax.set_yticks([(len(LANES) - 1 - i) * rows + rows / 2 for i in range(len(LANES))],
                  [name for name, _ in LANES])
    ax.tick_params(axis="y", length=0)
    ax.grid(True, axis="x", alpha=0.3)
    dropped = 0
    for i, (_name, kinds) in enumerate(LANES):
        base = (len(LANES) - 1 - i) * rows
        ax.axhline(base, color="#dddddd", linewidth=0.8)
        lane = [e for e in marks if e.get("kind") in kinds]
        for e in lane:
            ax.plot([e["at_s"]], [base + 0.35], marker="|", color=_colour(e), markersize=8)
        placed, lost = place_labels([(e["at_s"], _short(s, e)) for e in lane], span_s, 150, rows)
        dropped += lost
        colours = {(e["at_s"], _short(s, e)): _colour(e) for e in lane}
        for t, text, row in placed:
            ax.text(t, base + rows - 0.6 - row * 0.95, text, fontsize="x-small", va="center",
                    color=colours[(t, text)], clip_on=True)
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


def main(args: argparse.Namespace) -> int:
    path = Path(args.file)
    out = Path(args.output) if args.output else path.with_suffix(".png")
    if out.suffix.lower() not in (".png", ".html"):
        print(f"lunaris report: the output must end in .png or .html, got {out}", file=sys.stderr)
        return 2
    if not path.is_file():
        print(f"lunaris report: {path} does not exist", file=sys.stderr)
        return 2
    try:
        sessions = load_session(path)
    except ValueError as exc:
        print(f"lunaris report: {exc}", file=sys.stderr)
        return 2
    sessions = {r: s for r, s in sessions.items() if s.battery["soc"][0] or s.summary["load_power_w"][0]}
    if not sessions:
        print(f"lunaris report: {path} holds no rover telemetry", file=sys.stderr)
        return 1
    rover = args.rover
    if rover is None:
        if len(sessions) > 1:
            print(f"lunaris report: {path} holds several rovers ({', '.join(sorted(sessions))}); "
                  "choose one with --rover", file=sys.stderr)
            return 2
        rover = next(iter(sessions))
    if rover not in sessions:
        print(f"lunaris report: no telemetry of rover {rover!r} in {path} "
              f"(rovers: {', '.join(sorted(sessions))})", file=sys.stderr)
        return 2
    s = sessions[rover]
    note = add_thresholds(s, args.rover_file)
    t0, t1 = s.span_s
    title = f"{rover} - {path.name} - {t1 - t0:.0f} s of simulated time"
    fig = draw(s, title)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=100)
    if out.suffix.lower() == ".png":
        out.write_bytes(png.getvalue())
    else:
        out.write_text(_html(s, title, png.getvalue()))
    drove = f", a path of {len(s.path[0])} positions" if s.path[0] else ""
    before = sum(1 for e in s.events if e.get("at_s") is None)
    print(f"wrote {out}: {rover}, {t1 - t0:.0f} s of sim time, {len(s.loads)} loads{drove}, "
          f"{len(_marks(s))} event(s) marked, {len(s.events)} event(s) in all ({before} from before "
          f"the recording); {note}")
    return 0


def _html(s: Session, title: str, png: bytes) -> str:
    def when(e: dict) -> str:
        return "before the recording" if e.get("at_s") is None else f"{e['at_s']:.1f}"
    rows = "\n".join(
        f"<tr class='{html.escape(e.get('severity', ''))}{' before' if e.get('at_s') is None else ''}'>"
        f"<td>{when(e)}</td><td>{e.get('t_s', 0.0):.1f}</td>"
        f"<td>{html.escape(e.get('severity', ''))}</td><td>{html.escape(e.get('source', ''))}</td>"
        f"<td>{html.escape(e.get('kind', ''))}</td><td>{html.escape(e.get('message', ''))}</td></tr>"
        for e in s.events)
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 2px 8px; border-bottom: 1px solid #ddd; }}
tr.warning td {{ color: #b36b00; }} tr.critical td {{ color: #c00; font-weight: bold; }}
tr.before td {{ color: #888; font-style: italic; }}
</style></head>
<body>
<h1>{html.escape(title)}</h1>
<img alt="session plots" src="data:image/png;base64,{base64.b64encode(png).decode()}">
<h2>Events ({len(s.events)})</h2>
<table><tr><th>t [s since the start]</th><th>sim t [s]</th><th>severity</th><th>source</th><th>kind</th>
<th>message</th></tr>
{rows}
</table>
</body></html>
"""
