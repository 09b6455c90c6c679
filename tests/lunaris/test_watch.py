"""``lunaris watch``: the drawing from a snapshot, and the live view read off a pseudo-terminal
while faults are injected and the router goes away and comes back."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import signal
import struct
import subprocess
import termios
import threading
import time

import pytest
from rich.console import Console

from common import keys
from common.messages import BatteryState, Clock, DriveState, Event, LoadPower, RadioLink, RailState, encode
from lunaris.watch import Connection, Snapshot, render
from tests.harness import (
    ALL_SERVICES,
    ROOT,
    Probe,
    Twin,
    env_without_zenoh_config,
    free_endpoint,
    lunaris_cmd,
    open_router,
    wait_for,
)
from tests.lunaris.conftest import MAPP, R, run_tool

# -- drawing ----------------------------------------------------------------------------------


def _snapshot(**extra) -> Snapshot:
    now = 1000.0
    latest = {
        keys.clock(R): (encode(Clock(125.5, 0.1, 1255, 20.0, False)), now),
        keys.battery_state(R): (encode(BatteryState(125.5, 4.1e5, 5.3e5, 0.1234, 16.4, 16.1, 4.25, 68.4, 61.5,
                                                    True, 1, ["over_temperature"], 5432.0)), now),
        keys.rail_state(R, "5V_CH2"): (encode(RailState(125.5, 0.0, 0.0, 0.0, 5.0, "tripped",
                                                        "over-current 50.00 A > 5.0 A")), now),
        keys.rail_state(R, "12V"): (encode(RailState(125.5, 12.0, 4.5, 54.0, 10.0, "on")), now),
        keys.load_power(R, "nav_camera"): (encode(LoadPower(125.5, 0.0, "5V_CH2", False, ["short"])), now),
        keys.load_power(R, "drive_motors"): (encode(LoadPower(125.5, 41.25, "12V", True, [])), now),
        keys.radio_link(R, "lander"): (encode(RadioLink(125.5, False, 512.0, 3.0)), now - 10),
    }
    faults = {R: [
        {"key": keys.fault(R, "load/nav_camera", "short"), "params": {"resistance_ohm": 0.05},
         "since_t_s": 120.0, "origin": "injected", "severity": "warning"},
        {"key": f"lunaris/{R}/battery/over_temperature", "params": {}, "since_t_s": 121.0,
         "origin": "derived", "severity": "critical"},
    ]}
    short = keys.fault(R, "load/nav_camera", "short")
    events = [(R, Event(120.0, "warning", "loads", "fault_injected", short,
                        "injected load/nav_camera/short")),
              (R, Event(121.0, "critical", "battery", "fault_raised", f"lunaris/{R}/battery/over_temperature",
                        "pack at 61.5 C, above 60 C"))]
    return Snapshot(latest, events, faults, {R: {"clock", "battery"}}, now=now, **extra)


def _draw(renderable) -> tuple[str, str]:
    console = Console(width=170, record=True, force_terminal=True, color_system="standard")
    console.print(renderable)
    return console.export_text(clear=False), console.export_text(styles=True)


def test_the_rover_view_shows_every_part_with_alarms_coloured_by_severity():
    conn = Connection("tcp/127.0.0.1:7447", state="connected")
    text, ansi = _draw(render(_snapshot(), conn, R, 8))
    for shown in ("connected to tcp/127.0.0.1:7447", "sim t 00:02:05.5", "x20", "services 2: battery, clock",
                  "state of charge", "12.34 %", "16.10 V", "4.25 A", "61.5 C", "1 h 30 min",
                  "over_temperature (code 1)", "5V_CH2", "tripped", "over-current 50.00 A > 5.0 A",
                  "drive_motors", "41.25", "OUT OF RANGE", "x 512 m", "load/nav_camera/short",
                  "resistance_ohm=0.05", "battery/over_temperature", "pack at 61.5 C, above 60 C"):
        assert shown in text, shown
    assert text.index("12V") < text.index("drive_motors") < text.index("5V_CH2") < text.index("nav_camera")
    assert "\x1b[1;31mtripped" in ansi  # a tripped rail in bold red
    assert "\x1b[1;31mbattery/over_temperature" in ansi  # critical
    assert "\x1b[33mload/nav_camera/short" in ansi  # warning
    assert "\x1b[33m   12.34 %" in ansi  # state of charge below 20 %
    assert "\x1b[1;31m    61.5 C" in ansi  # over temperature: critical


def test_the_fleet_view_has_a_line_per_rover():
    text, _ = _draw(render(_snapshot(), Connection("x", state="connected"), None, 8))
    line = next(ln for ln in text.splitlines() if ln.strip().startswith(R))
    assert "125.5" in line and "12.3 %" in line and "1/2" in line and "lander:OUT" in line


def test_the_drive_panel_and_the_fleet_column_of_a_rover_that_drives():
    snap = _snapshot()
    assert "drive" not in _draw(render(snap, Connection("x", state="connected"), R, 0))[0].split("PDM")[0]
    snap.latest[keys.drive_state(R)] = (encode(DriveState(
        125.5, 120.4, 35.2, 6.8, 0.064, 42.0, 18.5, 8.0, 0.8, 20.0, 180.7, 2, True, "power_limited", 5,
        96.3, 5400.0)), snap.now)
    text, ansi = _draw(render(snap, Connection("x", state="connected"), R, 0))
    for shown in ("POWER LIMITED", "x 120.4  y 35.2  z 6.8 m", "42 deg", "grade +18.5 deg", "0.06 m/s",
                  "20.0 W", "force 8.0 N", "torque 0.80 N m", "to waypoint 3 of 5, 96 m to go",
                  "180.7 m", "drive energy 1.50 Wh"):
        assert shown in text, shown
    assert "\x1b[1;33mPOWER LIMITED" in ansi
    fleet, _ = _draw(render(snap, Connection("x", state="connected"), None, 0))
    assert "power limited 0.06 m/s 181 m" in fleet


def test_the_banner_follows_the_connection():
    conn = Connection("tcp/h:1")
    assert "CONNECTING to tcp/h:1" in _draw(render(_snapshot(), conn, R, 0))[0]
    conn.update(True, now=10.0)
    conn.update(False, now=20.0)
    snap = _snapshot()
    snap.now = 32.0
    assert conn.state == "disconnected"
    assert "DISCONNECTED from the router at tcp/h:1 for 12 s - retrying" in _draw(render(snap, conn, R, 0))[0]
    conn.update(True, now=50.0)
    snap.now = 51.0
    assert conn.reconnected_after_s == 30.0
    assert "reconnected after an outage of 30 s" in _draw(render(snap, conn, R, 0))[0]


# -- live, on a pseudo-terminal ---------------------------------------------------------------

_CSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Z0-9]")


class Terminal:
    """A process on a pseudo-terminal of a fixed size; :meth:`screen` is its last full frame."""

    def __init__(self, argv: list[str], cols: int = 170, rows: int = 70):
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
        env = env_without_zenoh_config() | {"TERM": "xterm-256color", "COLUMNS": str(cols),
                                            "LINES": str(rows)}
        self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, cwd=ROOT,
                                     start_new_session=True)
        os.close(slave)
        self.master = master
        self._buf = bytearray()
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            ready, _, _ = select.select([self.master], [], [], 0.1)
            if not ready:
                if self.proc.poll() is not None:
                    return
                continue
            try:
                data = os.read(self.master, 65536)
            except OSError:
                return
            if not data:
                return
            with self._lock:
                self._buf += data

    def screen(self) -> str:
        """The text of the last complete frame (rich redraws each from the cursor's home)."""
        with self._lock:
            frames = bytes(self._buf).split(b"\x1b[H")
        if len(frames) < 3:
            return ""
        return _CSI.sub("", frames[-2].decode("utf-8", "replace")).replace("\r", "")

    def wait_screen(self, predicate, timeout_s: float, what: str) -> str:
        found: list[str] = []

        def check() -> bool:
            text = self.screen()
            if predicate(text):
                found.append(text)
                return True
            return False
        try:
            wait_for(check, timeout_s, what, poll_s=0.1)
        except AssertionError:
            raise AssertionError(f"{what}; last screen:\n{self.screen()}") from None
        return found[0]

    def close(self) -> int | None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5)
        if self.master >= 0:
            os.close(self.master)
            self.master = -1
        return self.proc.returncode

    def tail(self, n: int = 2000) -> str:
        """The last of what the process wrote (a panic's message, for a failure)."""
        with self._lock:
            return _CSI.sub("", bytes(self._buf[-n:]).decode("utf-8", "replace"))


def _sim_t(screen: str) -> float:
    m = re.search(r"sim t \S+\s+\((\d+\.\d) s\)", screen)
    return float(m.group(1)) if m else -1.0


@pytest.mark.timeout(90)
def test_watch_shows_the_rover_live_through_a_fault_and_a_router_restart(tmp_path):
    endpoint = free_endpoint()
    router = open_router(endpoint)
    term = None
    try:
        with Twin(endpoint, [MAPP], tmp_path / "twin") as _twin, Probe(endpoint) as p:
            p.wait_services(R, ALL_SERVICES)
            term = Terminal(lunaris_cmd("watch", "--rover", R, "--connect", endpoint, "--refresh", "5"))
            screen = term.wait_screen(
                lambda s: "IN RANGE" in s and "services 7" in s and "thermal_imager" in s, 20,
                "the rover's values on the screen")
            assert "connected to " + endpoint in screen
            assert re.search(r"state of charge\s+\d+\.\d\d %", screen)
            assert re.search(r"voltage\s+1\d\.\d\d V", screen)
            assert re.search(r"solar left\s+\d+\.\d W", screen) and "umbilical   disconnected" in screen
            assert re.search(r"5V_CH2\s+on\s+5\.00", screen) and "none" in screen  # no active fault

            p.put(keys.fault(R, "load/nav_camera", "short"), b"")
            screen = term.wait_screen(lambda s: "load/nav_camera/short" in s and "rail/5V_CH2/tripped" in s,
                                      10, "the injected fault on the screen")
            assert re.search(r"5V_CH2\s+tripped", screen)
            assert "fault_injected" in screen and "injected load/nav_camera/short" in screen
            before = _sim_t(screen)

            router.close()  # the router goes away ...
            term.wait_screen(lambda s: "DISCONNECTED from the router at " + endpoint in s, 15,
                             "the disconnected banner")
            router = open_router(endpoint)  # ... and comes back on the same endpoint
            screen = term.wait_screen(
                lambda s: "reconnected after an outage of" in s and _sim_t(s) > before + 1.0, 30,
                "the reconnection and fresh telemetry")
            assert "DISCONNECTED" not in screen and "load/nav_camera/short" in screen
            p.delete(keys.fault(R, "load/nav_camera", "short"))
            term.wait_screen(lambda s: "fault_cleared" in s, 15, "the clearing, after the reconnection")
            assert term.close() == 0, term.tail()
            term = None

            once = run_tool("watch", "--once", "--connect", endpoint, "--width", "160")  # fleet, piped
            assert once.returncode == 0, once.stderr
            assert re.search(rf"{R}\s+\d+\.\d", once.stdout) and "fleet: 1 rover(s)" in once.stdout
    finally:
        if term is not None:
            term.close()
        router.close()


def test_an_80x24_terminal_gets_a_compact_view_that_fits():
    conn = Connection("tcp/127.0.0.1:7447", state="connected")
    for rover in (R, None):
        console = Console(width=80, height=24, record=True, force_terminal=True, color_system="standard")
        console.print(render(_snapshot(), conn, rover, 8, width=80, height=24))
        lines = console.export_text().rstrip("\n").split("\n")
        assert len(lines) <= 24, "\n".join(lines)
        assert max(len(line) for line in lines) <= 80
        text = "\n".join(lines)
        assert "battery" in text or "fleet" in text
        if rover:
            assert "5V_CH2" in text and "tripped" in text and "over_temperature" in text


def test_piped_once_is_as_wide_as_the_reader_s_terminal_or_160(monkeypatch):
    import lunaris.watch as watch

    class Pipe:
        def isatty(self) -> bool:
            return False

    monkeypatch.setattr(watch.sys, "stderr", Pipe())
    monkeypatch.setattr(watch.sys, "stdin", Pipe())
    assert watch._piped_width() == watch.PIPED_WIDTH == 160


def test_closing_a_session_waits_for_zenohs_callback_threads():
    """A callback thread zenoh started from a daemon thread (watch declares from its opener)
    is a daemon too; left running at exit, it woke during the interpreter's shutdown and the
    process aborted (exit -6, 'FATAL: exception not rethrown'). close_session waits for it."""
    from lunaris.client import close_session

    closed = threading.Event()

    class Session:
        def close(self) -> None:
            closed.set()

    def callbacks() -> None:  # ends a moment after the session closes, as zenoh's do
        closed.wait(5)
        time.sleep(0.3)
    thread = threading.Thread(target=callbacks, name="Thread-9 (pyo3-closure)", daemon=True)
    thread.start()
    close_session(Session())
    assert not thread.is_alive()
