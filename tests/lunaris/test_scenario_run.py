"""``lunaris scenario run`` against a running twin: every step fires at its time or on its
condition, and its effect shows on the keys."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from common import keys
from tests.harness import ROOT, env_without_zenoh_config, lunaris_cmd, wait_for
from tests.lunaris.conftest import MAPP, R, run_tool

pytestmark = pytest.mark.timeout(90)

TICK_S = 0.1  # mapp.yaml: 10 Hz
SCENARIO = """
scenario: {name: integration drill}
rover: mapp-1
time_scale: 5               # 0.5 s of sim time per tick
steps:
  - name: dust
    at_s: 2
    inject: {component: solar/left, kind: dust, value: 0.5}
  - name: sun ramp
    after_s: 1
    sun_angle: {from: 60, to: 80, over_s: 4}
  - name: short once the sun is low
    after_s: 0
    when: solar.right.sun_angle_deg >= 79.9
    timeout_s: 30
    inject: {component: load/nav_camera, kind: short}
  - name: tripped
    after_s: 0
    when: rail.5V_CH2.state == tripped
    timeout_s: 5
    note: the channel tripped
  - name: clear the short
    after_s: 1
    clear: {component: load/nav_camera, kind: short}
  - name: reset the channel
    after_s: 0
    rail: {name: 5V_CH2, reset: true}
  - name: faster clock
    at_s: 4
    clock: {time_scale: 8}
  - name: drive away
    at_s: 3
    position: {radio: lander, distance_m: {from: 100, to: 600, over_s: 6}, angle_deg: 0}
  - name: lost the lander
    after_s: 0
    when: radio.lander.in_range == false
    timeout_s: 30
    clear: {component: solar/left, kind: dust}
  - name: plugged in
    at_s: 1
    umbilical: true
"""


def _run(path: Path, *args: str, timeout_s: float = 60) -> tuple[subprocess.CompletedProcess, dict]:
    summary = path.with_suffix(".json")
    done = run_tool("scenario", "run", str(path), "--json-summary", str(summary), *args, timeout_s=timeout_s)
    return done, json.loads(summary.read_text()) if summary.exists() else {}


def test_a_scenario_plays_every_step_at_its_time_or_condition(live, tmp_path):
    p, ep = live.probe, live.endpoint
    p.clear_history()
    path = tmp_path / "drill.yaml"
    path.write_text(SCENARIO)
    try:
        done, summary = _run(path, "--connect", ep, "--rover-file", str(MAPP))  # the rover without
        assert done.returncode == 0, done.stdout + done.stderr                # a drive: position
        assert summary["ok"] and summary["end_reason"] == "every step has played"
        steps = {s["label"]: s for s in summary["steps"]}
        t0 = summary["start_t_s"]

        # times: each step fired on the first tick at or after it was due (ticks of 0.5 or 0.8 s)
        def fired(label: str) -> float:
            return steps[label]["fired_t_s"]
        max_tick = 8 * TICK_S + 1e-6
        for label, due in (("dust", 2.0), ("plugged in", 1.0), ("drive away", 3.0), ("faster clock", 4.0)):
            assert due <= fired(label) <= due + max_tick, (label, fired(label))
        def after(label: str, previous: str, delay_s: float, ticks: int = 1) -> None:
            lo = fired(previous) + delay_s
            assert lo <= fired(label) <= lo + ticks * max_tick, (label, fired(label), previous, lo)
        after("sun ramp", "dust", 1.0)
        after("short once the sun is low", "sun ramp", 4.0, ticks=2)  # the ramp's end, then the sample
        after("tripped", "short once the sun is low", 0.0)
        after("clear the short", "tripped", 1.0)
        assert fired("reset the channel") == fired("clear the short")
        # in range up to 400 m along the x axis: 100 -> 600 m in 6 s passes 400 m at 3.6 s
        after("lost the lander", "drive away", 3.6, ticks=2)
        outcomes = {label: (s["status"], s["outcome"]) for label, s in steps.items()}
        assert outcomes == {
            "dust": ("fired", "accepted"), "sun ramp": ("done", "accepted"),
            "short once the sun is low": ("fired", "accepted"), "tripped": ("fired", "reached"),
            "clear the short": ("fired", "accepted"), "reset the channel": ("fired", "accepted"),
            "faster clock": ("fired", "accepted"), "drive away": ("done", "accepted"),
            "lost the lander": ("fired", "accepted"), "plugged in": ("fired", "accepted"),
        }

        # the twin's own journal agrees with the player's times
        journal = {(e["kind"], e["key"]): e["t_s"] - t0 for e in p.events(R)}
        for kind, key, label in (
                ("fault_injected", keys.fault(R, "solar/left", "dust"), "dust"),
                ("fault_injected", keys.fault(R, "load/nav_camera", "short"), "short once the sun is low"),
                ("fault_cleared", keys.fault(R, "load/nav_camera", "short"), "clear the short"),
                ("fault_cleared", keys.fault(R, "solar/left", "dust"), "lost the lander")):
            assert abs(journal[(kind, key)] - fired(label)) <= max_tick, (kind, key)

        # the effects, on the keys
        # the dust, as less power: the left panel against the clean right one, tick by tick
        right = {s["t_s"]: s["power_w"] for s in p.samples(keys.solar_power(R, "right"))}
        ratios = [s["power_w"] / right[s["t_s"]] for s in p.samples(keys.solar_power(R, "left"))
                  if right.get(s["t_s"])]
        assert any(r == pytest.approx(0.5) for r in ratios) and ratios[-1] == pytest.approx(1.0)
        angles = sorted({round(s["sun_angle_deg"], 3) for s in p.samples(keys.solar_power(R, "right"))})
        assert angles[0] == 60.0 and angles[-1] == 80.0 and len(angles) >= 6  # a ramp, not a jump
        states = [s["state"] for s in p.samples(keys.rail_state(R, "5V_CH2"))]
        assert "tripped" in states and states[-1] == "on"
        link = p.samples(keys.radio_link(R, "lander"))
        assert link[-1]["in_range"] is False and link[-1]["x_m"] == pytest.approx(600.0)
        assert any(s["in_range"] and 100 < s["x_m"] < 400 for s in link)
        assert p.value(keys.umbilical_state(R))["connected"] is True
        scales = [c["time_scale"] for c in p.samples(keys.clock(R))]
        assert {5.0, 8.0} <= set(scales)
        p.wait_value(keys.clock(R), lambda c: c["time_scale"] == 1.0)  # put back at the end
        assert "clock of mapp-1 put back to x1" in done.stdout
        assert "step 4/10 tripped: checkpoint (rail.5V_CH2.state = tripped)" in done.stdout
        assert "note: the channel tripped" in done.stdout
        assert "result: every step fired and was accepted" in done.stdout
    finally:
        p.put(f"lunaris/{R}/input/umbilical", False)
        p.put(keys.input_sun_angle(R), 60)
        p.put(keys.input_radio_position(R, "lander"), {"distance_m": 0, "angle_deg": 0})


def test_a_rejected_step_and_a_timeout_fail_the_run(live, tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("""
scenario: {name: rejected}
rover: mapp-1
time_scale: 10
steps:
  - at_s: 1
    clear: {component: umbilical, kind: disconnect}     # not active: the twin refuses
  - when: battery.soc < 0.01
    timeout_s: 2
    note: never
""")
    done, summary = _run(path, "--connect", live.endpoint)
    assert done.returncode == 1
    assert [(s["status"], s["outcome"]) for s in summary["steps"]] == [
        ("fired", "rejected"), ("timed out", "")]
    assert "no active fault umbilical/disconnect to clear" in summary["steps"][0]["detail"]
    assert "did not hold within 2 s" in summary["steps"][1]["detail"]
    assert "NOT every step played as planned" in done.stdout
    # its progress, published as it played, for the console and any other tool
    progress = live.probe.samples(keys.under(R, "scenario/progress"))
    assert progress and progress[-1]["state"] == "ended" and progress[-1]["ok"] is False
    assert progress[-1]["scenario"] == "rejected" and progress[-1]["actor"] == "scenario"
    assert [(s["status"], s["outcome"]) for s in progress[-1]["steps"]] == [
        ("fired", "rejected"), ("timed out", "")]
    assert any(m["state"] == "playing" for m in progress)


def test_the_shipped_shorted_camera_drill_played_with_a_scripted_crew_is_scored(live, tmp_path):
    """The drill, a crew process acting as the bridge does (writes with actor=crew), a recording:
    the report gives the short's response times and the crew's actions, and both expectations
    met (SPEC 12d)."""
    p, ep = live.probe, live.endpoint
    p.clear_history()
    # the trainee's session (SPEC 12c): what the twin did before is none of this crew's score
    done = run_tool("session", "start", R, "--trainee", "crew 1", "--connect", ep)
    assert done.returncode == 0, done.stdout + done.stderr
    scenario = ROOT / "config" / "scenarios" / "shorted-camera.yaml"
    summary_path, recording = tmp_path / "summary.json", tmp_path / "drill.mcap"
    env = env_without_zenoh_config()
    rec = subprocess.Popen(lunaris_cmd("record", str(recording), "--connect", ep, "--rover", R),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)
    crew = subprocess.Popen([sys.executable, "-m", "tests.lunaris.crew", ep, R, "5V_CH2", "15"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=env)
    proc = None
    try:
        assert rec.stderr.readline().startswith("recording "), "the recorder did not start"
        assert crew.stdout.readline().startswith("crew: watching"), "the crew did not start"
        proc = subprocess.Popen(lunaris_cmd("scenario", "run", str(scenario), "--time-scale", "20",
                                            "--connect", ep, "--json-summary", str(summary_path),
                                            "--clear-at-end"),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                                env=env)
        out, _ = proc.communicate(timeout=60)
    finally:
        for q in (proc, crew, rec):
            if q is not None and q.poll() is None:
                q.send_signal(signal.SIGINT)
                q.wait(20)
    assert proc.returncode == 0, out
    summary = json.loads(summary_path.read_text())
    statuses = {s["label"]: s["status"] for s in summary["steps"]}
    assert set(statuses.values()) == {"fired", "met"}, statuses
    assert "expectations of the crew: 2 of 2 met" in out
    assert p.value(keys.rail_state(R, "5V_CH2"))["state"] == "on"
    wait_for(lambda: not p.value(keys.faults_active(R, "loads"))["faults"], 5, "the camera repaired")

    done = run_tool("report", str(recording), "--json")
    assert done.returncode == 0, done.stderr
    drill = json.loads(done.stdout)[-1]  # the last session: the trainee's, the drill in it
    assert drill["trainee"] == "crew 1"
    (short,) = [f for f in drill["faults"] if f["key"] == keys.fault(R, "load/nav_camera", "short")]
    assert short["injected_by"] == "scenario"
    inj, symptom, acted = short["injected_t_s"], short["first_symptom_t_s"], short["first_crew_action_t_s"]
    # at_s 30, on the first tick after it (2 s ticks at x20), stamped with the last tick the
    # faults service had heard: the scenario's, or the one before it if that one is still on
    # its way to the faults service (CI: 28.1)
    assert 27.9 <= inj <= 40.0
    assert symptom is not None and inj <= symptom <= inj + 4.0  # the trip, within two ticks
    assert acted is not None and symptom <= acted <= symptom + 60.0
    actions = [(a["action"], a["target"], a["accepted"]) for a in short["crew_actions"]]
    assert actions[:2] == [("rail off", "5V_CH2", True), ("rail reset", "5V_CH2", True)], actions
    assert ("rail on", "5V_CH2", True) in actions  # the channel restored, in the fault's window
    assert short["resolved_t_s"] is not None and short["resolved_t_s"] >= acted
    expectations = {e["label"]: e for e in drill["expectations"]}
    safe = expectations["isolate the shorted camera - 5V_CH2 off and its trip reset"]
    back = expectations["restore 5V_CH2 for the hazard cameras"]
    assert safe["met"] and back["met"] and safe["within_s"] == 60 and back["within_s"] == 120
    assert acted <= safe["at_t_s"] <= acted + 10.0 and back["at_t_s"] > safe["at_t_s"]


def test_scenario_check_and_start_errors(live, tmp_path):
    shipped = sorted((ROOT / "config" / "scenarios").glob("*.yaml"))
    done = run_tool("scenario", "check", *[str(f) for f in shipped])
    assert done.returncode == 0, done.stderr
    assert done.stdout.count(": ok - ") == len(shipped) and "names checked against" in done.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("scenario: {name: x}\nrover: mapp-1\nsteps:\n  - {at_s: 1, rail: {name: 9V, on: true}}\n"
                   "  - {when: battery.sock < 1, note: n}\n")
    done = run_tool("scenario", "check", str(bad))
    assert done.returncode == 1
    assert "steps[0].rail.name: rover mapp-1 has no switchable rail '9V'" in done.stderr
    assert "steps[1].when: unknown field 'sock' of battery" in done.stderr
    done = run_tool("scenario", "run", str(bad), "--connect", live.endpoint)
    assert done.returncode == 1 and "2 problem(s)" in done.stderr
    done = run_tool("scenario", "check", str(tmp_path / "missing.yaml"))
    assert done.returncode == 1 and "cannot read file" in done.stderr
    other = tmp_path / "ltv.yaml"
    other.write_text("scenario: {name: x}\nrover: ltv-1\nsteps:\n  - {at_s: 1, sun_angle: 50}\n")
    done = run_tool("scenario", "run", str(other), "--connect", live.endpoint)
    assert done.returncode == 2 and "unknown rover 'ltv-1'" in done.stderr


def test_a_drill_playing_when_the_next_session_begins_stops_and_scores_none_of_it(live, tmp_path):
    """SPEC 13a: a drill belongs to its session. Found by an instructor: the shipped drill went
    on into the next trainee's session and scored it ("isolate the shorted camera ... waiting:
    55 s left"); the next session's report carried the drill's expectation, missed."""
    p, ep = live.probe, live.endpoint
    done = run_tool("session", "start", R, "--trainee", "ana", "--connect", ep)
    assert done.returncode == 0, done.stdout + done.stderr
    scenario = ROOT / "config" / "scenarios" / "shorted-camera.yaml"
    recording = tmp_path / "two.mcap"
    env = env_without_zenoh_config()
    rec = subprocess.Popen(lunaris_cmd("record", str(recording), "--connect", ep, "--rover", R),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)
    proc = None
    try:
        assert rec.stderr.readline().startswith("recording "), "the recorder did not start"
        proc = subprocess.Popen(lunaris_cmd("scenario", "run", str(scenario), "--time-scale", "20",
                                            "--connect", ep),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                                env=env)
        # the drill's short has tripped the camera's rail; nobody acts: its expectation waits
        p.wait_value(keys.rail_state(R, "5V_CH2"), lambda v: v["state"] == "tripped", timeout_s=60)
        done = run_tool("session", "start", R, "--trainee", "ben", "--connect", ep)
        assert done.returncode == 0, done.stdout + done.stderr
        out, _ = proc.communicate(timeout=60)
    finally:
        for q in (proc, rec):
            if q is not None and q.poll() is None:
                q.send_signal(signal.SIGINT)
                q.wait(20)
    stopped = [line for line in out.splitlines() if "a new session began" in line]
    assert stopped, out
    # at the new session's first tick it heard (its clock starts again from 0 at x20: 2 s a tick)
    assert float(stopped[0].split("stopped at sim t ")[1].split(" s")[0]) <= 4.0, stopped[0]

    done = run_tool("report", str(recording), "--json")
    assert done.returncode == 0, done.stderr
    by_trainee = {s["trainee"]: s for s in json.loads(done.stdout)}
    assert by_trainee["ben"]["expectations"] == [], by_trainee["ben"]["expectations"]
    assert not [f for f in by_trainee["ben"]["faults"] if f["injected_by"] == "scenario"]
    assert [f["fault"] for f in by_trainee["ana"]["faults"]] == ["load/nav_camera/short"]
