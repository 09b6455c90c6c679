"""What ``lunaris watch`` draws on a small terminal (80x24): the same snapshot, compacted.

Narrower than :data:`lunaris.watch_view.COMPACT_BELOW` columns, a rover is a line each for its
battery, power, radios and drive, its rails (not their loads), its faults and as many of the
latest events as the height leaves room for; the fleet is one short row per rover.
"""

from __future__ import annotations

from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from common import keys
from common.messages import BatteryState, Clock, DriveState, PowerSummary, RadioLink, RailState, SolarPower
from lunaris.watch_view import (
    DRIVE_STYLE,
    RAIL_STYLE,
    Snapshot,
    duration,
    rover_header,
    severity_style,
    trainee_label,
    worst,
)

__all__ = ["fleet_compact", "render_compact"]


def render_compact(snap: Snapshot, rover: str, height: int) -> RenderableType:
    """One rover on a small terminal (80x24): a line each for the battery, the power, the
    radios and the drive; the rails (not their loads); the faults; as many events as fit."""
    lines: list[RenderableType] = [rover_header(snap, rover)]
    got = snap.value(keys.battery_state(rover), BatteryState)
    if got is not None:
        b = got[0]
        line = Text("battery ", style="bold")
        soc_style = "bold red" if b.soc < 0.1 else "yellow" if b.soc < 0.2 else "green"
        line.append(f"{b.soc * 100:6.2f} %", style=soc_style)
        line.append(f"  {b.voltage_v:.2f} V  {b.current_a:.2f} A  {b.temperature_c:.1f} C  empty in "
                    f"{duration(b.time_to_empty_s) if b.time_to_empty_s is not None else '-'}  ")
        line.append("ok" if b.operational else "NOT OPERATIONAL",
                    style="green" if b.operational else "bold red")
        if b.faults:
            line.append(f"  {', '.join(b.faults)}", style="yellow")
        lines.append(line)
    p = snap.value(keys.power_summary(rover), PowerSummary)
    if p is not None:
        panels = snap.named(rover, "solar", "power", SolarPower)
        sun = " ".join(f"{n} {s.power_w:.0f} W" for n, s in panels.items())
        lines.append(Text(f"power   loads {p[0].load_power_w:.1f} W  gen {p[0].generation_w:.1f} W  net "
                          f"{p[0].net_battery_power_w:.1f} W  ({sun})"))
    radios = snap.named(rover, "radio", "link", RadioLink)
    d = snap.value(keys.drive_state(rover), DriveState)
    if radios or d:
        line = Text("radio   ")
        for n, r in radios.items():
            line.append(f"{n} {'in' if r.in_range else 'OUT'}  ", style="green" if r.in_range else "bold red")
        if d:
            line.append(f"drive {d[0].status.replace('_', ' ')} {d[0].speed_m_per_s:.2f} m/s "
                        f"{d[0].odometer_m:,.0f} m", style=DRIVE_STYLE.get(d[0].status, ""))
        lines.append(line)
    rails = snap.named(rover, "rail", "state", RailState)
    t = Table(box=None, padding=(0, 1), show_edge=False, pad_edge=False)
    for name, justify in (("rail", "left"), ("state", "left"), ("V", "right"), ("A", "right"),
                          ("W", "right"), ("limit", "right")):
        t.add_column(name, justify=justify, no_wrap=True)  # type: ignore[arg-type]
    for name, r in rails.items():
        t.add_row(name, Text(r.state, style=RAIL_STYLE.get(r.state, "")), f"{r.voltage_v:.2f}",
                  f"{r.current_a:.2f}", f"{r.power_w:.1f}",
                  f"{r.current_limit_a:.1f}" if r.current_limit_a is not None else "-")
    lines.append(t)
    faults = snap.faults.get(rover, [])
    prefix = keys.rover_prefix(rover) + "/"
    text = Text("faults  ")
    if not faults:
        text.append("none", style="green")
    for f in faults[:4]:
        name = f["key"].removeprefix(prefix).removeprefix("fault/")
        text.append(name + "  ", style=severity_style(f.get("severity", "")))
    if len(faults) > 4:
        text.append(f"+{len(faults) - 4} more")
    lines.append(text)
    used = 3 + len(lines) + len(rails) + 1
    events = [e for r, e in snap.events if r == rover][-max(1, height - used - 1):]
    for ev in events:
        line = Text(f"{ev.t_s:7.1f} s ", style="dim")
        line.append(f"{ev.kind} ", style=severity_style(ev.severity))
        line.append(ev.message)
        line.truncate(200)
        lines.append(line)
    return Group(*lines)


def fleet_compact(snap: Snapshot, n_events: int) -> RenderableType:
    t = Table(title=f"fleet: {len(snap.rovers())} rover(s)", box=None, padding=(0, 1), title_justify="left",
              title_style="bold")
    for name in ("rover", "sim t", "SoC", "V", "A", "C", "rails", "faults"):
        t.add_column(name, no_wrap=True, justify="left" if name == "rover" else "right")
    for rover in snap.rovers():
        c = snap.value(keys.clock(rover), Clock)
        b = snap.value(keys.battery_state(rover), BatteryState)
        rails = snap.named(rover, "rail", "state", RailState)
        faults = snap.faults.get(rover, [])
        worst_severity = worst(faults)
        on = sum(1 for r in rails.values() if r.state == "on")
        link = snap.links.get(rover)
        lost = link is not None and link.state == "lost"
        trainee = trainee_label(snap, rover)
        label = Text(rover + (f" ({trainee})" if trainee else "") + (" LOST" if lost else ""),
                     style="bold white on red" if lost else "bold")
        fault_style = severity_style(worst_severity) if worst_severity else "green"
        t.add_row(label, f"{c[0].t_s:.0f}" if c else "-",
                  f"{b[0].soc * 100:.1f} %" if b else "-", f"{b[0].voltage_v:.1f}" if b else "-",
                  f"{b[0].current_a:.1f}" if b else "-", f"{b[0].temperature_c:.0f}" if b else "-",
                  f"{on}/{len(rails)}", Text(str(len(faults)), style=fault_style))
    events = [Text(f"{r} {e.t_s:.1f} s {e.kind}: {e.message}", overflow="ellipsis", no_wrap=True)
              for r, e in snap.events[-min(n_events, 6):]]
    return Group(t, *events)
