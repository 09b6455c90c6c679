"""``lunaris report FILE.mcap -o OUT.png|OUT.html``: a recorded session, drawn for the debrief.

One figure per rover against simulated time: state of charge, battery voltage
and current, battery temperature, the power of each load, generation (each
solar panel, the umbilical and the total) against the load, and the session's
fault events as marks across every plot (injected, cleared, raised, resolved,
rejected), coloured by severity. A rover that drove also gets its path in the site
frame, coloured by the drive's power. ``.html`` embeds the figure and adds the event
table. Drawn with matplotlib's Agg backend: no display needed.
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

__all__ = ["Session", "add_arguments", "draw", "load_session", "main"]

MARK_KINDS = {"fault_injected": "+", "fault_cleared": "-", "fault_raised": "!",
              "fault_resolved": "ok ", "rejected": "x "}
SEVERITY_COLOUR = {"info": "tab:blue", "warning": "tab:orange", "critical": "tab:red"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap", help="a recording made by lunaris record")
    p.add_argument("-o", "--output", metavar="OUT", default=None,
                   help="OUT.png or OUT.html (default: FILE with .png)")
    p.add_argument("--rover", metavar="ID", help="the rover to draw (needed when several were recorded)")


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
    events: list[dict] = field(default_factory=list)

    @property
    def span_s(self) -> tuple[float, float]:
        ts = self.battery["soc"][0] or self.summary["load_power_w"][0]
        return (min(ts), max(ts)) if ts else (0.0, 0.0)


def _add(series: Series, t: float, v: float | None) -> None:
    if v is not None:
        series[0].append(t)
        series[1].append(float(v))


def load_session(path: Path) -> dict[str, Session]:
    """Every rover's series from a recording (raises ValueError if it is not an MCAP file)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    sessions: dict[str, Session] = {}
    seen_events: set[tuple] = set()
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
        family = fam.name if fam is not None else None
        if family is None:
            continue
        try:
            v = msgspec.json.decode(message.data)
        except msgspec.DecodeError:
            continue
        s = sessions.setdefault(rover, Session(rover))
        t = v.get("t_s", 0.0)
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
        elif family == "event":
            ident = (rover, t, v.get("kind"), v.get("key"), v.get("message"))
            if ident not in seen_events:  # a cache replayed after a reconnection
                seen_events.add(ident)
                s.events.append(v)
    for s in sessions.values():
        s.events.sort(key=lambda e: e.get("t_s", 0.0))
    return sessions


def _marks(s: Session) -> list[dict]:
    return [e for e in s.events if e.get("kind") in MARK_KINDS]


def _short(s: Session, e: dict) -> str:
    name = e.get("key", "").removeprefix(keys.rover_prefix(s.rover) + "/").removeprefix("fault/")
    return f"{MARK_KINDS.get(e.get('kind', ''), '')}{name}"


def draw(s: Session, title: str):
    """The debrief figure of one rover (a matplotlib Figure, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drove = len(s.path[0]) > 0
    fig, all_axes = plt.subplots(6 if drove else 5, 1, figsize=(13, 24 if drove else 16),
                                 constrained_layout=True,
                                 gridspec_kw={"height_ratios": [1] * 5 + ([2.2] if drove else [])})
    axes = all_axes[:5]  # against time
    for ax in axes[1:]:
        ax.sharex(axes[0])
    ax_soc, ax_vi, ax_temp, ax_loads, ax_gen = axes
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
    ax_gen.set_xlabel("simulated time [s]")
    t0, t1 = s.span_s
    # Events replayed from the publishers' caches may predate the recording: list them in the
    # HTML table, but keep the time axis on the recorded telemetry.
    marks = [e for e in _marks(s) if t0 <= e.get("t_s", 0.0) <= t1]
    for ax in (*axes, ax_i):
        ax.ticklabel_format(axis="y", useOffset=False)
    ax_gen.set_xlim(t0, max(t1, t0 + 1e-3))
    for ax in axes:
        ax.grid(True, alpha=0.3)
        for e in marks:
            ax.axvline(e.get("t_s", 0.0), color=SEVERITY_COLOUR.get(e.get("severity", ""), "gray"),
                       alpha=0.6, linewidth=1.0, linestyle=":" if e.get("kind") == "rejected" else "-")
    for i, e in enumerate(marks[:40]):  # labels beyond that would only be ink
        ax_soc.annotate(_short(s, e), xy=(e.get("t_s", 0.0), 1.0), xycoords=("data", "axes fraction"),
                        xytext=(2, -4 - 9 * (i % 6)), textcoords="offset points", fontsize="x-small",
                        va="top", color=SEVERITY_COLOUR.get(e.get("severity", ""), "gray"))
    if drove:
        _draw_path(fig, all_axes[5], s)
    fig.suptitle(title)
    return fig


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
    t0, t1 = s.span_s
    title = f"{rover} - {path.name} - sim time {t0:.0f} to {t1:.0f} s"
    fig = draw(s, title)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=100)
    if out.suffix.lower() == ".png":
        out.write_bytes(png.getvalue())
    else:
        out.write_text(_html(s, title, png.getvalue()))
    drove = f", a path of {len(s.path[0])} positions" if s.path[0] else ""
    print(f"wrote {out}: {rover}, {t1 - t0:.0f} s of sim time, {len(s.loads)} loads{drove}, "
          f"{len(_marks(s))} fault event(s), {len(s.events)} event(s) in all")
    return 0


def _html(s: Session, title: str, png: bytes) -> str:
    rows = "\n".join(
        f"<tr class='{html.escape(e.get('severity', ''))}'><td>{e.get('t_s', 0.0):.1f}</td>"
        f"<td>{html.escape(e.get('severity', ''))}</td><td>{html.escape(e.get('source', ''))}</td>"
        f"<td>{html.escape(e.get('kind', ''))}</td><td>{html.escape(e.get('message', ''))}</td></tr>"
        for e in s.events)
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 2px 8px; border-bottom: 1px solid #ddd; }}
tr.warning td {{ color: #b36b00; }} tr.critical td {{ color: #c00; font-weight: bold; }}
</style></head>
<body>
<h1>{html.escape(title)}</h1>
<img alt="session plots" src="data:image/png;base64,{base64.b64encode(png).decode()}">
<h2>Events ({len(s.events)})</h2>
<table><tr><th>sim t [s]</th><th>severity</th><th>source</th><th>kind</th><th>message</th></tr>
{rows}
</table>
</body></html>
"""
