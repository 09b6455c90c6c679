"""``lunaris report --json`` of a live twin's recording: the symptoms the crew could see (SPEC
12d), from the services' own telemetry and events (issue 31: an instructor's open camera, its
rail off at the fault and switched on after, had ``first_symptom_t_s: null``)."""

from __future__ import annotations

import json
import signal
import subprocess

import pytest

from common import keys
from tests.harness import ROOT, env_without_zenoh_config, lunaris_cmd
from tests.lunaris.conftest import R, run_tool

pytestmark = pytest.mark.timeout(90)

RAIL, CAMERA = "5V_CH2", "nav_camera"


def test_an_open_camera_on_a_rail_off_at_the_fault_shows_once_the_rail_is_on(live, tmp_path):
    p, ep = live.probe, live.endpoint
    p.clear_history()
    done = run_tool("session", "start", R, "--trainee", "open circuit", "--connect", ep)
    assert done.returncode == 0, done.stdout + done.stderr
    recording = tmp_path / "open.mcap"
    rec = subprocess.Popen(lunaris_cmd("record", str(recording), "--connect", ep, "--rover", R),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                           env=env_without_zenoh_config())
    fault = keys.fault(R, f"load/{CAMERA}", "open")
    try:
        assert rec.stderr is not None and rec.stderr.readline().startswith("recording "), \
            "the recorder did not start"
        p.put(keys.cmd_rail(R, RAIL), {"on": False})
        p.wait_value(keys.rail_state(R, RAIL), lambda s: s["state"] == "off")
        p.put(fault, {})
        p.wait_event(R, lambda e: e["kind"] == "fault_injected" and e["key"] == fault)
        p.put(keys.cmd_rail(R, RAIL), {"on": True})
        on = p.wait_event(R, lambda e: e["kind"] == "command" and e["key"] == keys.cmd_rail(R, RAIL)
                          and (e.get("params") or {}).get("on") is True)
        seen = p.wait_value(keys.load_power(R, CAMERA), lambda x: x["on"] and x["power_w"] == 0.0)
        # a second of sim time more: the recorder, a subscriber of its own, has heard it too
        p.wait_value(keys.clock(R), lambda c: c["t_s"] >= seen["t_s"] + 1.0)
    finally:
        rec.send_signal(signal.SIGINT)
        rec.wait(20)
        p.delete(fault)
        p.put(keys.cmd_rail(R, RAIL), {"on": True})
    done = run_tool("report", str(recording), "--json")
    assert done.returncode == 0, done.stderr
    session = json.loads(done.stdout)[-1]
    assert session["trainee"] == "open circuit"
    (f,) = [f for f in session["faults"] if f["key"] == fault]
    # nothing while the rail was off; the first sample on the live rail, at the command's tick
    # or the next
    assert f["first_symptom_t_s"] is not None, f
    # (times to a part in 10^9: the same tick's time computed by two services can differ in
    # its last bits, 0.8 against 0.7999999999999999 in a full run)
    assert on["t_s"] - 1e-9 <= f["first_symptom_t_s"] <= seen["t_s"] + 1e-9, (on["t_s"], f, seen)
    assert f["symptom"] == f"load/{CAMERA} power 0 W on a live rail"
