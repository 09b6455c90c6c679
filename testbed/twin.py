"""The twin on a bench, for the tests and the benchmarks: a router, the services, a probe.

- :func:`open_router` opens an embedded router on a loopback port the system chooses (the
  router binds port 0) and :func:`router_endpoint` says which: no other process can take the
  port between its choice and its use, as tests run in parallel (pytest-xdist). For a router
  that must come back on the same endpoint, or one in a process of its own,
  :func:`free_endpoint` names a free port outside the range the system gives out
  (:func:`free_port`, for any other server a test starts).
- :class:`Twin` starts services as ``lunaris run`` subprocesses connected to a
  router, waits for their liveliness tokens, and stops them (SIGINT, then kill)
  even when the test fails.
- :class:`Probe` is a client session that keeps the latest sample of every key
  it watches and waits on conditions with a deadline, never on fixed sleeps.
- :func:`rover_without_drive` writes a shipped rover without its ``drive`` section: the
  first release's rover, whose drive load is a noisy sample and whose radios take the
  position input. The tests of the power chain, the faults and the tools use it, so their
  expectations (a pack that drains, a position typed in) do not depend on the drive's.

The processes are started and stopped as ``lunaris up`` starts and stops them
(:mod:`lunaris.processes`); ``tests/harness.py`` hands these names on to the tests.
"""

from __future__ import annotations

import atexit
import functools
import json
import os
import random
import shutil
import socket
import subprocess
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.connection import make_config
from common.datafile import load_yaml
from lunaris.processes import (
    lunaris_cmd,
    run_args,
    start_router_process,
    stop_process,
    stop_processes,
    wait_for,
)

__all__ = ["ALL_SERVICES", "ANY_PORT", "ROOT", "ROVERS", "Probe", "Twin", "copies_of",
           "env_without_zenoh_config", "free_endpoint", "free_port", "json_bridge_extra", "lunaris_cmd",
           "mapp_fleet", "open_router", "router_endpoint", "rover_without_drive",
           "start_router_process", "static_rover", "stop_process", "wait_for"]

ROOT = Path(__file__).resolve().parent.parent
ROVERS = ROOT / "config" / "rovers"
ALL_SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "faults")


def rover_without_drive(src: Path, folder: Path) -> Path:
    """``src`` without its drive section (the top-level ``drive:`` block, cut from the text so
    the rest reads as written), written to ``folder`` under the same name."""
    kept, inside = [], False
    for line in src.read_text().splitlines(keepends=True):
        if line.startswith("drive:"):
            inside = True
        elif inside and line.strip() and not line[0].isspace() and not line.startswith("#"):
            inside = False
        if not inside:
            kept.append(line)
    folder.mkdir(parents=True, exist_ok=True)
    dst = folder / src.name
    dst.write_text("".join(kept))
    assert load_yaml(dst.read_text(), str(dst)).get("drive") is None, dst
    return dst


@functools.cache
def _static_folder() -> Path:
    folder = Path(tempfile.mkdtemp(prefix="lunaris-static-rovers-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder


@functools.cache
def static_rover(name: str) -> Path:
    """``config/rovers/<name>`` without its drive section, written once per test process."""
    return rover_without_drive(ROVERS / name, _static_folder())


def mapp_fleet(folder: Path, n: int) -> list[Path]:
    """``n`` files of the MAPP rover without its drive (:func:`static_rover`), ids mapp-01,
    mapp-02 ..., written to ``folder``."""
    base = static_rover("mapp.yaml").read_text()
    files = []
    for i in range(1, n + 1):
        rid = f"mapp-{i:02d}"
        f = folder / f"{rid}.yaml"
        f.write_text(base.replace("id: mapp-1", f"id: {rid}"))
        files.append(f)
    return files


def copies_of(rover: Rover, n: int, **load_changes: Any) -> list[Rover]:
    """``n`` copies of a rover (ids r0, r1, ...), each of its loads changed as given."""
    loads = [msgspec.structs.replace(ld, **load_changes) for ld in rover.loads]
    return [msgspec.structs.replace(rover, rover=msgspec.structs.replace(rover.rover, id=f"r{i}"),
                                    loads=loads) for i in range(n)]


ANY_PORT = "tcp/127.0.0.1:0"  # a router listening here gets a free port from the system


def _ephemeral_ports() -> range:
    """The ports the system gives to a socket bound to port 0 or connecting out."""
    try:
        low, high = map(int, Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
    except (OSError, ValueError):
        low, high = 32768, 60999  # Linux's default
    return range(low, high + 1)


def free_port() -> int:
    """A loopback TCP port nothing listens on, drawn at random below the system's ephemeral
    range: no socket bound to port 0 and no outgoing connection can take it before the
    caller binds it (two draws of parallel tests meet with a chance of about 1 in 20,000)."""
    ephemeral = _ephemeral_ports()
    pool = range(10000, ephemeral.start) if ephemeral.start > 12000 else range(ephemeral.stop, 65536)
    rng = random.SystemRandom()
    while True:
        port = rng.choice(pool)
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        return port


def free_endpoint() -> str:
    """A loopback TCP endpoint (:func:`free_port`) for a router that must come back on the same
    endpoint or that runs in a process of its own; elsewhere :func:`open_router` and
    :func:`router_endpoint` let the router take a port itself."""
    return f"tcp/127.0.0.1:{free_port()}"


def json_bridge_extra(folder: Path, crew_view: str = "symptoms") -> dict[str, list[str]]:
    """``Twin(extra=...)`` for a bridge with the shipped mapping and its json flavour on too
    (the shipped mapping leaves it off), so a test can read the dashboard topics as JSON; in
    the crew's view (``symptoms``, the shipped default) or ``full`` (every fault in effect)."""
    text = (ROOT / "config" / "bridge" / "default.yaml").read_text()
    assert "json: {enabled: false, prefix: json}" in text and "crew_view: symptoms" in text
    path = folder / "every-flavour.yaml"
    path.write_text(text.replace("json: {enabled: false, prefix: json}",
                                 "json: {enabled: true, prefix: json}")
                    .replace("crew_view: symptoms", f"crew_view: {crew_view}"))
    return {"bridge": ["--bridge-config", str(path)]}


class Twin:
    """Services for some rovers as subprocesses on a router at ``endpoint``."""

    def __init__(self, endpoint: str, rover_files: list[str | Path], state_dir: Path,
                 services: tuple[str, ...] = ALL_SERVICES, seed: int = 1,
                 extra: dict[str, list[str]] | None = None, log_dir: Path | None = None):
        self.endpoint = endpoint
        self.rover_files = [str(f) for f in rover_files]
        self.state_dir = state_dir
        self.services = services
        self.seed = seed
        self.extra = extra or {}
        self.procs: dict[str, subprocess.Popen] = {}
        self.router: subprocess.Popen | None = None  # a benchmark's router, run as a process
        self.logs: dict[str, Path] = {}
        self.log_dir = log_dir or state_dir  # elsewhere for a state folder on a disk made full

    def start(self, service: str) -> subprocess.Popen:
        """``service`` may be ``kind-k`` (``bridge-2``): another process of that kind, whose
        arguments (``--shard 2/3``) come from ``extra``."""
        args = run_args(service, self.rover_files, self.state_dir, connect=self.endpoint,
                        seed=self.seed, extra=self.extra.get(service, []))
        log = self.log_dir / f"{service}.log"
        self.logs[service] = log
        with open(log, "ab") as out:
            proc = subprocess.Popen(lunaris_cmd(*args), stdout=out, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, cwd=ROOT)
        self.procs[service] = proc
        return proc

    def __enter__(self) -> Twin:
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        try:
            for service in self.services:
                self.start(service)
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def stop(self) -> None:
        stop_processes(self.procs.values())

    def log(self, service: str) -> str:
        path = self.logs.get(service)
        return path.read_text(errors="replace") if path and path.exists() else ""


class Probe:
    """A test's own client session: watch keys, put, delete, get; wait on conditions."""

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.session = zenoh.open(make_config("client", connect=[endpoint]))
        self.latest: dict[str, Any] = {}
        self.history: dict[str, list[Any]] = {}
        self._events: dict[str, list[dict]] = {}  # rover -> its events, each once (events())
        self._event_ids: set[tuple] = set()
        self._lock = threading.Lock()
        self._subs: list[Any] = []

    def close(self) -> None:
        self._subs.clear()
        self.session.close()

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def watch(self, keyexpr: str) -> None:
        """Keep the latest JSON value and the history of every key matching ``keyexpr``."""
        def on_sample(s: zenoh.Sample) -> None:
            key = str(s.key_expr)
            raw = s.payload.to_bytes()
            try:
                value = json.loads(raw) if raw else None
            except ValueError:
                value = raw
            with self._lock:
                self.latest[key] = value
                self.history.setdefault(key, []).append(value)
                self._note_event(key, value)
        self._subs.append(self.session.declare_subscriber(keyexpr, on_sample))

    def clear_history(self) -> None:
        """Forget the samples and events seen so far (the latest value of each key is kept)."""
        with self._lock:
            self.history.clear()
            self._events.clear()
            self._event_ids.clear()

    def value(self, key: str) -> Any:
        with self._lock:
            return self.latest.get(key)

    def samples(self, key: str) -> list[Any]:
        with self._lock:
            return list(self.history.get(key, []))

    def wait_value(self, key: str, predicate: Callable[[Any], bool] = lambda v: True,
                   timeout_s: float = 10.0) -> Any:
        """The latest value of ``key`` once it satisfies ``predicate``."""
        def check() -> Any:
            v = self.value(key)
            return (v,) if v is not None and predicate(v) else None
        return wait_for(check, timeout_s,
                        lambda: f"{key} to satisfy the condition (last: {self.value(key)!r})")[0]

    def wait_sample(self, key: str, predicate: Callable[[Any], bool], timeout_s: float = 10.0) -> Any:
        """The first sample of ``key`` since the history was last cleared that satisfies
        ``predicate``: a state that lasts less than a poll of the latest value (a drill's dust
        for 0.6 s of wall time, on a machine too busy to look then) is still seen."""
        def check() -> Any:
            return next(((v,) for v in self.samples(key) if v is not None and predicate(v)), None)
        return wait_for(check, timeout_s,
                        lambda: f"a sample of {key} to satisfy the condition (last: {self.value(key)!r})")[0]

    def events(self, rover: str) -> list[dict]:
        """The events of ``rover`` watched, in the order they arrived, each once: from the
        journal's stream (``event``) and from each service's own key (``event/<service>``, so
        without the faults service too), told apart by ``source_id`` and ``seq``."""
        with self._lock:
            return list(self._events.get(rover, []))

    def _note_event(self, key: str, value: Any) -> None:
        """(Holding the lock.) Keep an event sample of ``event`` or ``event/<service>``."""
        parts = key.split("/")
        if not (3 <= len(parts) <= 4 and parts[2] == "event" and isinstance(value, dict)):
            return
        ident = (parts[1], value.get("source_id"), value.get("seq")) if value.get("source_id") \
            else (parts[1], len(self._event_ids))
        if ident not in self._event_ids:
            self._event_ids.add(ident)
            self._events.setdefault(parts[1], []).append(value)

    def wait_event(self, rover: str, predicate: Callable[[dict], bool],
                   timeout_s: float = 10.0) -> dict:
        """The first event of ``rover`` (on ``event`` or ``event/*``) that satisfies ``predicate``."""
        def check() -> Any:
            return next((e for e in self.events(rover) if predicate(e)), None)
        return wait_for(check, timeout_s, lambda: f"an event of {rover} (seen: {self.events(rover)!r})")

    def wait_services(self, rover: str, services: tuple[str, ...], timeout_s: float = 20.0) -> None:
        def live() -> bool:
            names = {str(r.ok.key_expr).rsplit("/", 1)[-1]
                     for r in self.session.liveliness().get(f"{keys.ROOT}/{rover}/service/*")
                     if r.ok is not None}
            return set(services) <= names
        wait_for(live, timeout_s, f"services {services} of {rover} to be live", poll_s=0.1)

    def put(self, key: str, payload: Any = b"") -> None:
        if not isinstance(payload, bytes | str):
            payload = json.dumps(payload)
        self.session.put(key, payload)

    def delete(self, key: str) -> None:
        self.session.delete(key)

    def get_json(self, selector: str, timeout_s: float = 5.0) -> list[Any]:
        replies = self.session.get(selector, timeout=timeout_s)
        return [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]


def open_router(endpoint: str = ANY_PORT) -> zenoh.Session:
    """An embedded Zenoh router listening on ``endpoint`` (default: a loopback port the system
    chooses; :func:`router_endpoint` tells which). Its admin space is readable, for that."""
    conf = make_config("router", listen=[endpoint])
    conf.insert_json5("adminspace/enabled", "true")
    return zenoh.open(conf)


def router_endpoint(router: zenoh.Session, timeout_s: float = 10.0) -> str:
    """The TCP endpoint a router of :func:`open_router` listens on (port 0 resolved), as its
    admin space (``@/<zid>/router``) lists it."""
    selector = f"@/{router.info.zid()}/router"

    def listening() -> str | None:
        for reply in router.get(selector, timeout=timeout_s):
            if reply.ok is not None:
                found = [loc.split("?")[0] for loc in json.loads(reply.ok.payload.to_bytes())["locators"]
                         if loc.startswith("tcp/")]
                if found:
                    return found[0]
        return None
    return wait_for(listening, timeout_s, f"the router's endpoint in {selector}")


def env_without_zenoh_config() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("LUNARIS_ZENOH_CONFIG", None)
    return env
