"""What the reliability suite shares: a whole twin, process sizes, kill -9 and restart.

Every test here is bounded in count and time, runs on loopback only, and stops what it
starts, pass or fail (the fixtures of ``tests/conftest.py``).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from common import keys
from testbed.procfs import rss_kib as rss_kib  # the reliability tests measure with it
from tests.harness import ALL_SERVICES, Probe, Twin, json_bridge_extra, static_rover, wait_for

R = "mapp-1"
MAPP = static_rover("mapp.yaml")  # without its drive: parked, the pack drains
WITH_BRIDGE = (*ALL_SERVICES, "bridge")


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(") ", 1)[1][0]
    except (FileNotFoundError, IndexError):
        return False
    return state != "Z"


def kill9(twin: Twin, service: str) -> None:
    proc = twin.procs[service]
    proc.kill()
    proc.wait(10)


def restart(twin: Twin, probe: Probe, service: str, rover: str = R) -> subprocess.Popen:
    """kill -9 a service, start it again, wait for its token: the new one's (the killed
    one's is waited out first; a full run found the old token still there, and a query
    sent at once went unanswered while the new process was still starting)."""
    kill9(twin, service)
    token = keys.service(rover, service)
    wait_for(lambda: not [r for r in probe.session.liveliness().get(token) if r.ok is not None], 10,
             f"the killed {service}'s token to go")
    proc = twin.start(service)
    probe.wait_services(rover, (service,))
    return proc


@pytest.fixture
def whole_twin(twin_factory, probe_solo, tmp_path):
    """(probe, twin): every service of mapp-1, bridge included (its json flavour on, its
    /diagnostics in the full view: every fault in effect), the probe watching every key."""
    probe_solo.watch("lunaris/**")
    twin = twin_factory([MAPP], services=WITH_BRIDGE, extra=json_bridge_extra(tmp_path, "full"))
    probe_solo.wait_services(R, WITH_BRIDGE)
    probe_solo.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
    return probe_solo, twin


def events(p: Probe, kind: str | None = None, key: str | None = None) -> list[dict]:
    return [e for e in p.events(R)
            if (kind is None or e["kind"] == kind) and (key is None or e["key"] == key)]


def wait_events(p: Probe, n: int, kind: str, key: str | None = None, timeout_s: float = 30.0) -> None:
    wait_for(lambda: len(events(p, kind, key)) >= n, timeout_s,
             lambda: f"{n} {kind} events (have {len(events(p, kind, key))})", poll_s=0.05)
