"""A deployment as an integrator runs it, outside Docker: the commands themselves.

``lunaris deploy secrets`` into a test's folder, ``lunaris deploy acl --secrets-dir`` for a
router configuration that finds them there, ``lunaris router --config`` (the embedded
router reads the same JSON5 as zenohd, access control and TLS included) and each service
as ``lunaris run SERVICE --config client-lunaris-SERVICE.json5``: every process under its
own identity, with the publishers it really declares. ``prefix`` runs a command elsewhere
(``ip netns exec NS``: another machine, see tests/netns.py).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import zenoh

from common.connection import make_config

REPO = Path(__file__).resolve().parents[2]
SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")


def lunaris(*args: str) -> list[str]:
    return [sys.executable, "-m", "lunaris.cli", *args]


def run_lunaris(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    """A ``lunaris`` command run to its end; its output kept for the assertion's message."""
    env = {k: v for k, v in os.environ.items() if k != "LUNARIS_ZENOH_CONFIG"}
    return subprocess.run(lunaris(*args), cwd=REPO, capture_output=True, text=True,
                          timeout=timeout_s, env=env)


def wait_until(condition: Callable[[], Any], timeout_s: float,
               what: str | Callable[[], str]) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        got = condition()
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for "
                                 f"{what() if callable(what) else what}")
        time.sleep(0.02)


class Processes:
    """The processes a test starts, each logging to a file of ``folder``; all stopped by
    :meth:`stop` (SIGINT, then SIGKILL), pass or fail."""

    def __init__(self, folder: Path):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name: str, argv: Sequence[str], prefix: Sequence[str] = (),
              env: dict[str, str] | None = None) -> subprocess.Popen:
        environ = {k: v for k, v in os.environ.items() if k != "LUNARIS_ZENOH_CONFIG"}
        environ.update(env or {})
        with (self.folder / f"{name}.log").open("ab") as out:
            proc = subprocess.Popen([*prefix, *argv], cwd=REPO, stdout=out,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=environ)
        self.procs[name] = proc
        return proc

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def stop(self, name: str) -> None:
        proc = self.procs.pop(name, None)
        if proc is not None:
            _stop(proc)

    def stop_all(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in self.procs.values():
            _stop(proc)
        self.procs.clear()

    def tails(self, chars: int = 1500) -> str:
        """The end of every log: what a failing test prints."""
        return "\n".join(f"--- {p.stem} ---\n{p.read_text(errors='replace')[-chars:]}"
                         for p in sorted(self.folder.glob("*.log")))


def _stop(proc: subprocess.Popen, timeout_s: float = 10.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout_s)


def start_router(procs: Processes, name: str, config: Path, listen: list[str] | None = None,
                 prefix: Sequence[str] = (), env: dict[str, str] | None = None) -> None:
    """``lunaris router --config FILE`` (its own endpoints, or ``listen``), once it listens."""
    args = ["router", "--config", str(config)]
    for endpoint in listen or []:
        args += ["--listen", endpoint]
    proc = procs.start(name, lunaris(*args), prefix, env)
    wait_until(lambda: "listening" in procs.log(name) or proc.poll() is not None, 60,
               f"the router {name}")
    assert proc.poll() is None, f"the router {name} stopped:\n{procs.log(name)[-3000:]}"


def start_service(procs: Processes, service: str, secrets: Path, rovers: Sequence[Path],
                  state_dir: Path, connect: str | None = None, prefix: Sequence[str] = (),
                  extra: Sequence[str] = (), name: str | None = None) -> subprocess.Popen:
    """``lunaris run SERVICE`` with the service's own client configuration."""
    args = ["run", service, "--config", str(secrets / f"client-lunaris-{service}.json5"),
            "--state-dir", str(state_dir)]
    if connect:
        args += ["--connect", connect]
    for rover in rovers:
        args += ["--rover", str(rover)]
    return procs.start(name or service, lunaris(*args, *extra), prefix)


def open_as(secrets: Path, identity: str, connect: str | None = None) -> zenoh.Session:
    """A session of this process under one identity, from its generated client file."""
    return zenoh.open(make_config("client", connect=[connect] if connect else None,
                                  config_file=secrets / f"client-{identity}.json5"))


def live_services(session: zenoh.Session, rover: str) -> set[str]:
    return {str(r.ok.key_expr).rsplit("/", 1)[-1]
            for r in session.liveliness().get(f"lunaris/{rover}/service/*", timeout=5.0)
            if r.ok is not None}


class Tap:
    """Every sample a subscriber got, in order: (key, payload bytes, kind)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._got: list[tuple[str, bytes, str]] = []

    def __call__(self, s: zenoh.Sample) -> None:
        with self._lock:
            self._got.append((str(s.key_expr), s.payload.to_bytes(), str(s.kind)))

    def samples(self, key: str | Callable[[str], bool] | None = None) -> list[tuple[str, bytes, str]]:
        with self._lock:
            got = list(self._got)
        if key is None:
            return got
        return [s for s in got if (key(s[0]) if callable(key) else s[0] == key)]

    def payloads(self, key: str) -> list[bytes]:
        return [p for _, p, _ in self.samples(key)]


def changes(values: list[Any]) -> list[Any]:
    """``values`` with each run of equal ones kept once: the changes a reader saw."""
    out: list[Any] = []
    for v in values:
        if not out or out[-1] != v:
            out.append(v)
    return out


class Remote:
    """A running ``tests/deploy/remote.py``: commands in, its answers and samples out, read
    by a thread of ours as they come (see that module for the protocol)."""

    def __init__(self, proc: subprocess.Popen, name: str = "remote"):
        assert proc.stdin is not None and proc.stdout is not None
        self.proc, self.name = proc, name
        self._lock = threading.Lock()
        self._lines: list[dict[str, Any]] = []
        self._ids = iter(range(1, 1 << 30))
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.wait(lambda m: m["op"] == "ready", 60, f"{name}'s session")

    @staticmethod
    def argv(config: Path, connect: str | None = None) -> list[str]:
        return [sys.executable, "-m", "tests.deploy.remote", "--config", str(config),
                *(["--connect", connect] if connect else [])]

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            with self._lock:
                self._lines.append(msg)

    def lines(self) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._lines)

    def send(self, **cmd: Any) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()

    def wait(self, test: Callable[[dict[str, Any]], bool], timeout_s: float,
             what: str | Callable[[], str]) -> dict[str, Any]:
        def found() -> dict[str, Any] | None:
            if self.proc.poll() is not None:
                raise AssertionError(f"{self.name} stopped (exit {self.proc.returncode})")
            return next((m for m in self.lines() if test(m)), None)
        return wait_until(found, timeout_s, what)

    def call(self, op: str, timeout_s: float = 30.0, **args: Any) -> dict[str, Any]:
        """A command and its answer."""
        n = next(self._ids)
        self.send(op=op, id=n, **args)
        return self.wait(lambda m: m.get("id") == n and m["op"] != op, timeout_s,
                         f"{self.name}'s answer to {op} {args}")

    def subscribe(self, sid: str, key: str, decode: str = "json") -> None:
        self.send(op="sub", id=sid, key=key, decode=decode)
        self.wait(lambda m: m["op"] == "subscribed" and m["id"] == sid, 30, f"{self.name}'s {key}")

    def samples(self, sid: str, key: str | None = None) -> list[dict[str, Any]]:
        return [m for m in self.lines() if m["op"] == "sample" and m["id"] == sid
                and (key is None or m["key"] == key)]

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.send(op="quit")
                self.proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(10)
