"""What ``lunaris watch`` draws: a snapshot of the twin as rich tables and panels.

Pure rendering: a :class:`Snapshot` (the latest payload of every key, the events, the
faults in effect, the live services) and the :class:`Connection` state in, a rich
renderable out. ``lunaris.watch`` keeps the snapshot up to date from Zenoh.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec
from rich import box
from rich.columns import Columns
from rich.console import Group, JustifyMethod, RenderableType
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from common import keys
from common.messages import (
    BatteryState,
    Clock,
    DriveState,
    Event,
    LoadPower,
    PowerSummary,
    RadioLink,
    RailState,
    SolarPower,
    UmbilicalState,
    decode,
)
from lunaris.client import Link, Session

__all__ = ["DRIVE_STYLE", "RAIL_STYLE", "Connection", "Snapshot", "banner", "duration", "render_fleet",
           "render_rover", "rover_header", "severity_style", "trainee_label", "worst"]

SEVERITY_STYLE = {"info": "cyan", "warning": "yellow", "critical": "bold red"}
SEVERITY_RANK = {"info": 0, "warning": 1, "critical": 2}
RAIL_STYLE = {"on": "green", "off": "dim", "shed": "yellow", "tripped": "bold red", "failed": "bold red"}
DRIVE_STYLE = {"driving": "green", "power_limited": "bold yellow", "unpowered": "bold red",
               "arrived": "cyan", "parked": ""}
STALE_S = 3.0  # telemetry older than this (wall time) is flagged


@dataclass
class Snapshot:
    """A consistent copy of the store, what one frame is drawn from."""

    latest: dict[str, tuple[bytes, float]]  # key -> (payload, wall time received)
    events: list[tuple[str, Event]]  # (rover, event), oldest first
    faults: dict[str, list[dict]]  # rover -> the faults in effect (the owners' records)
    services: dict[str, set[str]]  # rover -> live services
    now: float = field(default_factory=time.time)  # the clock of the times in ``latest``
    links: dict[str, Link] = field(default_factory=dict)  # rover -> its link (lunaris.client)
    sessions: dict[str, Session] = field(default_factory=dict)  # rover -> its trainee session

    def rovers(self) -> list[str]:
        found = set(self.services) | set(self.faults) | set(self.links)
        for key in self.latest:
            rover, _ = keys.split(key)
            found.add(rover)
        return sorted(found)

    def value(self, key: str, typ: type) -> tuple[Any, float] | None:
        """The decoded latest value of ``key`` and its age [s], or None."""
        got = self.latest.get(key)
        if got is None:
            return None
        try:
            return decode(got[0], typ), self.now - got[1]
        except (msgspec.DecodeError, msgspec.ValidationError):
            return None

    def named(self, rover: str, head: str, tail: str, typ: type) -> dict[str, Any]:
        """``head/<name>/tail`` values of a rover by name (``rail/*/state``)."""
        prefix, out = f"{keys.rover_prefix(rover)}/{head}/", {}
        for key in sorted(self.latest):
            if key.startswith(prefix) and key.endswith(f"/{tail}"):
                name = key[len(prefix):-len(tail) - 1]
                got = self.value(key, typ)
                if got is not None and "/" not in name:
                    out[name] = got[0]
        return out


@dataclass
class Connection:
    """The state of the link to the router, as the banner shows it."""

    endpoint: str
    state: str = "connecting"  # connecting | connected | disconnected
    since: float = field(default_factory=time.time)  # of the current state
    reconnected_after_s: float | None = None  # the last outage, shown for a while

    def update(self, connected: bool, now: float | None = None) -> None:
        now = time.time() if now is None else now
        new = "connected" if connected else ("disconnected" if self.state != "connecting" else "connecting")
        if new == self.state:
            return
        if self.state == "disconnected" and new == "connected":
            self.reconnected_after_s = now - self.since
        self.state, self.since = new, now


# -- drawing ----------------------------------------------------------------------------------


def severity_style(severity: str) -> str:
    return SEVERITY_STYLE.get(severity, "")


def worst(faults: list[dict], contains: str = "") -> str | None:
    sevs = [f.get("severity", "warning") for f in faults if contains in f.get("key", "")]
    return max(sevs, key=lambda s: SEVERITY_RANK.get(s, 1)) if sevs else None


def duration(s: float | None) -> str:
    if s is None:
        return "-"
    if s >= 3600:
        return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"
    if s >= 60:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{s:.0f} s"


def _clock_text(t_s: float) -> str:
    return f"{int(t_s // 3600):02d}:{int(t_s % 3600 // 60):02d}:{t_s % 60:04.1f}"


def banner(conn: Connection, now: float) -> Text:
    text = Text()
    if conn.state == "connecting":
        text.append(f" CONNECTING to {conn.endpoint} ... ", style="bold black on yellow")
    elif conn.state == "disconnected":
        text.append(f" DISCONNECTED from the router at {conn.endpoint} for {duration(now - conn.since)}"
                    " - retrying; values below are the last received ", style="bold white on red")
    else:
        text.append(f" connected to {conn.endpoint} ", style="bold black on green")
        if conn.reconnected_after_s is not None and now - conn.since < 15.0:
            text.append(f"  reconnected after an outage of {duration(conn.reconnected_after_s)}",
                        style="bold green")
    return text


def _kv(rows: Sequence[tuple[str, Text | str]]) -> Table:
    t = Table.grid(padding=(0, 1))
    t.add_column(style="bold", no_wrap=True)
    t.add_column(no_wrap=True)
    for name, value in rows:
        t.add_row(name, value)
    return t


def _battery_panel(snap: Snapshot, rover: str, faults: list[dict]) -> Panel:
    got = snap.value(keys.battery_state(rover), BatteryState)
    battery_worst = worst(faults, "/battery/")
    if got is None:
        return Panel("waiting for battery/state ...", title="battery", border_style="dim", expand=False)
    b, age = got
    soc_style = "bold red" if b.soc < 0.1 else "yellow" if b.soc < 0.2 else "green"
    temp_faults = [f for f in b.faults if "temperature" in f or "cutoff" in f or f == "heating"]
    temp_style = severity_style(worst([f for f in faults if any(n in f["key"] for n in temp_faults)]) or "")
    status = Text("operational", style="green") if b.operational else Text("NOT OPERATIONAL",
                                                                             style="bold red")
    if b.faults:
        status.append(f"  {', '.join(b.faults)} (code {b.fault_code})",
                      style=severity_style(battery_worst or "warning"))
    rows: list[tuple[str, Text | str]] = [
        ("energy", f"{b.energy_j / 1e3:8.1f} kJ of {b.capacity_j / 1e3:.1f} kJ"),
        ("state of charge", Text(f"{b.soc * 100:8.2f} %", style=soc_style)),
        ("voltage", f"{b.voltage_v:8.2f} V   (open circuit {b.ocv_v:.2f} V)"),
        ("current", f"{b.current_a:8.2f} A   ({b.power_w:.1f} W)"),
        ("temperature", Text(f"{b.temperature_c:8.1f} C", style=temp_style)),
        ("time to empty", "- (not draining)" if b.time_to_empty_s is None
         else f"{duration(b.time_to_empty_s)}   (at this draw; predict counts shedding)"),
        ("status", status),
    ]
    if age > STALE_S:
        rows.append(("", Text(f"no update for {duration(age)}", style="yellow")))
    return Panel(_kv(rows), title="battery",
                 border_style=severity_style(battery_worst) if battery_worst else "blue",
                 expand=False)


def _power_panel(snap: Snapshot, rover: str) -> Panel:
    rows: list[tuple[str, Text | str]] = []
    got = snap.value(keys.power_summary(rover), PowerSummary)
    if got is not None:
        p = got[0]
        rows += [("loads", f"{p.load_power_w:7.1f} W"), ("bus draw", f"{p.bus_power_w:7.1f} W"),
                 ("generation", f"{p.generation_w:7.1f} W"),
                 ("net battery", f"{p.net_battery_power_w:7.1f} W"),
                 ("bus voltage", f"{p.bus_voltage_v:7.2f} V")]
    for name, s in snap.named(rover, "solar", "power", SolarPower).items():
        style = "yellow" if s.faults or s.dust > 0 else ""
        extra = f"  {', '.join(s.faults)}" if s.faults else ""
        rows.append((f"solar {name}", Text(f"{s.power_w:7.1f} W  sun {s.sun_angle_deg:.0f} deg  "
                                           f"dust {s.dust * 100:.0f} %{extra}", style=style)))
    got_u = snap.value(keys.umbilical_state(rover), UmbilicalState)
    if got_u is not None:
        u = got_u[0]
        rows.append(("umbilical", Text(f"{u.power_w:7.1f} W  connected" if u.connected
                                       else "disconnected", style="green" if u.connected else "dim")))
    if not rows:
        return Panel("waiting for power/summary ...", title="power", border_style="dim", expand=False)
    return Panel(_kv(rows), title="power, solar, umbilical", border_style="blue", expand=False)


def _radio_panel(snap: Snapshot, rover: str) -> Panel:
    radios = snap.named(rover, "radio", "link", RadioLink)
    if not radios:
        return Panel("no radio", title="radios", border_style="dim", expand=False)
    rows = []
    for name, r in radios.items():
        state = Text("IN RANGE", style="green") if r.in_range else Text("OUT OF RANGE", style="bold red")
        if r.faults:
            state.append(f"  {', '.join(r.faults)}", style="yellow")
        state.append(f"  x {r.x_m:.0f} m  y {r.y_m:.0f} m")
        rows.append((name, state))
    return Panel(_kv(rows), title="radios", border_style="blue", expand=False)


def _drive_panel(snap: Snapshot, rover: str) -> Panel | None:
    """The drive of a rover that has one (None for a rover that does not drive)."""
    got = snap.value(keys.drive_state(rover), DriveState)
    if got is None:
        return None
    d, age = got
    status = Text(d.status.replace("_", " ").upper(), style=DRIVE_STYLE.get(d.status, ""))
    if d.waypoint is not None:
        traverse = f"to waypoint {d.waypoint + 1} of {d.waypoints}, {d.remaining_m:,.0f} m to go"
    else:
        traverse = "arrived" if d.status == "arrived" else "none"
    rows: list[tuple[str, Text | str]] = [
        ("status", status),
        ("position", f"x {d.x_m:,.1f}  y {d.y_m:,.1f}  z {d.z_m:,.1f} m"),
        ("heading", f"{d.heading_deg:5.0f} deg   grade {d.grade_deg:+.1f} deg"),
        ("speed", f"{d.speed_m_per_s:8.2f} m/s"),
        ("power", Text(f"{d.power_w:8.1f} W   force {d.tractive_force_n:,.1f} N   torque "
                       f"{d.wheel_torque_nm:,.2f} N m",
                       style="yellow" if d.status == "power_limited" else "")),
        ("traverse", traverse),
        ("odometer", f"{d.odometer_m:8,.1f} m   drive energy {d.energy_j / 3600:,.2f} Wh"),
    ]
    if age > STALE_S:
        rows.append(("", Text(f"no update for {duration(age)}", style="yellow")))
    return Panel(_kv(rows), title="drive", border_style="red" if d.status == "unpowered" else "blue",
                 expand=False)


def _pdm_table(snap: Snapshot, rover: str) -> Table:
    rails = snap.named(rover, "rail", "state", RailState)
    loads = snap.named(rover, "load", "power", LoadPower)
    t = Table(title="PDM", box=box.SIMPLE_HEAD, padding=(0, 1), title_justify="left",
              title_style="bold")
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("rail / load", "left"), ("state", "left"), ("V", "right"), ("A", "right"), ("W", "right"),
        ("limit A", "right"), ("faults", "left"))
    for name, justify in columns:
        t.add_column(name, justify=justify, no_wrap=True)
    for rname, r in rails.items():
        style = RAIL_STYLE.get(r.state, "")
        limit = f"{r.current_limit_a:.1f}" if r.current_limit_a is not None else "-"
        t.add_row(Text(rname, style="bold"), Text(r.state, style=style), f"{r.voltage_v:.2f}",
                  f"{r.current_a:.3f}", f"{r.power_w:.2f}", limit, Text(r.reason, style=style))
        for lname, ld in loads.items():
            if ld.rail == rname:
                t.add_row(f"  {lname}", Text("on" if ld.on else "off", style="" if ld.on else "dim"),
                          "", "", f"{ld.power_w:.2f}", "",
                          Text(", ".join(ld.faults), style="yellow" if ld.faults else ""))
    orphans = {n: ld for n, ld in loads.items() if ld.rail not in rails}
    for lname, ld in orphans.items():
        t.add_row(f"  {lname}", "on" if ld.on else "off", "", "", f"{ld.power_w:.2f}", "",
                  ", ".join(ld.faults))
    if not rails and not loads:
        t.add_row("waiting for rails ...", "", "", "", "", "", "")
    return t


def _faults_table(faults_by_rover: dict[str, list[dict]], fleet: bool) -> Table:
    t = Table(title="active faults", box=box.SIMPLE_HEAD, padding=(0, 1), title_justify="left",
              title_style="bold")
    if fleet:
        t.add_column("rover", no_wrap=True)
    for name in ("since", "severity", "origin", "fault", "params"):
        t.add_column(name, no_wrap=name != "params", justify="right" if name == "since" else "left")
    count = 0
    for rover, faults in sorted(faults_by_rover.items()):
        prefix = keys.rover_prefix(rover) + "/"
        for f in faults:
            count += 1
            style = severity_style(f.get("severity", "warning"))
            name = f["key"].removeprefix(prefix).removeprefix("fault/")
            params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                              for k, v in (f.get("params") or {}).items())
            row = [f"{f.get('since_t_s', 0):.1f} s", Text(f.get("severity", ""), style=style),
                   f.get("origin", ""), Text(name, style=style), params]
            t.add_row(*([rover] if fleet else []), *row)
    if not count:
        t.add_row(*([""] if fleet else []), "", Text("none", style="green"), "", "", "")
    return t


def _events_table(events: list[tuple[str, Event]], n: int, fleet: bool) -> Table:
    t = Table(title=f"latest events ({min(n, len(events))} of {len(events)})", box=box.SIMPLE_HEAD,
              padding=(0, 1), title_justify="left", title_style="bold", expand=True)
    if fleet:
        t.add_column("rover", no_wrap=True)
    t.add_column("t", justify="right", no_wrap=True)
    t.add_column("severity", no_wrap=True)
    t.add_column("source", no_wrap=True)
    t.add_column("kind", no_wrap=True)
    t.add_column("message", overflow="ellipsis", no_wrap=True, ratio=1)
    for rover, ev in events[-n:] if n > 0 else []:
        style = severity_style(ev.severity)
        row: list[RenderableType] = [f"{ev.t_s:.1f} s", Text(ev.severity, style=style), ev.source,
                                     Text(ev.kind, style=style), ev.message]
        t.add_row(*([rover] if fleet else []), *row)
    return t


def trainee_label(snap: Snapshot, rover: str) -> str:
    """Who the rover's running session trains: ``Ana``, ``no trainee named``, ``trainee ?``
    (the event that opened the session not heard), or "" before the clock's first tick."""
    session = snap.sessions.get(rover)
    if session is None:
        return ""
    if session.trainee is None:
        return "trainee ?"
    return session.trainee or "no trainee named"


def rover_header(snap: Snapshot, rover: str) -> Text:
    text = Text(f"LUNARIS  {rover}", style="bold")
    session = snap.sessions.get(rover)
    if session is not None:
        text.append(f"   {trainee_label(snap, rover)}", style="bold cyan")
        text.append(f" (session {session.id})", style="dim")
    got = snap.value(keys.clock(rover), Clock)
    if got is not None:
        c, age = got
        text.append(f"   sim t {_clock_text(c.t_s)}  ({c.t_s:.1f} s)  x{c.time_scale:g}")
        if c.paused:
            text.append("  PAUSED", style="bold yellow")
        if age > STALE_S:
            text.append(f"  no clock for {duration(age)}", style="bold yellow")
    else:
        text.append("   waiting for the clock ...", style="yellow")
    services = snap.services.get(rover, set())
    text.append(f"   services {len(services)}: {', '.join(sorted(services)) or 'none'}",
                style="" if services else "yellow")
    link = snap.links.get(rover)
    if link is not None and link.state == "lost":
        text.append(f"\n LINK LOST to {rover}: {link.reason}; values below are the last received ",
                    style="bold white on red")
    return text


def render_rover(snap: Snapshot, rover: str, n_events: int) -> RenderableType:
    faults = snap.faults.get(rover, [])
    # Columns keep each part at its natural width and wrap on a narrow terminal.
    drive = _drive_panel(snap, rover)
    top = Columns([_battery_panel(snap, rover, faults), _power_panel(snap, rover),
                   _radio_panel(snap, rover), *([drive] if drive is not None else [])], padding=(0, 1))
    middle = Columns([_pdm_table(snap, rover), _faults_table({rover: faults}, fleet=False)],
                     padding=(0, 3))
    events = [(r, e) for r, e in snap.events if r == rover]
    return Group(rover_header(snap, rover), top, middle, _events_table(events, n_events, fleet=False))


def render_fleet(snap: Snapshot, n_events: int) -> RenderableType:
    t = Table(title=f"fleet: {len(snap.rovers())} rover(s)", box=box.SIMPLE_HEAD, title_justify="left",
              title_style="bold")
    for name in ("rover", "sim t", "x", "SoC", "V", "A", "C", "to empty", "loads W", "gen W",
                 "rails on", "radios", "drive", "faults", "services"):
        t.add_column(name, no_wrap=True, justify="left" if name in ("rover", "radios", "drive")
                     else "right")
    for rover in snap.rovers():
        c = snap.value(keys.clock(rover), Clock)
        b = snap.value(keys.battery_state(rover), BatteryState)
        p = snap.value(keys.power_summary(rover), PowerSummary)
        rails = snap.named(rover, "rail", "state", RailState)
        radios = snap.named(rover, "radio", "link", RadioLink)
        faults = snap.faults.get(rover, [])
        worst_severity = worst(faults)
        bad_rails = sum(1 for r in rails.values() if r.state in ("tripped", "failed"))
        link = snap.links.get(rover)
        lost = link is not None and link.state == "lost"
        trainee = trainee_label(snap, rover)
        row: list[Text | str] = [Text(rover + (f" ({trainee})" if trainee else "")
                                      + (" LINK LOST" if lost else ""),
                                      style="bold white on red" if lost else "bold")]
        row += [f"{c[0].t_s:.1f}", f"{c[0].time_scale:g}"] if c else ["-", "-"]
        if b:
            bs = b[0]
            soc_style = "bold red" if bs.soc < 0.1 else "yellow" if bs.soc < 0.2 else ""
            row += [Text(f"{bs.soc * 100:.1f} %", style=soc_style), f"{bs.voltage_v:.2f}",
                    f"{bs.current_a:.2f}", f"{bs.temperature_c:.1f}", duration(bs.time_to_empty_s)]
        else:
            row += ["-"] * 5
        row += [f"{p[0].load_power_w:.1f}", f"{p[0].generation_w:.1f}"] if p else ["-", "-"]
        on = sum(1 for r in rails.values() if r.state == "on")
        row.append(Text(f"{on}/{len(rails)}", style="bold red" if bad_rails else ""))
        row.append(Text(" ".join(f"{n}:{'in' if r.in_range else 'OUT'}" for n, r in radios.items()),
                        style="" if all(r.in_range for r in radios.values()) else "bold red"))
        d = snap.value(keys.drive_state(rover), DriveState)
        row.append(Text(f"{d[0].status.replace('_', ' ')} {d[0].speed_m_per_s:.2f} m/s "
                        f"{d[0].odometer_m:,.0f} m", style=DRIVE_STYLE.get(d[0].status, ""))
                   if d else "-")
        fault_style = severity_style(worst_severity) if worst_severity else "green"
        row.append(Text(str(len(faults)), style=fault_style))
        row.append(str(len(snap.services.get(rover, ()))))
        t.add_row(*row)
    if not snap.rovers():
        t.add_row("waiting for rovers ...", *[""] * 14)
    return Group(t, _faults_table(snap.faults, fleet=True), _events_table(snap.events, n_events, fleet=True))
