"""``lunaris watch [--rover ID]``: a live terminal view of one rover, or of the whole fleet.

With ``--rover`` it shows the battery (energy, state of charge, voltage, current,
temperature, time to empty), the power summary, solar panels and umbilical,
radios, the PDM table (every rail with its loads), the active faults and the
latest events; alarms are coloured by severity. Without it, one line per rover,
the fleet's active faults and events.

The session's subscriptions are advanced subscribers with history, so values
appear at once when the tool joins a running session. The view says when the
router goes away ("DISCONNECTED ... retrying"): Zenoh keeps trying to reconnect,
and when it does the subscriptions are restored and the view says so.

On a terminal the view is a full-screen ``rich`` display refreshed a few times a
second (Ctrl-C quits); piped, it prints a snapshot every ``--interval`` seconds,
or once with ``--once``.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext
from rich import box
from rich.columns import Columns
from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from common import keys
from common.connection import add_connection_args
from common.messages import (
    BatteryState,
    Clock,
    Event,
    LoadPower,
    PowerSummary,
    RadioLink,
    RailState,
    SolarPower,
    UmbilicalState,
    decode,
)
from lunaris.telemetry import FAMILIES, family_of
from lunaris.tooling import ToolError, describe_endpoint, open_session

__all__ = ["Connection", "Snapshot", "Store", "add_arguments", "main", "render"]

SEVERITY_STYLE = {"info": "cyan", "warning": "yellow", "critical": "bold red"}
SEVERITY_RANK = {"info": 0, "warning": 1, "critical": 2}
RAIL_STYLE = {"on": "green", "off": "dim", "shed": "yellow", "tripped": "bold red", "failed": "bold red"}
STALE_S = 3.0  # telemetry older than this (wall time) is flagged
FAULT_KINDS = {"fault_injected", "fault_cleared", "fault_raised", "fault_resolved"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rover", metavar="ID", help="show one rover in detail (default: the fleet)")
    p.add_argument("--events", type=int, default=8, metavar="N", help="latest events shown (default 8)")
    p.add_argument("--refresh", type=float, default=4.0, metavar="HZ",
                   help="screen refreshes per second (default 4)")
    p.add_argument("--once", action="store_true",
                   help="print one snapshot once data has arrived, then exit")
    p.add_argument("--interval", type=float, default=5.0, metavar="S",
                   help="seconds between snapshots when the output is not a terminal (default 5)")
    p.add_argument("--width", type=int, default=None, help="render width (default: the terminal's)")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="--once: how long to wait for data (default 10 s)")
    add_connection_args(p)


# -- what the view knows, kept up to date by Zenoh callbacks --------------------------------


@dataclass
class Snapshot:
    """A consistent copy of the store, what one frame is drawn from."""

    latest: dict[str, tuple[bytes, float]]  # key -> (payload, wall time received)
    events: list[tuple[str, Event]]  # (rover, event), oldest first
    faults: dict[str, list[dict]]  # rover -> active faults (the journal's answer)
    services: dict[str, set[str]]  # rover -> live services
    now: float = field(default_factory=time.monotonic)

    def rovers(self) -> list[str]:
        found = set(self.services) | set(self.faults)
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


class Store:
    """Thread-safe: Zenoh calls back on its own threads, the view reads snapshots."""

    def __init__(self, max_events: int = 500):
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[bytes, float]] = {}
        self._events: deque[tuple[str, Event]] = deque(maxlen=max_events)
        self._seen: set[tuple] = set()
        self._faults: dict[str, list[dict]] = {}
        self._services: dict[str, set[str]] = {}
        self.faults_changed = threading.Event()
        self.last_sample = 0.0

    def on_sample(self, s: zenoh.Sample) -> None:
        key = str(s.key_expr)
        try:
            rover, parts = keys.split(key)
        except ValueError:
            return
        family = family_of(parts)
        if family is None or s.kind != zenoh.SampleKind.PUT:
            return
        payload, now = s.payload.to_bytes(), time.monotonic()
        if family == "event":
            try:
                ev = decode(payload, Event)
            except (msgspec.DecodeError, msgspec.ValidationError):
                return
            ident = (rover, ev.t_s, ev.source, ev.kind, ev.key, ev.message)
            with self._lock:
                self.last_sample = now
                if ident in self._seen:  # a cache replayed after a reconnection
                    return
                self._seen.add(ident)
                self._events.append((rover, ev))
            if ev.kind in FAULT_KINDS:
                self.faults_changed.set()
            return
        with self._lock:
            self._latest[key] = (payload, now)
            self.last_sample = now

    def on_token(self, s: zenoh.Sample) -> None:
        try:
            rover, parts = keys.split(str(s.key_expr))
        except ValueError:
            return
        with self._lock:
            live = self._services.setdefault(rover, set())
            (live.add if s.kind == zenoh.SampleKind.PUT else live.discard)(parts[-1])

    def set_faults(self, rover: str, faults: list[dict]) -> None:
        with self._lock:
            self._faults[rover] = faults

    def snapshot(self) -> Snapshot:
        with self._lock:
            events = sorted(self._events, key=lambda re: re[1].t_s)  # services interleave
            return Snapshot(dict(self._latest), events, dict(self._faults),
                            {r: set(s) for r, s in self._services.items()})


@dataclass
class Connection:
    """The state of the link to the router, as the banner shows it."""

    endpoint: str
    state: str = "connecting"  # connecting | connected | disconnected
    since: float = field(default_factory=time.monotonic)  # of the current state
    reconnected_after_s: float | None = None  # the last outage, shown for a while

    def update(self, connected: bool, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        new = "connected" if connected else ("disconnected" if self.state != "connecting" else "connecting")
        if new == self.state:
            return
        if self.state == "disconnected" and new == "connected":
            self.reconnected_after_s = now - self.since
        self.state, self.since = new, now


# -- drawing ----------------------------------------------------------------------------------


def _sev(severity: str) -> str:
    return SEVERITY_STYLE.get(severity, "")


def _worst(faults: list[dict], contains: str = "") -> str | None:
    sevs = [f.get("severity", "warning") for f in faults if contains in f.get("key", "")]
    return max(sevs, key=lambda s: SEVERITY_RANK.get(s, 1)) if sevs else None


def _duration(s: float | None) -> str:
    if s is None:
        return "-"
    if s >= 3600:
        return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"
    if s >= 60:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{s:.0f} s"


def _clock_text(t_s: float) -> str:
    return f"{int(t_s // 3600):02d}:{int(t_s % 3600 // 60):02d}:{t_s % 60:04.1f}"


def _banner(conn: Connection, now: float) -> Text:
    text = Text()
    if conn.state == "connecting":
        text.append(f" CONNECTING to {conn.endpoint} ... ", style="bold black on yellow")
    elif conn.state == "disconnected":
        text.append(f" DISCONNECTED from the router at {conn.endpoint} for {_duration(now - conn.since)}"
                    " - retrying; values below are the last received ", style="bold white on red")
    else:
        text.append(f" connected to {conn.endpoint} ", style="bold black on green")
        if conn.reconnected_after_s is not None and now - conn.since < 15.0:
            text.append(f"  reconnected after an outage of {_duration(conn.reconnected_after_s)}",
                        style="bold green")
    return text


def _kv(rows: list[tuple[str, Text | str]]) -> Table:
    t = Table.grid(padding=(0, 1))
    t.add_column(style="bold", no_wrap=True)
    t.add_column(no_wrap=True)
    for name, value in rows:
        t.add_row(name, value)
    return t


def _battery_panel(snap: Snapshot, rover: str, faults: list[dict]) -> Panel:
    got = snap.value(keys.battery_state(rover), BatteryState)
    worst = _worst(faults, "/battery/")
    if got is None:
        return Panel("waiting for battery/state ...", title="battery", border_style="dim", expand=False)
    b, age = got
    soc_style = "bold red" if b.soc < 0.1 else "yellow" if b.soc < 0.2 else "green"
    temp_faults = [f for f in b.faults if "temperature" in f or "cutoff" in f or f == "heating"]
    temp_style = _sev(_worst([f for f in faults if any(n in f["key"] for n in temp_faults)]) or "")
    status = Text("operational", style="green") if b.operational else Text("NOT OPERATIONAL",
                                                                             style="bold red")
    if b.faults:
        status.append(f"  {', '.join(b.faults)} (code {b.fault_code})", style=_sev(worst or "warning"))
    rows = [
        ("energy", f"{b.energy_j / 1e3:8.1f} kJ of {b.capacity_j / 1e3:.1f} kJ"),
        ("state of charge", Text(f"{b.soc * 100:8.2f} %", style=soc_style)),
        ("voltage", f"{b.voltage_v:8.2f} V   (open circuit {b.ocv_v:.2f} V)"),
        ("current", f"{b.current_a:8.2f} A   ({b.power_w:.1f} W)"),
        ("temperature", Text(f"{b.temperature_c:8.1f} C", style=temp_style)),
        ("time to empty", "- (not draining)" if b.time_to_empty_s is None else _duration(b.time_to_empty_s)),
        ("status", status),
    ]
    if age > STALE_S:
        rows.append(("", Text(f"no update for {_duration(age)}", style="yellow")))
    return Panel(_kv(rows), title="battery", border_style=_sev(worst) if worst else "blue",
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


def _pdm_table(snap: Snapshot, rover: str) -> Table:
    rails = snap.named(rover, "rail", "state", RailState)
    loads = snap.named(rover, "load", "power", LoadPower)
    t = Table(title="PDM", box=box.SIMPLE_HEAD, padding=(0, 1), title_justify="left",
              title_style="bold")
    for name, justify in (("rail / load", "left"), ("state", "left"), ("V", "right"), ("A", "right"),
                          ("W", "right"), ("limit A", "right"), ("faults", "left")):
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
            style = _sev(f.get("severity", "warning"))
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
        style = _sev(ev.severity)
        row = [f"{ev.t_s:.1f} s", Text(ev.severity, style=style), ev.source,
               Text(ev.kind, style=style), ev.message]
        t.add_row(*([rover] if fleet else []), *row)
    return t


def _rover_header(snap: Snapshot, rover: str) -> Text:
    text = Text(f"LUNARIS  {rover}", style="bold")
    got = snap.value(keys.clock(rover), Clock)
    if got is not None:
        c, age = got
        text.append(f"   sim t {_clock_text(c.t_s)}  ({c.t_s:.1f} s)  x{c.time_scale:g}")
        if c.paused:
            text.append("  PAUSED", style="bold yellow")
        if age > STALE_S:
            text.append(f"  no clock for {_duration(age)}", style="bold yellow")
    else:
        text.append("   waiting for the clock ...", style="yellow")
    services = snap.services.get(rover, set())
    text.append(f"   services {len(services)}: {', '.join(sorted(services)) or 'none'}",
                style="" if services else "yellow")
    return text


def render_rover(snap: Snapshot, rover: str, n_events: int) -> RenderableType:
    faults = snap.faults.get(rover, [])
    # Columns keep each part at its natural width and wrap on a narrow terminal.
    top = Columns([_battery_panel(snap, rover, faults), _power_panel(snap, rover),
                   _radio_panel(snap, rover)], padding=(0, 1))
    middle = Columns([_pdm_table(snap, rover), _faults_table({rover: faults}, fleet=False)],
                     padding=(0, 3))
    events = [(r, e) for r, e in snap.events if r == rover]
    return Group(_rover_header(snap, rover), top, middle, _events_table(events, n_events, fleet=False))


def render_fleet(snap: Snapshot, n_events: int) -> RenderableType:
    t = Table(title=f"fleet: {len(snap.rovers())} rover(s)", box=box.SIMPLE_HEAD, title_justify="left",
              title_style="bold")
    for name in ("rover", "sim t", "x", "SoC", "V", "A", "C", "to empty", "loads W", "gen W",
                 "rails on", "radios", "faults", "services"):
        t.add_column(name, no_wrap=True, justify="left" if name in ("rover", "radios") else "right")
    for rover in snap.rovers():
        c = snap.value(keys.clock(rover), Clock)
        b = snap.value(keys.battery_state(rover), BatteryState)
        p = snap.value(keys.power_summary(rover), PowerSummary)
        rails = snap.named(rover, "rail", "state", RailState)
        radios = snap.named(rover, "radio", "link", RadioLink)
        faults = snap.faults.get(rover, [])
        worst = _worst(faults)
        bad_rails = sum(1 for r in rails.values() if r.state in ("tripped", "failed"))
        row: list[Text | str] = [Text(rover, style="bold")]
        row += [f"{c[0].t_s:.1f}", f"{c[0].time_scale:g}"] if c else ["-", "-"]
        if b:
            bs = b[0]
            soc_style = "bold red" if bs.soc < 0.1 else "yellow" if bs.soc < 0.2 else ""
            row += [Text(f"{bs.soc * 100:.1f} %", style=soc_style), f"{bs.voltage_v:.2f}",
                    f"{bs.current_a:.2f}", f"{bs.temperature_c:.1f}", _duration(bs.time_to_empty_s)]
        else:
            row += ["-"] * 5
        row += [f"{p[0].load_power_w:.1f}", f"{p[0].generation_w:.1f}"] if p else ["-", "-"]
        on = sum(1 for r in rails.values() if r.state == "on")
        row.append(Text(f"{on}/{len(rails)}", style="bold red" if bad_rails else ""))
        row.append(Text(" ".join(f"{n}:{'in' if r.in_range else 'OUT'}" for n, r in radios.items()),
                        style="" if all(r.in_range for r in radios.values()) else "bold red"))
        row.append(Text(str(len(faults)), style=_sev(worst) if worst else "green"))
        row.append(str(len(snap.services.get(rover, ()))))
        t.add_row(*row)
    if not snap.rovers():
        t.add_row("waiting for rovers ...", *[""] * 13)
    return Group(t, _faults_table(snap.faults, fleet=True), _events_table(snap.events, n_events, fleet=True))


def render(snap: Snapshot, conn: Connection, rover: str | None, n_events: int) -> RenderableType:
    body = render_rover(snap, rover, n_events) if rover else render_fleet(snap, n_events)
    return Group(_banner(conn, snap.now), body)


# -- the session ------------------------------------------------------------------------------


class _Watcher:
    """Opens the session in the background and keeps the store and the connection state."""

    def __init__(self, args: argparse.Namespace, store: Store):
        self.args = args
        self.store = store
        self.conn = Connection(describe_endpoint(args))
        self.session: zenoh.Session | None = None
        self.error: str | None = None
        self.stop = threading.Event()
        self._keep: list[Any] = []
        self._threads = [threading.Thread(target=self._open, name="watch-open", daemon=True),
                         threading.Thread(target=self._poll_faults, name="watch-faults", daemon=True)]

    def start(self) -> None:
        for th in self._threads:
            th.start()

    def _open(self) -> None:
        try:
            session = open_session(self.args, wait_s=None)
        except ToolError as exc:
            self.error = str(exc)
            return
        root = f"{keys.ROOT}/{self.args.rover or '*'}"
        history = zext.HistoryConfig(detect_late_publishers=True)
        for family in FAMILIES:
            self._keep.append(zext.declare_advanced_subscriber(
                session, f"{root}/{family}", self.store.on_sample, history=history))
        self._keep.append(session.liveliness().declare_subscriber(
            f"{root}/service/*", self.store.on_token, history=True))
        self.session = session
        self.store.faults_changed.set()

    def _poll_faults(self) -> None:
        """The active faults, from the journal: at once after a fault event, else every 2 s."""
        while not self.stop.is_set():
            self.store.faults_changed.wait(2.0)
            self.store.faults_changed.clear()
            if not self.stop.is_set() and self.conn.state == "connected":
                self.query_faults()

    def query_faults(self) -> None:
        session = self.session
        if session is None:
            return
        try:
            for reply in session.get(keys.faults(self.args.rover or "*"), timeout=2.0):
                if reply.ok is None:
                    continue
                rover, _ = keys.split(str(reply.ok.key_expr))
                self.store.set_faults(rover, msgspec.json.decode(reply.ok.payload.to_bytes()))
        except (zenoh.ZError, msgspec.DecodeError, ValueError) as exc:
            print(f"lunaris watch: faults query failed: {exc}", file=sys.stderr)

    def refresh_connection(self) -> None:
        session = self.session
        if session is None:
            return
        try:
            connected = bool(session.info.routers_zid())
        except zenoh.ZError:
            connected = False
        was = self.conn.state
        self.conn.update(connected)
        if was == "disconnected" and connected:
            self.store.faults_changed.set()

    def close(self) -> None:
        """Stop the poller *before* the interpreter exits: a thread that comes back from a
        native Zenoh call during finalisation aborts the process."""
        self.stop.set()
        self.store.faults_changed.set()
        poller = self._threads[1]
        if poller.is_alive():
            poller.join(5.0)
        self._keep.clear()
        if self.session is not None:
            self.session.close()


def main(args: argparse.Namespace) -> int:
    store = Store()
    watcher = _Watcher(args, store)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    watcher.start()
    tty = sys.stdout.isatty() and not args.once
    console = Console(width=args.width) if args.width else Console()

    def frame() -> RenderableType:
        watcher.refresh_connection()
        return render(store.snapshot(), watcher.conn, args.rover, args.events)

    try:
        if args.once:
            return _once(args, watcher, store, console, frame)
        if tty:
            with Live(frame(), console=console, screen=True, auto_refresh=False,
                      redirect_stderr=False) as live:
                while not stop.wait(1.0 / max(0.5, args.refresh)):
                    if watcher.error:
                        break
                    live.update(frame(), refresh=True)
        else:
            while True:
                console.print(frame())
                console.print()
                sys.stdout.flush()
                if stop.wait(args.interval) or watcher.error:
                    break
    except KeyboardInterrupt:
        pass
    finally:
        watcher.close()
    if watcher.error:
        print(f"lunaris watch: {watcher.error}", file=sys.stderr)
        return 2
    return 0


def _once(args: argparse.Namespace, watcher: _Watcher, store: Store, console: Console, frame) -> int:
    deadline = time.monotonic() + args.timeout
    want = keys.battery_state(args.rover) if args.rover else None

    def ready() -> bool:
        snap = store.snapshot()
        return (want in snap.latest) if want else bool(snap.latest)

    while not ready() and time.monotonic() < deadline and not watcher.error:
        time.sleep(0.05)
    # The caches of the other publishers answer within a moment of the first one.
    settle = time.monotonic() + min(0.5, max(0.0, deadline - time.monotonic()))
    while time.monotonic() < settle:
        time.sleep(0.05)
    watcher.refresh_connection()
    watcher.query_faults()
    console.print(frame())
    if not ready():
        what = f"telemetry of {args.rover}" if args.rover else "telemetry"
        print(f"lunaris watch: no {what} within {args.timeout:g} s", file=sys.stderr)
        return 1
    return 0
