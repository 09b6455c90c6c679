"""``lunaris up`` killed with kill -9 at a moment of its start, and what it leaves running.

SPEC §13e: a service never outlives its supervisor. One round: ``lunaris up`` on a state
folder of its own, SIGKILL after ``moment_s``, then the processes given that folder as an
argument (the services it started, or a child forked but not yet a service: its command
line is still ``up``'s) polled until none is left or ``settle_s`` has passed. Shared by
tests/reliability/test_supervisor.py (a few rounds) and bench/supervisor_death.py (the issue's
200). Linux: processes are found in ``/proc``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from lunaris.processes import SOURCE, lunaris_cmd
from testbed.twin import free_endpoint

__all__ = ["Round", "alive", "kill_up_at", "naming", "start_up"]


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped, does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def naming(argument: str) -> list[int]:
    """The running processes (not this one) with ``argument`` among their arguments."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        pid = int(cmdline.parent.name)
        try:
            args = cmdline.read_bytes().split(b"\0")
        except OSError:
            continue  # gone meanwhile
        if pid != os.getpid() and argument.encode() in args and alive(pid):
            found.append(pid)
    return sorted(found)


def start_up(rover: Path, state_dir: Path, services: Sequence[str],
             endpoint: str | None = None) -> subprocess.Popen:
    """``lunaris up`` for ``rover`` on 127.0.0.1 (a free port unless ``endpoint``), its state
    and its services' logs in ``state_dir``, no status display."""
    return subprocess.Popen(
        lunaris_cmd("up", "--rover", str(rover), "--listen", endpoint or free_endpoint(),
                    "--state-dir", str(state_dir), "--services", ",".join(services), "--no-status"),
        cwd=SOURCE, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True)


@dataclass
class Round:
    moment_s: float  # how long up ran before its kill [s]
    started: int  # the processes up had started by then (a child forked, a service)
    left: dict[int, str] = field(default_factory=dict)  # pid -> command line, running settle_s later


def kill_up_at(moment_s: float, rover: Path, state_dir: Path, services: Sequence[str],
               settle_s: float = 10.0) -> Round:
    """One round (see the module); ``left`` is empty as soon as none is left. Whatever is
    left is then ended (SIGKILL, by its pid), and ``up`` is, whatever happens: a round leaves
    nothing behind."""
    state_dir.mkdir(parents=True, exist_ok=True)
    up = start_up(rover, state_dir, services)
    left: list[int] = []
    try:
        try:
            up.wait(moment_s)  # the moment of the kill: the measured variable, not a synchronisation
        except subprocess.TimeoutExpired:
            pass
        started = len([pid for pid in naming(str(state_dir)) if pid != up.pid])
        up.send_signal(signal.SIGKILL)
        up.wait(10)
        deadline = time.monotonic() + settle_s
        left = naming(str(state_dir))
        while left and time.monotonic() < deadline:
            time.sleep(0.05)  # a poll of the condition: none left
            left = naming(str(state_dir))
        return Round(moment_s, started, {pid: _command(pid) for pid in left})
    finally:
        if up.poll() is None:
            up.kill()
            up.wait(10)
        for pid in left or naming(str(state_dir)):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def _command(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode().strip()
    except OSError:
        return "?"
