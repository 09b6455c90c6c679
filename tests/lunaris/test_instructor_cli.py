"""``lunaris rail``, ``clock``, ``input``, ``reset`` and ``snapshot`` against a running twin: each
confirmed by the twin's answer, with ``lunaris fault``'s exit codes (0, 1, 2)."""

from __future__ import annotations

import json

import pytest

from common import keys
from tests.lunaris.conftest import R, run_tool

pytestmark = pytest.mark.timeout(90)


def test_rail_off_on_and_a_rejection(live):
    p, ep = live.probe, live.endpoint
    done = run_tool("rail", R, "3V3_CH2", "off", "--connect", ep)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("accepted: command") and "the rail is now off" in done.stdout
    p.wait_value(keys.rail_state(R, "3V3_CH2"), lambda r: r["state"] == "off")
    assert "the rail is now on" in run_tool("rail", R, "3V3_CH2", "on", "--connect", ep).stdout
    bad = run_tool("rail", R, "9V", "on", "--connect", ep)
    assert bad.returncode == 1 and "has no rail '9V'" in bad.stdout
    solar = run_tool("rail", R, "SOLAR", "off", "--connect", ep, "--json")
    assert solar.returncode == 1 and json.loads(solar.stdout)["kind"] == "rejected"


def test_the_instructor_stands_in_for_the_crew(live):
    """A drill run without the crew's dashboard: ``--as-crew`` makes the command the crew's (its
    event says so, and the crew's response counts it); without it, the instructor's."""
    ep = live.endpoint
    done = run_tool("rail", R, "3V3_CH2", "off", "--as-crew", "--connect", ep, "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["actor"] == "crew"
    done = run_tool("rail", R, "3V3_CH2", "on", "--connect", ep, "--json")
    assert done.returncode == 0 and json.loads(done.stdout)["actor"] == "instructor"


def test_clock_pause_resume_scale(live):
    p, ep = live.probe, live.endpoint
    done = run_tool("clock", R, "pause", "--connect", ep)
    assert done.returncode == 0 and "clock paused" in done.stdout, done.stderr
    p.wait_value(keys.clock(R), lambda c: c["paused"])
    assert "clock paused at x5" in run_tool("clock", R, "scale", "5", "--connect", ep).stdout
    done = run_tool("clock", R, "resume", "--connect", ep)
    assert "clock running at x5" in done.stdout
    assert run_tool("clock", R, "scale", "1", "--connect", ep).returncode == 0
    p.wait_value(keys.clock(R), lambda c: not c["paused"] and c["time_scale"] == 1)
    bad = run_tool("clock", R, "scale", "-2", "--connect", ep)
    assert bad.returncode == 1 and "time_scale" in bad.stderr  # refused before sending
    assert run_tool("clock", R, "scale", "--connect", ep).returncode == 1


def test_inputs_sun_panel_position_umbilical(live):
    p, ep = live.probe, live.endpoint
    done = run_tool("input", R, "sun_angle", "70", "--connect", ep)
    assert done.returncode == 0 and "accepted: input" in done.stdout and "sun angle 70 deg" in done.stdout
    p.wait_value(keys.solar_power(R, "right"), lambda s: s["sun_angle_deg"] == 70)
    done = run_tool("input", R, "solar/left/sun_angle", "20", "--connect", ep)
    assert "on panel left" in done.stdout, done.stderr
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["sun_angle_deg"] == 20)
    assert p.value(keys.solar_power(R, "right"))["sun_angle_deg"] == 70
    done = run_tool("input", R, "solar/left/sun_angle", "--delete", "--connect", ep)
    assert "back to the rover's sun angle" in done.stdout
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["sun_angle_deg"] == 70)
    # the dashboard's dust on one panel, a layer over the instructor's dust fault
    done = run_tool("input", R, "solar/left/dust", "0.5", "--connect", ep)
    assert done.returncode == 0 and "dust 0.5 on panel left" in done.stdout, done.stdout + done.stderr
    half = p.wait_value(keys.solar_power(R, "left"), lambda s: s["dust"] == 0.5 and s["faults"] == [])
    p.put(keys.fault(R, "solar/left", "dust"), 0.3)
    # 1 - (1 - 0.3)(1 - 0.5) = 0.65 of the light lost; dust reports the input, never the fault
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["dust"] == 0.5
                 and s["power_w"] == pytest.approx(0.7 * half["power_w"]))
    p.delete(keys.fault(R, "solar/left", "dust"))
    done = run_tool("input", R, "solar/left/dust", "--delete", "--connect", ep)
    assert "no dust input on panel left" in done.stdout, done.stdout + done.stderr
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["dust"] == 0.0)
    assert run_tool("input", R, "solar/left/dust", "1.5", "--connect", ep).returncode == 1
    done = run_tool("input", R, "radio/lander/position", "300", "45", "--connect", ep)
    assert done.returncode == 0 and "300 m at 45 deg" in done.stdout, done.stdout + done.stderr
    done = run_tool("input", R, "umbilical", "true", "--connect", ep)
    assert "umbilical plugged in" in done.stdout
    p.wait_value(keys.umbilical_state(R), lambda u: u["connected"])
    assert run_tool("input", R, "umbilical", "false", "--connect", ep).returncode == 0
    assert run_tool("input", R, "sun_angle", "60", "--connect", ep).returncode == 0
    assert run_tool("input", R, "radio/lander/position", "0", "0", "--connect", ep).returncode == 0
    # Refused before sending, in the Struct's words; refused by the twin, in its words.
    bad = run_tool("input", R, "sun_angle", "500", "--connect", ep)
    assert bad.returncode == 1 and "angle_deg must be at most 360 (got 500)" in bad.stderr
    bad = run_tool("input", R, "solar/middle/sun_angle", "5", "--connect", ep)
    assert bad.returncode == 1 and "has no panel 'middle'" in bad.stdout
    bad = run_tool("input", R, "drive/traverse", '{"waypoints": [{"x_m": 1, "y_m": 0, "z_m": 0}]}',
                   "--connect", ep)
    assert bad.returncode == 1 and "no drive section" in bad.stdout
    assert run_tool("input", R, "wind", "3", "--connect", ep).returncode == 1
    assert run_tool("input", R, "sun_angle", "--delete", "--connect", ep).returncode == 1


def test_reset_and_snapshots(live):
    p, ep = live.probe, live.endpoint
    done = run_tool("snapshot", "save", R, "cli-1", "--connect", ep)
    assert done.returncode == 0 and "snapshot 'cli-1' saved" in done.stdout, done.stderr
    listed = run_tool("snapshot", "list", R, "--connect", ep)
    assert listed.returncode == 0 and listed.stdout.startswith("cli-1"), listed.stdout
    assert json.loads(run_tool("snapshot", "list", R, "--json", "--connect", ep).stdout)[0]["name"] == "cli-1"
    done = run_tool("snapshot", "restore", R, "cli-1", "--connect", ep)
    assert done.returncode == 0 and "restored" in done.stdout
    bad = run_tool("snapshot", "restore", R, "never", "--connect", ep)
    assert bad.returncode == 1 and "no snapshot 'never'" in bad.stdout
    assert run_tool("snapshot", "save", R, "bad name", "--connect", ep).returncode == 1
    assert run_tool("snapshot", "save", R, "--connect", ep).returncode == 1
    done = run_tool("reset", R, "--connect", ep)
    assert done.returncode == 0 and "session reset" in done.stdout
    p.wait_value(keys.clock(R), lambda c: c["cause"] == "reset")
    gone = run_tool("reset", "no-such-rover", "--connect", ep, "--wait", "3")
    assert gone.returncode == 2 and "unknown rover" in gone.stderr


@pytest.mark.parametrize("command", [["pdm", "--interval", "0.2"], ["watch", "--interval", "0.2"]])
def test_a_reader_that_goes_away_ends_the_tool_without_a_traceback(live, command):
    """``lunaris pdm | head``: the tool's next print finds the pipe closed and ends quietly."""
    import subprocess

    from tests.harness import ROOT, env_without_zenoh_config, lunaris_cmd
    proc = subprocess.Popen(lunaris_cmd(*command, "--rover", R, "--connect", live.endpoint),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                            env=env_without_zenoh_config(), stdin=subprocess.DEVNULL)
    try:
        assert proc.stdout is not None and proc.stdout.readline()  # it prints ...
        proc.stdout.close()  # ... and its reader goes, as head does after its lines
        proc.wait(20)
        err = proc.stderr.read().decode() if proc.stderr else ""
        assert "Traceback" not in err and "BrokenPipeError" not in err, err
        assert proc.returncode == 0, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("name, said", [
    ("before storm", "'before storm' has a space"),
    ("été", "'été' has 'é'"),
    ("a/b", "'a/b' has a '/'"),
])
def test_a_snapshot_name_that_cannot_be_one_is_refused_in_words_before_sending(name, said):
    done = run_tool("snapshot", "save", R, name, "--connect", "tcp/127.0.0.1:9", "--wait", "1")
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr == ("lunaris snapshot: a snapshot name is letters, digits, '-', '_' and '.'; "
                           f"{said}\n")
