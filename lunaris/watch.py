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
from collections import deque
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext
from rich.console import Console, RenderableType
from rich.live import Live

from common import keys
from common.connection import add_connection_args
from common.messages import (
    ActiveFaults,
    Event,
    decode,
)
from lunaris.client import ToolError, close_session, describe_endpoint, ignored, open_session
from lunaris.watch_view import Connection, Snapshot, render

__all__ = ["Connection", "Snapshot", "Store", "add_arguments", "main", "render"]


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


class Store:
    """Thread-safe: Zenoh calls back on its own threads, the view reads snapshots."""

    def __init__(self, max_events: int = 500):
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[bytes, float]] = {}
        self._events: deque[tuple[str, Event]] = deque(maxlen=max_events)
        self._seen: set[tuple] = set()
        self._faults: dict[str, dict[str, list[dict]]] = {}  # rover -> service -> faults
        self._services: dict[str, set[str]] = {}
        self.last_sample = 0.0

    def on_sample(self, s: zenoh.Sample) -> None:
        key = str(s.key_expr)
        try:
            rover, parts = keys.split(key)
        except ValueError:
            return
        fam = keys.telemetry_family(parts)
        family = fam.name if fam is not None else None
        if family is None or s.kind != zenoh.SampleKind.PUT:
            return
        payload, now = s.payload.to_bytes(), time.monotonic()
        if family == "event":
            try:
                ev = decode(payload, Event)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                ignored(key, f"not an event ({exc})")
                return
            ident = (rover, ev.t_s, ev.source, ev.kind, ev.key, ev.message)
            with self._lock:
                self.last_sample = now
                if ident in self._seen:  # a cache replayed after a reconnection
                    return
                self._seen.add(ident)
                self._events.append((rover, ev))
            return
        if family == "faults/active/*":
            try:
                active = decode(payload, ActiveFaults)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                ignored(key, f"not a list of faults ({exc})")
                return
            with self._lock:
                self._faults.setdefault(rover, {})[active.service] = [
                    msgspec.structs.asdict(f) for f in active.faults]
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

    def snapshot(self) -> Snapshot:
        with self._lock:
            events = sorted(self._events, key=lambda re: re[1].t_s)  # services interleave
            faults = {r: sorted((f for fs in by_service.values() for f in fs),
                                key=lambda f: (f["since_t_s"], f["key"]))
                      for r, by_service in self._faults.items()}
            return Snapshot(dict(self._latest), events, faults,
                            {r: set(s) for r, s in self._services.items()})


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
        rover = self.args.rover or "*"
        history = zext.HistoryConfig(detect_late_publishers=True)
        try:
            for family in keys.families("out"):
                self._keep.append(zext.declare_advanced_subscriber(
                    session, family.pattern(rover), self.store.on_sample, history=history))
            self._keep.append(session.liveliness().declare_subscriber(
                keys.service(rover, "*"), self.store.on_token, history=True))
        except zenoh.ZError:
            if not self.stop.is_set():  # else: closed while declaring, on the way out
                raise

    def still_opening(self) -> bool:
        """The opener still in a Zenoh call (no router yet): left to the interpreter's
        shutdown, its return would abort the process."""
        return self._opener.is_alive()

    def refresh_connection(self) -> None:
        session = self.session
        if session is None:
            return
        try:
            connected = bool(session.info.routers_zid())
        except zenoh.ZError:
            connected = False
        self.conn.update(connected)

    def close(self) -> None:
        self.stop.set()
        self._keep.clear()
        if self.session is not None:
            close_session(self.session)


def main(args: argparse.Namespace) -> int:
    store = Store()
    watcher = _Watcher(args, store)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    # Ctrl-C quits even when started with SIGINT ignored (from a script's background job,
    # as `make test &` is; its children inherit the ignoring): like the other tools' handlers
    signal.signal(signal.SIGINT, signal.default_int_handler)
    watcher.start()
    tty = sys.stdout.isatty() and not args.once
    console = Console(width=args.width or _piped_width()) if args.width or not sys.stdout.isatty() \
        else Console()

    def frame() -> RenderableType:
        watcher.refresh_connection()
        return render(store.snapshot(), watcher.conn, args.rover, args.events,
                      width=console.size.width, height=console.size.height)

    code = 0
    try:
        if args.once:
            code = _once(args, watcher, store, console, frame)
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
    console.print(frame())
    if not ready():
        what = f"telemetry of {args.rover}" if args.rover else "telemetry"
        print(f"lunaris watch: no {what} within {args.timeout:g} s", file=sys.stderr)
        return 1
    return 0
