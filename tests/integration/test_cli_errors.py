"""Command-line errors are one clear line and a non-zero exit, never a traceback."""

from __future__ import annotations

import subprocess

import pytest

from tests.harness import ROOT, ROVERS, lunaris_cmd

pytestmark = pytest.mark.timeout(60)


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(lunaris_cmd(*args), capture_output=True, text=True, cwd=ROOT, timeout=45)


def test_a_router_on_a_port_in_use(router):
    for cmd in (("router", "--listen", router), ("up", "--listen", router, "--no-status")):
        r = run(*cmd)
        assert r.returncode == 1
        assert "Address already in use" in r.stderr and "Traceback" not in r.stderr
        assert ".rs:" not in r.stderr  # no Rust source locations


def test_a_missing_zenoh_configuration_file(tmp_path):
    r = run("run", "clock", "--rover", str(ROVERS / "mapp.yaml"), "--config", str(tmp_path / "x"))
    assert r.returncode == 1 and "does not exist" in r.stderr and "Traceback" not in r.stderr


def test_up_refuses_unknown_services_and_broken_rovers(tmp_path):
    r = run("up", "--services", "clock,warp_drive")
    assert r.returncode == 2 and "unknown service(s): warp_drive" in r.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("rover: {id: x, name: y}\n")
    r = run("up", "--rover", str(bad))
    assert r.returncode == 2 and "battery: missing required field" in r.stderr
