"""Fixtures shared by every test layer (see tests/harness.py), and the kind of every test.

Every test is ``unit`` (in this process: no Zenoh session, no Lunaris process) or ``twin``
(real processes: a router, the services, the CLI); ``browser`` and ``ros2`` also mark the twin tests
that drive Chromium or real ROS 2 software. ``pytest -m unit`` waits on nothing. A test's kind
is its own mark or its module's ``pytestmark``, else :data:`KINDS` by its path; a module in no
folder listed is taken as ``twin`` (slow is the safe guess). A ``unit`` test that opens a Zenoh
session or runs Lunaris in a process fails, saying so.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
import zenoh

from common import keys
from tests.harness import ALL_SERVICES, Probe, Twin, open_router, router_endpoint, static_rover

# Tests never read an operator's Zenoh configuration.
os.environ.pop("LUNARIS_ZENOH_CONFIG", None)

TESTS = Path(__file__).resolve().parent
KIND_MARKS = ("unit", "twin", "browser", "ros2")
# path under tests/ (a folder, or a module of it) -> its tests' kinds; the longest path wins
KINDS: dict[str, tuple[str, ...]] = {
    "architecture": ("unit",),
    "common": ("unit",),
    "common/test_config.py": ("twin",),  # lunaris check and lunaris run as processes
    "common/test_connection.py": ("twin",),
    "common/test_worker_signals.py": ("twin",),  # each case a process of its own, ended if it hangs
    "console": ("twin", "browser"),
    "console/test_server.py": ("twin",),  # the server in-process, a router and a stand-in rover
    "console/test_up_console.py": ("twin",),
    "deploy": ("twin",),
    "integration": ("twin",),
    "integration/test_bridge_ros2.py": ("twin", "ros2"),
    "integration/test_bridge_rmw_zenoh_sdk.py": ("twin", "ros2"),
    "lunaris": ("twin",),
    "lunaris/test_client.py": ("unit",),
    "lunaris/test_record_offline.py": ("unit",),
    "lunaris/test_scenario_model.py": ("unit",),
    "lunaris/test_scenario_waiting.py": ("unit",),
    "reliability": ("twin",),
    "services": ("unit",),
    "services/test_composed.py": ("twin",),  # lunaris sim as a process
}


def _under_tests(path: Path) -> str:
    """``path`` relative to tests/ (a path elsewhere as it is)."""
    resolved = path.resolve()
    return resolved.relative_to(TESTS).as_posix() if resolved.is_relative_to(TESTS) else str(resolved)


def kinds_of(path: Path) -> tuple[str, ...]:
    """The kinds :data:`KINDS` gives a test module at ``path``."""
    rel = _under_tests(path)
    found = [k for k in KINDS if rel == k or rel.startswith(k + "/")]
    return KINDS[max(found, key=len)] if found else ("twin",)


# Folders in the order their tests are handed out: the longest first (the models' CPU-bound
# tests, then the long twin tests), so that on parallel workers no long test starts last.
FIRST = ("services", "reliability", "lunaris", "integration", "deploy", "console")


def _rank(item: pytest.Item) -> int:
    folder = _under_tests(item.path).split("/")[0]
    return FIRST.index(folder) if folder in FIRST else len(FIRST)


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each test's kinds; on parallel workers (``--dist loadgroup``) the tests of a module that
    share a fixture of a wider scope than the test's (a module's twin) go to one worker, which
    starts it once; the rest are handed out one by one, in the order of :data:`FIRST`."""
    grouped = config.pluginmanager.hasplugin("xdist")  # (its mark is unknown without it)
    for item in items:
        if not any(item.get_closest_marker(k) for k in KIND_MARKS):
            for kind in kinds_of(item.path):
                item.add_marker(kind)
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        if grouped and any(d.scope in ("class", "module", "package") for fds in defs for d in fds):
            item.add_marker(pytest.mark.xdist_group(_under_tests(item.path)))
    items.sort(key=_rank)  # stable: a module's tests stay together, in their order


def _lunaris_process(args: object) -> bool:
    """Whether a command line runs Lunaris (``python -m lunaris.cli ...``, ``lunaris ...``)."""
    words = [args] if isinstance(args, str | os.PathLike) else list(args)  # type: ignore[call-overload]
    return any("lunaris.cli" in str(w) or Path(str(w)).name == "lunaris" for w in words)


@pytest.fixture(autouse=True)
def _unit_tests_stay_in_process(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """A ``unit`` test that opens a Zenoh session or runs Lunaris in a process is a ``twin``
    test (a short helper process, a fresh interpreter checking imports, is allowed)."""
    if request.node.get_closest_marker("unit") is None:
        return
    wrong = (f"{request.node.nodeid} is marked unit but opens a Zenoh session or runs Lunaris "
             "in a process: mark it twin (tests/conftest.py KINDS)")

    def no_session(*_: object, **__: object) -> None:
        raise AssertionError(wrong)

    class Popen(subprocess.Popen):
        def __init__(self, args, *more, **kw):
            if _lunaris_process(args):
                raise AssertionError(wrong)
            super().__init__(args, *more, **kw)

    monkeypatch.setattr(zenoh, "open", no_session)
    monkeypatch.setattr(subprocess, "Popen", Popen)


@pytest.fixture
def router():
    """An embedded Zenoh router on a loopback port of the system's choosing; yields its
    endpoint."""
    session = open_router()
    try:
        yield router_endpoint(session)
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
    router = open_router()
    try:
        endpoint = router_endpoint(router)
        with Twin(endpoint, [static_mapp_file], tmp_path_factory.mktemp("twin")) as t, \
                Probe(endpoint) as p:
            p.watch("lunaris/**")
            p.wait_services("mapp-1", ALL_SERVICES)
            p.wait_value(keys.battery_state("mapp-1"), lambda b: b["current_a"] > 0)
            yield p, t
    finally:
        router.close()
