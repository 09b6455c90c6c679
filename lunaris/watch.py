"""``lunaris watch [--rover ID]``: a live terminal view of one rover, or of the whole fleet.

With ``--rover`` it shows the battery (energy, state of charge, voltage, current,
temperature, time to empty), the power summary, solar panels and umbilical,
radios, the PDM table (every rail with its loads), the active faults and the
latest events; alarms are coloured by severity. Without it, one line per rover,
the fleet's active faults and events. Each rover is shown in its trainee session: the header
names the trainee (and the session's id), and the events are the session's only (a new
session starts the list empty: :class:`lunaris.client.Mirror`).

What it shows is the client's mirror of the twin (:class:`lunaris.client.Mirror`): values
appear at once when the tool joins a running session (the publishers' caches), events are
taken once. The view says when the router goes away ("DISCONNECTED ... retrying"): Zenoh
keeps trying to reconnect, and when it does the subscriptions are restored and the view says
so; and when a rover is cut off behind it ("LINK LOST": no clock tick for 2 s, or its clock's
token gone), which it shows within a refresh, and clears with the rover's next tick.

On a terminal the view is a full-screen ``rich`` display refreshed a few times a
second (Ctrl-C quits); narrower than 110 columns it draws a compact layout that fits an
80x24 terminal. Piped, it prints a snapshot every ``--interval`` seconds, or once with
``--once``, as wide as the terminal the user reads on (stderr's), else 160 columns.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from typing import Any

import msgspec
import zenoh
from rich.console import Console, RenderableType
from rich.live import Live

from common import keys
from common.connection import add_connection_args
from common.messages import ActiveFaults, Event
from common.session import parse_control
from lunaris.client import Mirror, ToolError, close_session, describe_endpoint, open_session
from lunaris.processes import quiet_stdout
from lunaris.watch_compact import fleet_compact, render_compact
from lunaris.watch_view import Connection, Snapshot, render_fleet, render_rover

__all__ = ["Connection", "Snapshot", "add_arguments", "main", "render", "snapshot_of"]


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


def _in_sim_order(events: list[tuple[str, Event]]) -> list[tuple[str, Event]]:
    """Events as they came, put in sim time order (the services' interleave) between a rover's
    resets and restores: the clock starts again at each, and what came after one is later
    whatever its time says (a drill's reset put the minutes before it last)."""
    era: dict[str, int] = {}
    keyed = []
    for i, (rover, ev) in enumerate(events):
        keyed.append(((era.get(rover, 0), ev.t_s, i), (rover, ev)))
        control = parse_control(ev.key.split("/")[2:]) if ev.kind == "session" else None
        if control is not None and control[0] in ("reset", "restore") and ev.severity == "info":
            era[rover] = era.get(rover, 0) + 1  # (a restore refused, a warning, begins nothing)
    return [item for _, item in sorted(keyed, key=lambda k: k[0])]


def snapshot_of(mirror: Mirror, rover: str | None = None) -> Snapshot:
    """What one frame is drawn from: the mirror's latest values, events (in sim time order:
    services interleave), faults in effect, live services and links (``rover``'s too when
    nothing of it has been heard: cut off, or not running)."""
    latest: dict[str, tuple[bytes, float]] = {}
    faults: dict[str, list[dict[str, Any]]] = {}
    for key, v in mirror.latest().items():
        rover, parts = keys.split(key)
        if parts[:2] == ["faults", "active"] and isinstance(v.value, ActiveFaults):
            faults.setdefault(rover, []).extend(msgspec.structs.asdict(f) for f in v.value.faults)
        else:
            latest[key] = (v.raw, v.at)
    for listed in faults.values():
        listed.sort(key=lambda f: (f["since_t_s"], f["key"]))
    events = _in_sim_order([(rover, ev) for rover, ev, _ in mirror.events()])
    links = mirror.links()
    if rover is not None and rover not in links:
        links[rover] = mirror.link(rover)
    return Snapshot(latest, events, faults, mirror.all_services(), links=links,
                    sessions=mirror.sessions())


COMPACT_BELOW = 110  # columns: narrower than this, the compact layout (an 80x24 terminal)


def render(snap: Snapshot, conn: Connection, rover: str | None, n_events: int,
           width: int = 200, height: int = 60) -> RenderableType:
    """The frame; below ``COMPACT_BELOW`` columns a compact one that fits an 80x24 terminal."""
    from rich.console import Group

    from lunaris.watch_view import banner

    compact = width < COMPACT_BELOW
    if rover:
        body = render_compact(snap, rover, height) if compact else render_rover(snap, rover, n_events)
    else:
        body = fleet_compact(snap, n_events) if compact else render_fleet(snap, n_events)
    return Group(banner(conn, snap.now), body)


# -- the session ------------------------------------------------------------------------------


class _Watcher:
    """Opens the session in the background and keeps the mirror and the connection state."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.mirror = Mirror(args.rover or "*")
        self.conn = Connection(describe_endpoint(args))
        self.session: zenoh.Session | None = None
        self.error: str | None = None
        self.stop = threading.Event()
        self._opener = threading.Thread(target=self._open, name="watch-open", daemon=True)

    def start(self) -> None:
        self._opener.start()

    def _open(self) -> None:
        try:
            session = open_session(self.args, wait_s=None)
        except ToolError as exc:
            self.error = str(exc)
            return
        self.session = session  # from here, close() closes it, declared or not
        try:
            self.mirror.start(session)
        except zenoh.ZError:
            if not self.stop.is_set():  # else: closed while declaring, on the way out
                raise

    def still_opening(self) -> bool:
        """The opener still in a Zenoh call (no router yet): left to the interpreter's
        shutdown, its return would abort the process."""
        return self._opener.is_alive()

    def refresh_connection(self) -> None:
        if self.session is None:
            return
        self.conn.update(self.mirror.refresh_connection())
        self.mirror.sweep()

    def close(self) -> None:
        self.stop.set()
        self.mirror.close()
        if self.session is not None:
            close_session(self.session)


def main(args: argparse.Namespace) -> int:
    watcher = _Watcher(args)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    # Ctrl-C quits even when started with SIGINT ignored (from a script's background job,
    # as `make test &` is; its children inherit the ignoring): like the other tools' handlers
    signal.signal(signal.SIGINT, signal.default_int_handler)
    watcher.start()
    tty = sys.stdout.isatty() and not args.once
    console = _Console(width=args.width or _piped_width()) if args.width or not sys.stdout.isatty() \
        else _Console()

    def frame() -> RenderableType:
        watcher.refresh_connection()
        return render(snapshot_of(watcher.mirror, args.rover), watcher.conn, args.rover, args.events,
                      width=console.size.width, height=console.size.height)

    code = 0
    try:
        if args.once:
            code = _once(args, watcher, console, frame)
        elif tty:
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
    except BrokenPipeError:  # the reader has gone (| head): close as on Ctrl-C, quietly
        quiet_stdout()
    if watcher.error:
        print(f"lunaris watch: {watcher.error}", file=sys.stderr, flush=True)
        code = 2
    _close(watcher, code)
    return code


def _close(watcher: _Watcher, code: int) -> None:
    """Close the session, within ``CLOSE_DEADLINE_S``: Ctrl-C always ends the tool. Should
    the closing hang, or the opener still be in a Zenoh call, the process leaves at once (a
    viewer holds no state)."""
    closer = threading.Thread(target=watcher.close, name="watch-close", daemon=True)
    closer.start()
    closer.join(CLOSE_DEADLINE_S)
    if closer.is_alive() or watcher.still_opening():
        if closer.is_alive():
            print(f"lunaris watch: the Zenoh session did not close within {CLOSE_DEADLINE_S:g} s; "
                  "leaving it", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)


CLOSE_DEADLINE_S = 3.0  # the longest the session's closing is waited for [s]
PIPED_WIDTH = 160  # a log or a file: wide enough for the whole layout


def _piped_width() -> int:
    """Piped, the width of the terminal the user reads on (stderr's), or ``PIPED_WIDTH``."""
    for stream in (sys.stderr, sys.stdin):
        try:
            if stream.isatty():
                return os.get_terminal_size(stream.fileno()).columns
        except (OSError, ValueError):
            continue
    return PIPED_WIDTH


class _Console(Console):
    def on_broken_pipe(self) -> None:
        """rich exits the process (SystemExit) when its reader goes; the session must be
        closed first, or zenoh's threads abort the interpreter's exit: say it as an error."""
        self.quiet = True
        raise BrokenPipeError



def _once(args: argparse.Namespace, watcher: _Watcher, console: Console, frame) -> int:
    deadline = time.monotonic() + args.timeout
    want = keys.battery_state(args.rover) if args.rover else None

    def ready() -> bool:
        return (watcher.mirror.get(want) is not None) if want else bool(watcher.mirror.latest())

    def lost() -> bool:  # a rover asked for, cut off (or not running): said at once, not waited for
        return bool(args.rover) and watcher.mirror.link(args.rover).state == "lost"

    while not ready() and not lost() and time.monotonic() < deadline and not watcher.error:
        time.sleep(0.05)
    # The caches of the other publishers answer within a moment of the first one.
    settle = time.monotonic() + min(0.5, max(0.0, deadline - time.monotonic()))
    while time.monotonic() < settle:
        time.sleep(0.05)
    watcher.refresh_connection()
    console.print(frame())
    if not ready():
        if lost():
            print(f"lunaris watch: link to {args.rover} lost: {watcher.mirror.link(args.rover).reason}",
                  file=sys.stderr)
            return 1
        what = f"telemetry of {args.rover}" if args.rover else "telemetry"
        print(f"lunaris watch: no {what} within {args.timeout:g} s", file=sys.stderr)
        return 1
    return 0
