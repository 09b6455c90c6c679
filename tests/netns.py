"""Machines for a test, made of Linux network namespaces (``ip netns``), on a switch of their own.

A :class:`Network` is a switch (a namespace holding a bridge) and machines (a namespace
each, with ``lo`` and one ``eth0`` cabled to the switch by a veth pair, an address of
``10.77.0.0/24``). Nothing is made in the test's own namespace: every address exists only
inside the namespaces, so tests running in parallel may use the same addresses on switches
of their own. A command runs on a machine with ``ip netns exec`` (:meth:`Network.popen`,
:meth:`Network.run`); :meth:`Network.cut` and :meth:`Network.restore` unplug and plug a
machine's cable (the switch's end of its veth, down and up).

Everything is deleted on exit, pass or fail, processes first; namespaces a crashed earlier
run left behind (their name carries the pid of the process that made them, which is gone)
are deleted when the next network is made. Needs root (CI runs as root); :func:`unavailable`
says why namespaces cannot be made here, for ``pytest.skip``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

__all__ = ["PREFIX", "Machine", "Network", "remove_stale", "unavailable"]

PREFIX = "lunaris-t"  # every namespace of ours: lunaris-t<pid>-<n>-<name>
SUBNET = "10.77.0"
_counter = [0]


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and out.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {out.stderr.strip()}")
    return out


def _namespaces() -> list[str]:
    out = _ip("netns", "list", check=False).stdout
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _kill_inside(namespace: str) -> None:
    """Stop the processes still running in one of our namespaces (SIGKILL: it is going)."""
    pids = _ip("netns", "pids", namespace, check=False).stdout.split()
    for pid in pids:
        try:
            os.kill(int(pid), signal.SIGKILL)
        except (ProcessLookupError, ValueError):
            pass


def remove_stale() -> list[str]:
    """Delete the namespaces of ours whose maker is gone (a run that crashed or was killed):
    their processes first. Returns their names."""
    gone = []
    for ns in _namespaces():
        if not ns.startswith(PREFIX):
            continue
        pid = ns[len(PREFIX):].split("-", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            _kill_inside(ns)
            _ip("netns", "del", ns, check=False)
            gone.append(ns)
    return gone


def unavailable() -> str | None:
    """Why network namespaces cannot be made here (None: they can)."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add): the tests across machines run in CI"
    probe = f"{PREFIX}{os.getpid()}-probe"
    try:
        made = _ip("netns", "add", probe, check=False)
    except FileNotFoundError:
        return "the ip command (iproute2) is not installed"
    if made.returncode != 0:
        return f"ip netns add failed here: {made.stderr.strip()}"
    try:
        bridge = _ip("-n", probe, "link", "add", "br0", "type", "bridge", check=False)
        if bridge.returncode != 0:
            return f"no bridge device in a network namespace here: {bridge.stderr.strip()}"
    finally:
        _ip("netns", "del", probe, check=False)
    return None


@dataclass(frozen=True)
class Machine:
    name: str
    namespace: str
    address: str  # on eth0, inside its namespace only
    port: str  # the switch's end of its cable, inside the switch's namespace


class Network:
    """A switch and the machines cabled to it; a context manager that deletes them all."""

    def __init__(self, log_dir: Path | None = None):
        remove_stale()
        _counter[0] += 1
        self.tag = f"{PREFIX}{os.getpid()}-{_counter[0]}"
        self.switch = f"{self.tag}-sw"
        self.machines: dict[str, Machine] = {}
        self.procs: list[subprocess.Popen] = []
        self.log_dir = log_dir
        self._made: list[str] = []

    def __enter__(self) -> Network:
        try:
            self._add_namespace(self.switch)
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self.switch, "link", "set", "br0", "up")
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _add_namespace(self, name: str) -> None:
        _ip("netns", "add", name)
        self._made.append(name)
        _ip("-n", name, "link", "set", "lo", "up")

    def add(self, name: str) -> Machine:
        """A machine: its namespace, its cable to the switch, its address."""
        index = len(self.machines) + 1
        ns = f"{self.tag}-{name}"
        port = f"p{index}"
        address = f"{SUBNET}.{index}"
        self._add_namespace(ns)
        _ip("-n", self.switch, "link", "add", port, "type", "veth", "peer", "name", "eth0",
            "netns", ns)
        _ip("-n", self.switch, "link", "set", port, "master", "br0")
        _ip("-n", self.switch, "link", "set", port, "up")
        _ip("-n", ns, "addr", "add", f"{address}/24", "dev", "eth0")
        _ip("-n", ns, "link", "set", "eth0", "up")
        machine = Machine(name, ns, address, port)
        self.machines[name] = machine
        return machine

    def __getitem__(self, name: str) -> Machine:
        return self.machines[name]

    # -- running things on a machine -----------------------------------------------------

    def prefix(self, machine: str) -> list[str]:
        """What runs a command on ``machine``: ``ip netns exec <its namespace>``."""
        return ["ip", "netns", "exec", self.machines[machine].namespace]

    def popen(self, machine: str, argv: Sequence[str], log: str | None = None,
              stdin: int | IO[Any] | None = subprocess.DEVNULL, stdout: int | IO[Any] | None = None,
              **kw: Any) -> subprocess.Popen:
        """Start ``argv`` on ``machine``; stopped by :meth:`close` if still running. ``log``:
        its output goes to ``<log_dir>/<log>.log``."""
        if log is not None and self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            with (self.log_dir / f"{log}.log").open("ab") as out:
                proc = subprocess.Popen([*self.prefix(machine), *argv], stdin=stdin, stdout=out,
                                        stderr=subprocess.STDOUT, **kw)
        else:
            proc = subprocess.Popen([*self.prefix(machine), *argv], stdin=stdin, stdout=stdout,
                                    **kw)
        self.procs.append(proc)
        return proc

    def run(self, machine: str, argv: Sequence[str], timeout_s: float = 60.0,
            **kw: Any) -> subprocess.CompletedProcess:
        """Run ``argv`` on ``machine`` to its end, its output captured."""
        return subprocess.run([*self.prefix(machine), *argv], capture_output=True, text=True,
                              timeout=timeout_s, **kw)

    # -- the cables --------------------------------------------------------------------

    def cut(self, machine: str) -> None:
        """Unplug the machine's cable: nothing goes in or out of it any more."""
        _ip("-n", self.switch, "link", "set", self.machines[machine].port, "down")

    def restore(self, machine: str) -> None:
        _ip("-n", self.switch, "link", "set", self.machines[machine].port, "up")

    def is_cut(self, machine: str) -> bool:
        out = _ip("-n", self.switch, "link", "show", self.machines[machine].port).stdout
        return "state DOWN" in out or ",UP" not in out.split(">")[0]

    # -- the end -----------------------------------------------------------------------

    def close(self) -> None:
        """Stop what was started (SIGINT, then SIGKILL), then delete every namespace (their
        veths go with them)."""
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 10.0
        for proc in self.procs:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(10)
        self.procs.clear()
        for ns in reversed(self._made):
            _kill_inside(ns)
            _ip("netns", "del", ns, check=False)
        self._made.clear()
        self.machines.clear()
