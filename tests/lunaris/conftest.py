"""Fixtures of the instructor tools' tests: a twin shared by a module, tools run as subprocesses."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from dataclasses import dataclass

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
    static_rover,
)

R = "mapp-1"
MAPP = static_rover("mapp.yaml")  # the first release's rover: no drive (tests/harness.py)


@dataclass
class Live:
    endpoint: str
    twin: Twin
    probe: Probe


@pytest.fixture(scope="module")
def live(tmp_path_factory) -> Iterator[Live]:
    """A MAPP twin on a router of its own, shared by a module's tests (each undoes what it does)."""
    endpoint = free_endpoint()
    router = open_router(endpoint)
    try:
        with Twin(endpoint, [MAPP], tmp_path_factory.mktemp("twin")) as twin, Probe(endpoint) as p:
            p.watch(f"{keys.ROOT}/{R}/**")
            p.wait_services(R, ALL_SERVICES)
            p.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
            yield Live(endpoint, twin, p)
    finally:
        router.close()


def run_tool(*args: str, timeout_s: float = 30.0, env: dict | None = None) -> subprocess.CompletedProcess:
    """Run ``lunaris ARGS`` to completion; text output captured."""
    return subprocess.run(lunaris_cmd(*args), capture_output=True, text=True, timeout=timeout_s, cwd=ROOT,
                          env=env if env is not None else env_without_zenoh_config(),
                          stdin=subprocess.DEVNULL)
