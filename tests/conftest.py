"""Fixtures shared by every test layer (see tests/harness.py)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from common import keys
from tests.harness import ALL_SERVICES, Probe, Twin, free_endpoint, open_router, static_rover

# Tests never read an operator's Zenoh configuration.
os.environ.pop("LUNARIS_ZENOH_CONFIG", None)


@pytest.fixture
def router():
    """An embedded Zenoh router on a free loopback port; yields its endpoint."""
    endpoint = free_endpoint()
    session = open_router(endpoint)
    try:
        yield endpoint
    finally:
        session.close()


@pytest.fixture
def probe(router):
    with Probe(router) as p:
        yield p


@pytest.fixture(scope="session")
def static_mapp_file() -> Path:
    """The MAPP rover without its drive (see tests/harness.py): the rover of the power-chain,
    fault and tool tests."""
    return static_rover("mapp.yaml")


@pytest.fixture
def mapp_file(static_mapp_file) -> Path:
    return static_mapp_file


@pytest.fixture
def twin_factory(router, tmp_path):
    """Start services for rover files; every twin is stopped at teardown, pass or fail."""
    twins: list[Twin] = []

    def start(rover_files, services=None, **kw) -> Twin:
        kw.setdefault("state_dir", tmp_path / f"state{len(twins)}")
        twin = Twin(router, list(rover_files), **kw) if services is None else Twin(
            router, list(rover_files), services=tuple(services), **kw)
        twins.append(twin)
        return twin.__enter__()

    try:
        yield start
    finally:
        for twin in twins:
            twin.stop()
            # Shown by pytest only when the test fails: what each service said.
            for service in twin.services:
                if log := twin.log(service).strip():
                    print(f"--- {service} log ---\n{log[-3000:]}")


@pytest.fixture
def probe_solo(router):
    """A probe for tests that start their own twin (the name keeps it apart from module probes)."""
    with Probe(router) as p:
        yield p


@pytest.fixture(scope="module")
def mapp_twin(tmp_path_factory, static_mapp_file):
    """(probe, twin): every service for mapp-1 (without its drive) on a router of their own,
    shared by one module. The probe watches every lunaris key; tests must undo what they
    change."""
    endpoint = free_endpoint()
    router = open_router(endpoint)
    try:
        with Twin(endpoint, [static_mapp_file], tmp_path_factory.mktemp("twin")) as t, \
                Probe(endpoint) as p:
            p.watch("lunaris/**")
            p.wait_services("mapp-1", ALL_SERVICES)
            p.wait_value(keys.battery_state("mapp-1"), lambda b: b["current_a"] > 0)
            yield p, t
    finally:
        router.close()
