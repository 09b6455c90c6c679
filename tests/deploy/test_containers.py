"""The deployment as shipped, in real containers: deploy/Dockerfile built, docker-compose.yml up.

A Docker engine of the test's own (:mod:`testbed.engine`: ``dockerd`` on its own socket and
folders), the image built from ``deploy/Dockerfile`` on a Debian bookworm base made locally
(no registry is reachable; the root filesystem is cached in /var/cache/lunaris-tests), and
``docker-compose.yml`` of the repository brought up by docker-compose with the secrets of
``lunaris deploy secrets`` in a folder of the test, as deploy/README.md says. The router's
image, ``eclipse/zenoh``, cannot be had here either: its stand-in (tag
``eclipse/zenoh:lunaris-router``, through ``ZENOH_VERSION``) is the Lunaris image running
``lunaris router --config`` on zenohd's command line, the same JSON5, access control and TLS.
Everything else runs as shipped: preflight, the router's ports, every service under its own
identity, the console.

From the host, through the ports compose publishes on ``LUNARIS_BIND=127.0.0.2`` (loopback
on Linux, but not a name the console takes for its own): an instructor's fault reaches the
crew's ``/diagnostics`` read by the ``dashboard`` identity, and the console, signed in,
writes a fault that the ``debrief`` identity then sees in effect.

Runs where a Docker engine can start (root; ``make system-deps`` installs docker.io,
docker-compose and debootstrap); skips saying what is missing otherwise.
"""

from __future__ import annotations

import http.cookiejar
import json
import shutil
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from common import keys
from lunaris.processes import lunaris_cmd, wait_for
from testbed import engine as engine_mod
from testbed.deployment import REPO, SERVICES, Tap, live_services, open_as
from tests import rosmsg

pytestmark = [pytest.mark.containers, pytest.mark.timeout(1500),
              pytest.mark.skipif(engine_mod.unavailable() is not None,
                                 reason=str(engine_mod.unavailable()))]

BIND = "127.0.0.2"  # LUNARIS_BIND: the router's and the console's published ports
ENDPOINT = f"tls/{BIND}:7447"
CONSOLE = f"http://{BIND}:8080"
TAG = "containers-test"  # LUNARIS_TAG: the image compose runs, built here
ROUTER_TAG = "lunaris-router"  # ZENOH_VERSION: eclipse/zenoh:lunaris-router, the stand-in
PROJECT = "lunaris-ct"
ROVER, RAIL, LOAD = "mapp-1", "5V_CH2", "nav_camera"  # a short on the camera trips its rail
UP_S = 180.0  # every service live from `up` (ten Python processes starting on 2 cores)
STEP_S = 20.0
PASSWORD = "c0ntainer-test-Passw0rd-7q"

# zenohd's command line (-c FILE), on the embedded router that reads the same JSON5
_ZENOHD = '[ \\"$1\\" = -c ] || exit 64; exec python -m lunaris.cli router --config \\"$2\\"'
ROUTER_DOCKERFILE = f"""FROM lunaris:{TAG}
ENTRYPOINT ["/bin/sh", "-c", "{_ZENOHD}", "zenohd"]
"""


@dataclass
class Deployment:
    engine: engine_mod.Engine
    project: Path
    secrets: Path
    timings: dict[str, float]

    def compose(self, *args: str, check: bool = True, timeout_s: float = 300.0
                ) -> subprocess.CompletedProcess:
        return self.engine.command(
            ["docker-compose", "-f", str(REPO / "docker-compose.yml"), "--project-directory",
             str(self.project), "-p", PROJECT, *args],
            check=check, timeout_s=timeout_s,
            env=self.engine.env(LUNARIS_TAG=TAG, ZENOH_VERSION=ROUTER_TAG, LUNARIS_BIND=BIND,
                                LUNARIS_ALLOW_HOST=BIND))

    def logs(self) -> str:
        done = self.compose("logs", "--no-color", "--tail", "30", check=False, timeout_s=60)
        return (done.stdout + done.stderr).decode(errors="replace")[-12000:]


def _free(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex((BIND, port)) != 0


def _timed(timings: dict[str, float], step: str, start: float) -> None:
    timings[step] = round(time.monotonic() - start, 1)


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Deployment]:
    for port in (7447, 8080):
        if not _free(port):
            pytest.skip(f"{BIND}:{port} is taken: the compose file publishes that port")
    folder = tmp_path_factory.mktemp("containers")
    project = folder / "project"
    timings: dict[str, float] = {}
    # what docker-compose.yml mounts: ./config, ./deploy/zenohd.json5, ./deploy/secrets
    shutil.copytree(REPO / "config", project / "config")
    (project / "deploy").mkdir()
    shutil.copy(REPO / "deploy" / "zenohd.json5", project / "deploy" / "zenohd.json5")
    secrets = project / "deploy" / "secrets"
    for argv in (["deploy", "secrets", str(secrets), "--host", "router", "--host", BIND],
                 ["console", "users", "add", "ana", "--role", "instructor", "--password-stdin",
                  "--accounts", str(secrets / "console-accounts.json")]):
        subprocess.run(lunaris_cmd(*argv), cwd=REPO, check=True, capture_output=True, timeout=120,
                       input=PASSWORD.encode())
    subprocess.run(["chown", "-R", "10001:10001", str(secrets)], check=True)  # the image's user

    start = time.monotonic()
    engine_mod.base_rootfs()  # debootstrap on this machine's first run, the cache after
    _timed(timings, "base rootfs", start)
    with engine_mod.Engine() as engine:
        dep = Deployment(engine, project, secrets, timings)
        try:
            start = time.monotonic()
            engine.import_base()
            _timed(timings, "base import", start)
            start = time.monotonic()
            engine.run("build", "--network", "host", "-f", "deploy/Dockerfile", "-t", f"lunaris:{TAG}",
                       ".", cwd=REPO, timeout_s=1200)
            engine.run("build", "--network", "host", "-t", f"eclipse/zenoh:{ROUTER_TAG}", "-",
                       input=ROUTER_DOCKERFILE.encode(), timeout_s=300)
            _timed(timings, "build", start)
            start = time.monotonic()
            dep.compose("up", "-d", "--no-build")
            _timed(timings, "compose up", start)
            yield dep
        finally:
            print(f"timings [s]: {timings}")
            print(dep.logs())
            dep.compose("down", "-v", "--rmi", "all", "--remove-orphans", check=False)


@pytest.fixture
def sessions(deployment: Deployment) -> Iterator[dict[str, zenoh.Session]]:
    opened: dict[str, zenoh.Session] = {}
    try:
        for who in ("debrief", "instructor", "dashboard"):
            opened[who] = open_as(deployment.secrets, who, connect=ENDPOINT)
        start = time.monotonic()
        wait_for(lambda: live_services(opened["debrief"], ROVER) >= set(SERVICES), UP_S,
                 lambda: f"every service live (live: {sorted(live_services(opened['debrief'], ROVER))})"
                 f"\n{deployment.logs()}")
        deployment.timings.setdefault("services live", round(time.monotonic() - start, 1))
        yield opened
    finally:
        for session in opened.values():
            session.close()


def test_every_zenoh_configuration_shipped_and_made_disables_multicast_scouting(
        deployment: Deployment) -> None:
    files = [deployment.project / "deploy" / "zenohd.json5", *deployment.secrets.glob("*.json5")]
    assert len(files) > 5
    for path in files:
        conf = zenoh.Config.from_file(str(path))
        assert json.loads(conf.get_json("scouting/multicast/enabled")) is False, path


def _rail_levels(tap: Tap) -> list[int]:
    """The rail's level in each /diagnostics the dashboard got (ros2dds flavour, mapp-1's
    namespace), in order."""
    out = []
    for payload in tap.payloads("mapp_1/diagnostics"):
        for status in rosmsg.decode("diagnostic_msgs/msg/DiagnosticArray", payload).status:
            if status.name == f"{ROVER}/rail/{RAIL}":
                level = status.level
                out.append(level[0] if isinstance(level, bytes) else int(level))
    return out


def test_a_fault_from_the_host_reaches_the_crews_diagnostics(
        deployment: Deployment, sessions: dict[str, zenoh.Session]) -> None:
    crew = Tap()
    sessions["dashboard"].declare_subscriber("mapp_1/diagnostics", crew)
    wait_for(lambda: _rail_levels(crew)[-1:] == [0], STEP_S,
             lambda: f"the rail OK in the crew's /diagnostics ({_rail_levels(crew)})")
    short = keys.fault(ROVER, f"load/{LOAD}", "short")
    pub = sessions["instructor"].declare_publisher(short)
    wait_for(lambda: pub.matching_status.matching, STEP_S, "the faults service behind the router")
    pub.put(json.dumps({"resistance_ohm": 0.05}))
    wait_for(lambda: _rail_levels(crew)[-1:] == [2], STEP_S,
             lambda: f"the tripped rail as ERROR in the crew's /diagnostics ({_rail_levels(crew)})"
             f"\n{deployment.logs()}")
    pub.delete()
    sessions["instructor"].put(keys.cmd_rail(ROVER, RAIL), json.dumps({"reset": True}))
    wait_for(lambda: _rail_levels(crew)[-1:] == [0], STEP_S,
             lambda: f"the rail back to OK in the crew's /diagnostics ({_rail_levels(crew)})")


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args: object, **kwargs: object) -> None:
        return None  # the test reads the 303 itself


def _ask(opener: urllib.request.OpenerDirector, method: str, path: str,
         body: bytes | None = None, headers: dict[str, str] | None = None) -> tuple[int, dict, bytes]:
    request = urllib.request.Request(CONSOLE + path, data=body, method=method, headers=headers or {})
    try:
        with opener.open(request, timeout=30) as answer:
            return answer.status, dict(answer.headers), answer.read()
    except urllib.error.HTTPError as error:
        return error.code, dict(error.headers), error.read()


def _heating_in_effect(debrief: zenoh.Session) -> bool:
    for reply in debrief.get(keys.faults_active(ROVER, "battery"), timeout=5.0):
        if reply.ok is not None:
            faults = json.loads(reply.ok.payload.to_bytes())["faults"]
            if any(f["key"].endswith("/fault/battery/heating") for f in faults):
                return True
    return False


def test_the_console_answers_on_lunaris_bind_signs_in_and_writes(
        deployment: Deployment, sessions: dict[str, zenoh.Session]) -> None:
    jar = http.cookiejar.CookieJar()
    opener = urllib.request.build_opener(_NoRedirect, urllib.request.HTTPCookieProcessor(jar))
    status, headers, _ = _ask(opener, "GET", "/")
    assert (status, headers.get("location")) == (303, "/login?next=/"), (status, headers)
    assert _ask(opener, "PUT", f"/api/rovers/{ROVER}/keys/fault/battery/heating", b"5")[0] == 401
    status, headers, _ = _ask(opener, "POST", "/login",
                              f"user=ana&password={PASSWORD}&next=/".encode(),
                              {"Content-Type": "application/x-www-form-urlencoded"})
    assert status == 303 and len(jar) == 1, (status, headers)
    status, _, me = _ask(opener, "GET", "/api/me")
    assert status == 200 and json.loads(me)["name"] == "ana", me
    status, _, answer = _ask(opener, "PUT", f"/api/rovers/{ROVER}/keys/fault/battery/heating", b"5",
                             {"Origin": CONSOLE})
    assert status == 200, answer
    wait_for(lambda: _heating_in_effect(sessions["debrief"]), STEP_S,
             lambda: f"the console's fault in effect\n{deployment.logs()}")
