"""Shared helpers for the deployment tests: the router of deploy/zenohd.json5 on loopback.

No Docker engine is needed (SPEC §11): the router's configuration is exercised by an
embedded Zenoh router (a Python session in router mode) that reads the same JSON5 file,
in a subprocess, on a free port of 127.0.0.1, over TLS, with the secrets that
``lunaris deploy secrets`` makes (a fresh set per test module, never the repository's).
"""

from __future__ import annotations

import base64
import json
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import zenoh

from lunaris import processes
from lunaris.deploy_secrets import read_credentials as read_credentials  # the tests read them
from lunaris.processes import stop_process as stop_process  # the tests stop with it

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"
ROUTER_CONFIG = DEPLOY / "zenohd.json5"

READY_TIMEOUT_S = 20.0

# Runs in the router subprocess: argv[1] the JSON5 file, argv[2] a JSON object of
# path -> value overrides (zenoh config paths). Prints READY once listening and
# serves until SIGTERM or SIGINT.
_ROUTER_SCRIPT = """
import json, signal, sys, threading
import zenoh

zenoh.init_log_from_env_or("error")
conf = zenoh.Config.from_file(sys.argv[1])
for path, value in json.loads(sys.argv[2]).items():
    conf.insert_json5(path, json.dumps(value))
stop = threading.Event()
for sig in (signal.SIGTERM, signal.SIGINT):
    signal.signal(sig, lambda *_: stop.set())
with zenoh.open(conf):
    print("READY", flush=True)
    stop.wait()
"""


def free_port() -> int:
    """A TCP port of 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_test_secrets(folder: Path) -> Path:
    """A deployment's secrets for a router on 127.0.0.1 (TLS certificate included)."""
    from lunaris.deploy import make_secrets
    make_secrets(folder, ["localhost", "127.0.0.1"], "tls/127.0.0.1:7447")
    return folder


def wait_for(condition: Callable[[], Any], what: str, timeout_s: float = 10.0) -> Any:
    """:func:`lunaris.processes.wait_for`, ``what`` first as these tests write it."""
    return processes.wait_for(condition, timeout_s, what, poll_s=0.02)


class Router:
    """A running router subprocess and the client configurations that reach it."""

    def __init__(self, port: int, secrets: Path):
        self.port = port
        self.secrets = secrets
        self.endpoint = f"tls/127.0.0.1:{port}"
        self.credentials = read_credentials(secrets / "credentials.txt")
        self._sessions: list[zenoh.Session] = []

    def client_config(
        self,
        user: str | None = None,
        password: str | None = None,
        *,
        base: Path | None = None,
        fail_fast: bool = False,
    ) -> zenoh.Config:
        """A client of this router: ``base`` file if given, credentials if given.

        ``fail_fast`` makes ``zenoh.open`` raise within a second when the router
        refuses the session, instead of retrying.
        """
        conf = zenoh.Config.from_file(str(base)) if base else zenoh.Config()
        if base is None:  # the deployment's CA, so that TLS works
            ca = (self.secrets / "tls" / "ca.crt").read_text()
            conf.insert_json5("transport/link/tls/root_ca_certificate_base64",
                              json.dumps(base64.b64encode(ca.encode()).decode()))
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([self.endpoint]))
        conf.insert_json5("listen/endpoints", "[]")
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("timestamping/enabled", "true")
        if user is not None:
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        if password is not None:
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
        conf.insert_json5("connect/timeout_ms", "1000" if fail_fast else "10000")
        conf.insert_json5("connect/exit_on_failure", "true")
        return conf

    def open(self, user: str) -> zenoh.Session:
        """A session authenticated as ``user``, from its generated client configuration."""
        session = zenoh.open(self.client_config(base=self.secrets / f"client-{user}.json5"))
        self._sessions.append(session)
        return session

    def close_sessions(self) -> None:
        while self._sessions:
            self._sessions.pop().close()


@contextmanager
def running_router(secrets: Path, overrides: dict[str, Any] | None = None,
                   config: Path = ROUTER_CONFIG) -> Iterator[Router]:
    """deploy/zenohd.json5 served over TLS on a free loopback port, with ``secrets``."""
    port = free_port()
    settings = {
        "listen/endpoints": [f"tls/127.0.0.1:{port}"],
        "transport/auth/usrpwd/dictionary_file": str(secrets / "credentials.txt"),
        "transport/link/tls/listen_certificate": str(secrets / "tls" / "router.crt"),
        "transport/link/tls/listen_private_key": str(secrets / "tls" / "router.key"),
        "scouting/multicast/enabled": False,
        **(overrides or {}),
    }
    with tempfile.TemporaryFile() as stderr:
        proc = subprocess.Popen(
            [sys.executable, "-c", _ROUTER_SCRIPT, str(config), json.dumps(settings)],
            stdout=subprocess.PIPE, stderr=stderr, cwd=REPO,
        )
        try:
            _wait_ready(proc, stderr)
            yield Router(port, secrets)
        finally:
            stop_process(proc)
            proc.stdout.close()


def _wait_ready(proc: subprocess.Popen, stderr) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stdout], [], [], 0.1)
        if ready:
            line = proc.stdout.readline()
            if line.strip() == b"READY":
                return
            if not line:  # EOF: the router died
                break
    proc.poll()
    stderr.seek(0)
    pytest.fail(f"router did not start (exit code {proc.returncode}):\n"
                f"{stderr.read().decode(errors='replace')[-4000:]}")


@pytest.fixture(scope="module")
def secrets(tmp_path_factory) -> Path:
    return make_test_secrets(tmp_path_factory.mktemp("secrets"))


@pytest.fixture(scope="module")
def router_process(secrets: Path) -> Iterator[Router]:
    with running_router(secrets) as router:
        yield router


@pytest.fixture
def router(router_process: Router) -> Iterator[Router]:
    """The module's router; sessions opened through it are closed after each test."""
    try:
        yield router_process
    finally:
        router_process.close_sessions()


class Collector:
    """Thread-safe record of what a callback received (Zenoh calls back on its threads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: list[Any] = []

    def __call__(self, item: Any) -> None:
        with self._lock:
            self._items.append(item)

    @property
    def items(self) -> list[Any]:
        with self._lock:
            return list(self._items)


def service_env(secrets: Path, service: str) -> dict[str, str]:
    """Environment of a Lunaris service subprocess with its own identity, as a container."""
    env = dict(os.environ)
    env["LUNARIS_ZENOH_CONFIG"] = str(secrets / f"client-lunaris-{service}.json5")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env
