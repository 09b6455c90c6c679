"""Fault -> the crew's /diagnostics: one router on loopback vs the three machines of the site.

Both deployments as generated, side by side in the same run (one after the other, so they
never share the cores), each process under its own identity, TLS and access control on:

- ``one router``: ``lunaris deploy secrets`` + ``deploy acl --secrets-dir``, ``lunaris router
  --config`` on 127.0.0.1, the nine services, an instructor and the crew's dashboard;
- ``three machines``: deploy/site.yaml on network namespaces (tests/netns.py): ground (router,
  faults, the instructor), mapp-1 (router, the models), crew (router, the bridge, the
  dashboard), mutual TLS between the routers.

The instructor and the dashboard are clients in processes of their own
(tests/deploy/remote.py), each on its machine; the time from the instructor's put of a load
short on mapp-1's nav_camera to the dashboard's sample is measured on ``time.monotonic()``,
one clock for every process of the host. Two end points, in the ros2dds flavour read
through Zenoh as the ``dashboard`` identity:

- ``first sign``: the first DiagnosticArray after the put in which the camera or its rail is
  no longer OK (today the injected short itself, WARN);
- ``rail ERROR``: the first in which the rail is ERROR (tripped): the symptom the crew sees
  even where the dashboard names no injected fault (SPEC §12b).

Between runs the short is cleared and the rail reset, and the dashboard's /diagnostics
back to OK. SPEC §10 target: p99 under 10 ms on a quiet machine, three machines.
Run: ``.venv/bin/python bench/site_latency.py [N]`` (as root, for the namespaces).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from benchlib import ROOT, machine, percentiles

from tests import netns
from tests.deploy.deployment import (
    SERVICES,
    Processes,
    Remote,
    run_lunaris,
    start_router,
    start_service,
    wait_until,
)
from tests.deploy.machines import SiteOnMachines

ROVER, RAIL, LOAD = "mapp-1", "5V_CH2", "nav_camera"
MAPP = ROOT / "config" / "rovers" / "mapp.yaml"
SHORT = f"lunaris/{ROVER}/fault/load/{LOAD}/short"
RESET = f"lunaris/{ROVER}/cmd/rail/{RAIL}"
WATCHED = (f"{ROVER}/rail/{RAIL}", f"{ROVER}/load/{LOAD}")


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def one_router(folder: Path) -> Iterator[tuple[Remote, Remote]]:
    endpoint = f"tls/127.0.0.1:{_free_port()}"
    secrets = folder / "secrets"
    assert run_lunaris("deploy", "secrets", str(secrets), "--host", "127.0.0.1", "--rover", str(MAPP),
                       "--connect", endpoint).returncode == 0
    assert run_lunaris("deploy", "acl", "--rover", str(MAPP), "--secrets-dir", str(secrets),
                       "--output", str(folder / "zenohd.json5")).returncode == 0
    procs = Processes(folder / "logs")
    remotes: list[Remote] = []
    try:
        start_router(procs, "router", folder / "zenohd.json5", [endpoint])
        for service in SERVICES:
            start_service(procs, service, secrets, [MAPP], folder / "state")
        for identity in ("instructor", "dashboard"):
            proc = subprocess.Popen(Remote.argv(secrets / f"client-{identity}.json5"), cwd=ROOT,
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            remotes.append(Remote(proc, identity))
        yield remotes[0], remotes[1]
    finally:
        for remote in remotes:
            remote.close()
        procs.stop_all()


@contextmanager
def three_machines(folder: Path) -> Iterator[tuple[Remote, Remote]]:
    with SiteOnMachines(folder) as site:
        yield site.remote("ground", "instructor"), site.remote("crew", "dashboard")


def _levels(sample: dict) -> dict[str, int]:
    return {s["name"]: s["level"] for s in sample["payload"] if s["name"] in WATCHED}


def _first_after(dashboard: Remote, t0: float, test: Callable[[dict[str, int]], bool],
                 what: str) -> dict:
    """The dashboard's first /diagnostics received after ``t0`` whose levels pass ``test``."""
    return wait_until(lambda: next((m for m in dashboard.samples("diag")
                                    if m["t"] > t0 and test(_levels(m))), None),
                      30, f"{what} on the dashboard")


def measure(instructor: Remote, dashboard: Remote, n: int) -> dict[str, list[float]]:
    dashboard.subscribe("diag", "diagnostics", decode="diagnostics")
    wait_until(lambda: dashboard.samples("diag"), 120, "the dashboard's /diagnostics")
    instructor.call("pub", key=SHORT)
    wait_until(lambda: instructor.call("matching", key=SHORT)["matching"], 60,
               "the instructor's publisher to learn of the loads service")
    got: dict[str, list[float]] = {"first sign": [], "rail ERROR": []}
    for _ in range(n):
        seen = len(dashboard.samples("diag"))
        wait_until(lambda s=seen: any(set(_levels(m).values()) == {0}
                                      for m in dashboard.samples("diag")[s:]), 30,
                   "the dashboard's /diagnostics all OK before the put")
        t0 = instructor.call("put", key=SHORT, payload=json.dumps({"resistance_ohm": 0.05}))["t"]
        first = _first_after(dashboard, t0, lambda lv: max(lv.values()) >= 1, "the fault")
        error = _first_after(dashboard, t0, lambda lv: lv.get(WATCHED[0]) == 2, "the rail tripped")
        got["first sign"].append((first["t"] - t0) * 1e3)
        got["rail ERROR"].append((error["t"] - t0) * 1e3)
        instructor.call("delete", key=SHORT)
        instructor.call("put", key=RESET, payload=json.dumps({"reset": True}))
    return got


def main() -> int:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 50
    why = netns.unavailable()
    print(f"fault -> the crew's /diagnostics, {n} load shorts on {ROVER}, each deployment as "
          f"generated (TLS, access control) ({machine()}; load average "
          f"{os.getloadavg()[0]:.2f} at the start)")
    results: dict[str, dict[str, list[float]]] = {}
    with tempfile.TemporaryDirectory(prefix="lunaris-bench-site-") as tmp:
        with one_router(Path(tmp) / "one") as (instructor, dashboard):
            results["one router, loopback"] = measure(instructor, dashboard, n)
        if why is None:
            with three_machines(Path(tmp) / "three") as (instructor, dashboard):
                results["three machines (netns)"] = measure(instructor, dashboard, n)
    for setup, ends in results.items():
        for end, ms in ends.items():
            print(f"  {setup:<24} put -> {end:<11} {percentiles(ms)}")
    if why is not None:
        print(f"  three machines: not measured: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
