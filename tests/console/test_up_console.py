"""``lunaris up --console``: the twin and the console in one command, the console supervised."""

from __future__ import annotations

import json
import signal
import subprocess
import urllib.request

import pytest

from testbed.twin import free_port
from tests.console.conftest import MAPP
from tests.harness import ROOT, env_without_zenoh_config, free_endpoint, lunaris_cmd, wait_for

pytestmark = pytest.mark.timeout(90)


def test_up_starts_the_console_and_prints_its_address(tmp_path):
    port, endpoint = free_port(), free_endpoint()
    log = tmp_path / "up.log"
    with open(log, "wb") as out:
        up = subprocess.Popen(lunaris_cmd("up", "--rover", str(MAPP), "--listen", endpoint, "--no-status",
                                          "--state-dir", str(tmp_path / "state"), "--console",
                                          f"127.0.0.1:{port}", "--recordings", str(tmp_path / "recs")),
                              stdout=out, stderr=subprocess.STDOUT, cwd=ROOT, env=env_without_zenoh_config())
    try:
        wait_for(lambda: f"instructor console: http://127.0.0.1:{port}/" in log.read_text(), 20,
                 lambda: f"the console's address (up said: {log.read_text()})")
        assert "you are the instructor" in log.read_text()

        def snapshot() -> dict | None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/live", timeout=5) as r:
                    first = json.loads(r.readline().removeprefix(b"data: "))
            except OSError:
                return None
            return first if "lunaris/mapp-1/battery/state" in first["values"] else None
        first = wait_for(snapshot, 40, "the console to show the rover", poll_s=0.5)
        assert first["type"] == "snapshot" and "faults" in first["services"]["mapp-1"]
        # the recordings where up was told (they went to ./recordings whatever it was given)
        assert f"recordings in {tmp_path / 'recs'}" in log.read_text()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/recordings", timeout=5) as r:
            assert json.loads(r.read())["folder"] == str(tmp_path / "recs")
    finally:
        up.send_signal(signal.SIGINT)
        up.wait(30)
    assert "[up] stopped" in log.read_text()
