"""``lunaris router``: it logs as zenohd does (``RUST_LOG``), and reads the generated
configuration without a warning (no option Zenoh 1.10 deprecated)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.deploy.conftest import free_port
from tests.deploy.deployment import Processes, lunaris, run_lunaris, start_router, wait_until

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def procs(tmp_path: Path):
    procs = Processes(tmp_path / "logs")
    try:
        yield procs
    finally:
        procs.stop_all()


def test_the_router_logs_what_rust_log_asks_for(procs: Processes) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start("quiet", lunaris("router", "--listen", endpoint))
    wait_until(lambda: "listening" in procs.log("quiet"), 30, "the quiet router")
    procs.stop("quiet")
    assert "INFO" not in procs.log("quiet"), procs.log("quiet")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs.start("told", lunaris("router", "--listen", endpoint),
                env={"RUST_LOG": "info", "NO_COLOR": "1"})
    wait_until(lambda: "listening" in procs.log("told"), 30, "the router told to log")
    assert f"Zenoh can be reached at: {endpoint}" in procs.log("told"), procs.log("told")


def test_the_generated_configuration_has_no_deprecated_option(procs: Processes,
                                                              tmp_path: Path) -> None:
    secrets, config = tmp_path / "secrets", tmp_path / "zenohd.json5"
    assert run_lunaris("deploy", "secrets", str(secrets), "--host", "127.0.0.1").returncode == 0
    assert run_lunaris("deploy", "acl", "--secrets-dir", str(secrets),
                       "--output", str(config)).returncode == 0
    endpoint = f"tls/127.0.0.1:{free_port()}"
    start_router(procs, "router", config, [endpoint], env={"RUST_LOG": "warn", "NO_COLOR": "1"})
    log = procs.log("router")
    assert "WARN" not in log and "deprecated" not in log, log
