"""A rover cut off from the tools (issue 22, DECISIONS D3), on loopback: the tools' router and the
rover's router are two, linked; the rover's is frozen (SIGSTOP) for a few seconds and thawed.

While the link is cut, ``lunaris watch`` shows it lost within 3 s, a fault written is not
applied and the writer is told so (exit 2, the reason in words), ``fault list`` never says
"no active faults"; once the link is back, the watch catches up by itself and the fault
written during the cut is not in effect.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator

import pytest

from common import keys
from tests.harness import (
    ALL_SERVICES,
    ROOT,
    Probe,
    Twin,
    env_without_zenoh_config,
    free_endpoint,
    lunaris_cmd,
    open_router,
    stop_process,
    wait_for,
)
from tests.lunaris.conftest import MAPP, R, run_tool

pytestmark = pytest.mark.timeout(120)


class Lines:
    """A process's output lines, read as they come, with the wall time each came."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.lines: list[tuple[float, str]] = []
        self._lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._lock:
                self.lines.append((time.monotonic(), line.rstrip("\n")))

    def since(self, t: float) -> list[str]:
        with self._lock:
            return [text for at, text in self.lines if at >= t]

    def first_after(self, t: float, needle: str) -> float | None:
        with self._lock:
            return next((at for at, text in self.lines if at >= t and needle in text), None)


@pytest.fixture
def cut_off(tmp_path) -> Iterator[tuple[str, subprocess.Popen, Probe]]:
    """(the tools' endpoint, the rover's router process, a probe on the tools' side)."""
    tools_ep, rover_ep = free_endpoint(), free_endpoint()
    tools_router = open_router(tools_ep)
    log = tmp_path / "rover-router.log"
    with log.open("wb") as out:
        rover_router = subprocess.Popen(lunaris_cmd("router", "--listen", rover_ep, "--connect", tools_ep),
                                        stdout=out, stderr=subprocess.STDOUT, cwd=ROOT,
                                        env=env_without_zenoh_config())
    try:
        wait_for(lambda: b"listening" in log.read_bytes(), 30, "the rover's router")
        with Twin(rover_ep, [MAPP], tmp_path / "twin"), Probe(tools_ep) as p:
            p.wait_services(R, ALL_SERVICES, timeout_s=30)
            p.watch(keys.battery_state(R))
            p.wait_value(keys.battery_state(R))
            yield tools_ep, rover_router, p
            os.kill(rover_router.pid, signal.SIGCONT)  # whatever happened, never left frozen
    finally:
        os.kill(rover_router.pid, signal.SIGCONT)
        stop_process(rover_router)
        tools_router.close()


def test_a_cut_is_shown_within_3_s_writes_are_not_applied_and_the_tools_catch_up(cut_off):
    tools_ep, rover_router, p = cut_off
    watch = subprocess.Popen(lunaris_cmd("watch", "--rover", R, "--interval", "0.25", "--width", "160",
                                         "--connect", tools_ep),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                             env=env_without_zenoh_config(), stdin=subprocess.DEVNULL)
    out = Lines(watch)
    try:
        wait_for(lambda: any("state of charge" in ln for ln in out.since(0)), 20, "the watch's first frame")
        assert not any("LINK LOST" in ln for ln in out.since(0))

        os.kill(rover_router.pid, signal.SIGSTOP)  # the cut
        cut = time.monotonic()
        lost = wait_for(lambda: out.first_after(cut, "LINK LOST to mapp-1"), 6, "the watch to show the cut")
        print(f"the watch showed the cut {lost - cut:.2f} s after it")
        assert lost - cut <= 3.0 + 0.25  # within 3 s, give or take one frame of the watch

        done = run_tool("fault", "inject", R, "battery", "heating", "20", "--connect", tools_ep)
        assert done.returncode == 2, done.stdout + done.stderr
        assert "not applied: the link to mapp-1 is lost" in done.stderr, done.stderr
        assert "is the service" not in done.stderr
        listed = run_tool("fault", "list", R, "--timeout", "2", "--connect", tools_ep)
        assert listed.returncode == 2 and "no active faults" not in listed.stdout, listed.stdout

        os.kill(rover_router.pid, signal.SIGCONT)  # the link comes back
        back = time.monotonic()
        wait_for(lambda: any("state of charge" in ln for ln in out.since(back + 1.0))
                 and not any("LINK LOST" in ln for ln in out.since(back + 1.0)), 20,
                 "the watch to catch up by itself")
        listed = run_tool("fault", "list", R, "--connect", tools_ep)
        assert listed.returncode == 0 and "no active faults" in listed.stdout, listed.stdout + listed.stderr
        assert "heating" not in p.value(keys.battery_state(R))["faults"]
    finally:
        stop_process(watch)
