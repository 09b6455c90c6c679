"""Scenarios without a twin: the format's validation, the condition grammar, the player's timing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from common.conditions import parse_condition
from common.config import load_rover
from common.scenario import ScenarioError, load_scenario, parse_scenario
from common.scenario_player import Player
from tests.harness import ROOT, ROVERS, static_rover

MAPP = load_rover(ROVERS / "mapp.yaml")
LTV = load_rover(ROVERS / "ltv.yaml")
STATIC_MAPP = load_rover(static_rover("mapp.yaml"))  # no drive
SCENARIOS = sorted((ROOT / "config" / "scenarios").glob("*.yaml"))


# -- conditions -------------------------------------------------------------------------------


@pytest.mark.parametrize("text, parts, field, op, value", [
    ("battery.soc < 0.4", ("battery", "state"), "soc", "<", 0.4),
    ("battery.operational == false", ("battery", "state"), "operational", "==", False),
    ("rail.5V_CH2.state == tripped", ("rail", "5V_CH2", "state"), "state", "==", "tripped"),
    ("rail.3V3_CH1.current_a>=2.5", ("rail", "3V3_CH1", "current_a"), "current_a", ">=", 2.5),
    ("radio.lander.in_range != true", ("radio", "lander", "link"), "in_range", "!=", True),
    ("summary.generation_w <= -1e1", ("power", "summary"), "generation_w", "<=", -10.0),
    ("load.nav.camera.v2.power_w > 3", ("load", "nav.camera.v2", "power"), "power_w", ">", 3.0),
    ("solar.left.dust > 0.5", ("solar", "left", "power"), "dust", ">", 0.5),
    ("clock.t_s >= 120", ("clock",), "t_s", ">=", 120.0),
    ("umbilical.connected == true", ("umbilical", "state"), "connected", "==", True),
])
def test_a_condition_names_a_key_a_field_and_a_typed_value(text, parts, field, op, value):
    (c,) = parse_condition(text).comparisons
    if parts[-1] == "current_a":  # rail fields live on rail/<name>/state
        parts = ("rail", "3V3_CH1", "state")
    assert (c.key_parts, c.field, c.op, c.value) == (parts, field, op, value)


@pytest.mark.parametrize("text, message", [
    ("", "empty condition"),
    ("battery.soc", "cannot read"),
    ("battery.soc << 3", "cannot read"),
    ("engine.rpm > 3", "unknown source 'engine'"),
    ("battery.charge < 0.4", "unknown field 'charge' of battery"),
    ("rail.state == on", "rail needs a name and a field"),
    ("battery.x.soc < 1", "battery has no names"),
    ("battery.soc < low", "battery.soc is a number"),
    ("battery.soc < nan", "not a finite number"),
    ("battery.operational == 1", "is true or false"),
    ("battery.operational < true", "only be compared with == or !="),
    ("rail.12V.state == melted", "is one of failed, off, on, shed, tripped"),
    ("rail.12V.state > on", "only be compared with == or !="),
    ("battery.faults == none", "cannot be compared"),
    ("__import__('os').system('true') == 1", "cannot read"),
    ("battery.soc < 1; import os", "cannot read"),
    ("battery.soc < 1 or battery.soc > 2", "cannot read"),
])
def test_anything_outside_the_grammar_is_refused_with_a_reason(text, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        parse_condition(text)


def _lookup(values: dict):
    return lambda parts: values.get(parts)


def test_a_condition_holds_only_when_every_comparison_does_on_present_data():
    cond = parse_condition("battery.soc < 0.4 and rail.5V_CH2.state == tripped")
    values = {("battery", "state"): {"soc": 0.35}, ("rail", "5V_CH2", "state"): {"state": "on"}}
    assert not cond.holds(_lookup(values))
    values[("rail", "5V_CH2", "state")]["state"] = "tripped"
    assert cond.holds(_lookup(values))
    assert cond.describe(_lookup(values)) == "battery.soc = 0.35, rail.5V_CH2.state = tripped"
    assert not cond.holds(_lookup({}))  # no telemetry yet
    assert not parse_condition("battery.time_to_empty_s < 60").holds(
        _lookup({("battery", "state"): {"time_to_empty_s": None}}))  # null while charging
    assert not parse_condition("battery.operational == false").holds(
        _lookup({("battery", "state"): {"operational": 0}}))  # a number is not a boolean


# -- the format -------------------------------------------------------------------------------


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
def test_the_shipped_scenarios_are_valid_for_their_rover(path: Path):
    rover = {r.id: r for r in (MAPP, LTV)}[load_scenario(path).rover]
    sc = load_scenario(path, rover)
    assert len(sc.steps) >= 5
    assert path.read_text().lstrip().startswith("#")  # commented for the training team


def test_four_scenarios_are_shipped_one_of_them_a_drive_drill():
    assert len(SCENARIOS) >= 4
    sortie = load_scenario(ROOT / "config" / "scenarios" / "crater-rim-sortie.yaml", LTV)
    traverses = [s.traverse for s in sortie.steps if s.traverse is not None]
    assert len(traverses[0]["waypoints"]) == 6  # the traverse file's, read at load time
    assert any(s.when and s.when.startswith("drive.") for s in sortie.steps)


BAD = """
scenario: {name: broken, colour: red}
rover: mapp-1
time_scale: -2
steps:
  - at_s: 10
    after_s: 5
    inject: {component: load/nav_cam, kind: short}
  - inject: {component: battery, kind: heating, value: -4}
  - at_s: 1
    when: battery.charge < 3
    timeout_s: 0
  - at_s: 2
    sun_angle: {from: 10, to: 500}
    umbilical: true
  - at_s: 3
    position: {radio: tower, distance_m: -1}
  - at_s: 4
    rail: {name: SOLAR}
  - at_s: 5
    timeout_s: 10
    clear: {component: wheel, kind: flat}
  - at_s: 6
    clock: {}
  - "not a step"
"""


def test_a_bad_scenario_reports_every_problem_with_its_path():
    with pytest.raises(ScenarioError) as err:
        parse_scenario(BAD, "bad.yaml", MAPP)
    problems = err.value.problems
    expected = [
        "scenario.colour: unknown field",
        "time_scale: must be > 0.0, got -2",
        "steps[0]: give at_s or after_s, not both",
        "steps[0].inject.component: rover mapp-1 has no load 'nav_cam'",
        "steps[1]: give a trigger: at_s, after_s or when",
        "steps[1].inject.value: heat_w must be at least 0",
        "steps[2].timeout_s: must be > 0.0, got 0",
        "steps[2]: give an action",
        "steps[2].when: unknown field 'charge' of battery",
        "steps[3]: give one action per step, got sun_angle, umbilical",
        "steps[3].sun_angle.over_s: missing required field",
        "steps[3].sun_angle.to: must be within -360..360, got 500",
        "steps[4].position.distance_m: must be within 0..1e+09, got -1",
        "steps[4].position.radio: rover mapp-1 has no radio 'tower'",
        "steps[5].rail: give on: true|false or reset: true",
        "steps[5].rail.name: rover mapp-1 has no switchable rail 'SOLAR'",
        "steps[6].timeout_s: only a step with a when condition can time out",
        "steps[6].clear: unknown component 'wheel'",
        "steps[7].clock: give time_scale (> 0) or paused (true or false)",
        "steps[8]: expected a mapping, got a string",
    ]
    for want in expected:
        assert any(p.startswith(want) for p in problems), f"{want!r} not in {problems}"
    assert str(err.value).startswith("bad.yaml: ")


def test_on_and_off_are_keys_and_words_not_booleans():
    text = ("scenario: {name: x}\nrover: mapp-1\nsteps:\n"
            "  - {at_s: 1, rail: {name: 12V, on: false}}\n  - {at_s: 2, rail: {name: 12V, reset: yes}}\n")
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text)
    assert err.value.problems == ["steps[1].rail.reset: expected true or false, got a string"]
    sc = parse_scenario(text.replace("yes", "true"))
    assert sc.steps[0].rail.on is False and sc.steps[1].rail.reset is True


def test_names_are_only_checked_when_a_rover_is_given():
    text = ("scenario: {name: x}\nrover: mapp-1\nsteps:\n"
            "  - {at_s: 1, inject: {component: load/x, kind: open}}\n")
    assert parse_scenario(text).steps[0].inject.component == "load/x"
    with pytest.raises(ScenarioError, match="has no load 'x'"):
        parse_scenario(text, rover=MAPP)
    with pytest.raises(ScenarioError, match="the scenario is for 'ltv-1'"):
        parse_scenario(text.replace("mapp-1", "ltv-1"), rover=MAPP)
    with pytest.raises(ScenarioError, match="not valid YAML"):
        parse_scenario("steps: [", "x")
    with pytest.raises(ScenarioError, match="cannot read file"):
        load_scenario("/nonexistent/scenario.yaml")


# -- the player -------------------------------------------------------------------------------

PLAY = """
scenario: {name: timing}
rover: mapp-1
steps:
  - at_s: 2
    inject: {component: solar/left, kind: dust, value: 0.5}
  - after_s: 1.5
    sun_angle: {from: 60, to: 80, over_s: 4}
  - after_s: 0
    when: battery.soc < 0.5
    timeout_s: 3
    rail: {name: 5V_CH2, on: false}
  - when: radio.lander.in_range == false
    clear: {component: solar/left, kind: dust}
  - after_s: 1
    note: a checkpoint
"""


def _play(text: str, ticks, values: dict):
    player = Player(parse_scenario(text))
    out = []
    for t in ticks:
        for w in player.tick(t, _lookup(values)):
            out.append((t, w))
        if callable(values.get("at")):
            values["at"](t, values)
    return player, out


def test_steps_fire_at_their_time_after_their_predecessor_or_on_their_condition():
    values: dict = {("battery", "state"): {"soc": 0.9}, ("radio", "lander", "link"): {"in_range": True}}

    def world(t, v):  # the condition of step 3 comes true at t0 + 6 s, step 4's at + 9 s
        if t >= 106:
            v[("battery", "state")] = {"soc": 0.45}
        if t >= 109:
            v[("radio", "lander", "link")] = {"in_range": False}
    values["at"] = world
    player, writes = _play(PLAY, [100 + 0.5 * i for i in range(30)], values)
    fired = [r.fired_t_s for r in player.results]
    assert fired == [2.0, 3.5, 6.5, 9.5, 10.5]
    assert [r.status for r in player.results] == ["fired", "done", "fired", "fired", "fired"]
    assert player.results[4].outcome == "reached"
    assert player.finished and player.end_reason == "every step has played"

    by_step = {}
    for t, w in writes:
        by_step.setdefault(w.step, []).append((t - 100, w))
    (_, inj), = by_step[0]
    assert (inj.key, inj.payload, inj.accepted) == ("lunaris/mapp-1/fault/solar/left/dust", b"0.5",
                                                  "fault_injected")
    ramp = by_step[1]
    angles = [json.loads(w.payload)["angle_deg"] for _, w in ramp]
    assert [t for t, _ in ramp][0] == 3.5 and angles[0] == 60.0 and angles[-1] == 80.0
    assert angles == sorted(angles) and abs(angles[4] - 70.0) < 1e-9  # 2 s into a 4 s ramp
    assert [w.final for _, w in ramp] == [False] * (len(ramp) - 1) + [True]
    (_, rail), = by_step[2]
    assert (rail.key, json.loads(rail.payload)) == ("lunaris/mapp-1/cmd/rail/5V_CH2", {"on": False})
    (_, clr), = by_step[3]
    assert clr.payload is None and clr.accepted == "fault_cleared"  # a clear is a delete
    assert 4 not in by_step  # a checkpoint writes nothing


def test_a_condition_that_never_holds_times_out_and_its_followers_do_not_fire():
    values = {("battery", "state"): {"soc": 0.9}, ("radio", "lander", "link"): {"in_range": False}}
    player, _ = _play(PLAY, [float(t) for t in range(30)], values)
    statuses = [r.status for r in player.results]
    assert statuses == ["fired", "done", "timed out", "fired", "fired"]
    assert player.results[2].fired_t_s is None and "did not hold within 3 s" in player.results[2].detail
    assert player.results[2].armed_t_s == 4.0  # step 2 fired at the tick of 4 s


def test_duration_ends_a_scenario_and_reports_what_did_not_fire():
    text = PLAY + "duration_s: 4\n"
    values = {("battery", "state"): {"soc": 0.9}}
    player, _ = _play(text, [float(t) for t in range(10)], values)
    assert player.finished and player.end_reason == "duration of 4 s reached"
    assert [r.status for r in player.results] == ["fired", "fired", "not fired", "not fired", "not fired"]
    assert "ramp cut short" in player.results[1].detail


def test_a_position_ramp_moves_distance_and_angle_together():
    text = """
scenario: {name: ramp}
rover: mapp-1
steps:
  - at_s: 0
    position: {radio: lander, distance_m: {from: 100, to: 600, over_s: 10}, angle_deg: 30}
"""
    _, writes = _play(text, [float(t) for t in range(12)], {})
    bodies = [json.loads(w.payload) for _, w in writes]
    assert {w.key for _, w in writes} == {"lunaris/mapp-1/input/radio/lander/position"}
    assert [b["distance_m"] for b in bodies] == [100 + 50 * i for i in range(11)]
    assert {b["angle_deg"] for b in bodies} == {30.0}


# -- the drive: traverse steps and drive conditions -----------------------------------------------

DRIVE = """
scenario: {name: drive}
rover: mapp-1
steps:
  - at_s: 1
    traverse: {speed_m_per_s: 0.1, waypoints: [{x_m: 5, y_m: 50, z_m: 0}], return_to_start: true}
  - when: drive.odometer_m > 20 and drive.status == driving
    traverse: stop
  - after_s: 0
    traverse: {file: TRAVERSE}
"""


def test_a_traverse_step_writes_the_traverse_and_stop_deletes_it(tmp_path):
    text = DRIVE.replace("TRAVERSE", str(ROOT / "config" / "traverses" / "mapp-crater-rim.yaml"))
    sc = parse_scenario(text, rover=MAPP)
    odometer = {"odometer_m": 0.0, "status": "driving"}
    values = {("drive", "state"): odometer}
    player = Player(sc)
    assert player.tick(0.0, lambda parts: values.get(parts)) == []  # the start
    first = player.tick(1.0, lambda parts: values.get(parts))
    (w,) = first
    assert w.key == "lunaris/mapp-1/input/drive/traverse" and w.accepted == "input"
    assert json.loads(w.payload) == {"speed_m_per_s": 0.1, "waypoints": [{"x_m": 5, "y_m": 50, "z_m": 0}],
                                     "return_to_start": True}
    assert player.tick(2.0, lambda parts: values.get(parts)) == []
    odometer["odometer_m"] = 25.0
    stop, from_file = player.tick(3.0, lambda parts: values.get(parts))
    assert stop.payload is None and stop.key == w.key
    body = json.loads(from_file.payload)
    assert len(body["waypoints"]) == 4 and body["return_to_start"] is True
    assert [r.label for r in player.results] == [
        "traverse through 1 waypoint(s) at 0.1 m/s, and back", "traverse stop",
        "traverse through 4 waypoint(s) at 0.1 m/s, and back"]


def test_traverse_steps_and_drive_conditions_are_checked_against_the_rover(tmp_path):
    bad = """
scenario: {name: drive}
rover: mapp-1
steps:
  - at_s: 1
    traverse: {speed_m_per_s: 0.5, waypoints: [{x_m: 5, y_m: 50, z_m: 0}, {x_m: 5, y_m: 51, z_m: 9}]}
  - at_s: 2
    traverse: {waypoints: [{x_m: 1, y_m: 2}]}
  - at_s: 3
    traverse: backwards
  - at_s: 4
    traverse: {file: nowhere.yaml}
  - at_s: 5
    traverse: {file: x.yaml, speed_m_per_s: 1}
  - when: drive.odometer_m > 20
    note: far
  - at_s: 6
    position: {radio: lander, distance_m: 10}
"""
    with pytest.raises(ScenarioError) as err:
        parse_scenario(bad, str(tmp_path / "bad.yaml"), MAPP)
    problems = err.value.problems
    for want in [
        "steps[0].traverse.speed_m_per_s: 0.5 m/s is above the rover's max_speed_m_per_s (0.1)",
        "steps[0].traverse.waypoints[1]: the leg from waypoints[0] climbs 83.7 deg",
        "steps[1].traverse.waypoints[0].z_m: missing required field",
        "steps[2].traverse: expected stop or a traverse",
        "steps[3].traverse.file: ",
        "steps[4].traverse: a traverse from a file is {file: PATH} alone",
        "steps[6].position.radio: radio lander of mapp-1 follows the rover's drive",
    ]:
        assert any(p.startswith(want) for p in problems), f"{want!r} not in {problems}"
    assert any("cannot read file" in p for p in problems)
    assert len(problems) == 7, problems
    # a rover that does not drive can neither take a traverse nor be watched driving
    with pytest.raises(ScenarioError) as err:
        parse_scenario(DRIVE.replace("TRAVERSE", "x.yaml"), rover=STATIC_MAPP)
    assert "steps[0].traverse: rover mapp-1 has no drive section: it does not drive" in err.value.problems
    assert "steps[1].when: rover mapp-1 has no drive section: it does not drive" in err.value.problems
    # ... and its radios take the position input
    ok = ("scenario: {name: x}\nrover: mapp-1\nsteps:\n"
          "  - {at_s: 1, position: {radio: lander, distance_m: 9}}\n")
    assert parse_scenario(ok, rover=STATIC_MAPP).steps[0].position.distance_m == 9


# -- expectations of the crew (SPEC 12d) ----------------------------------------------------------

EXPECT = """
scenario: {name: expectations}
rover: mapp-1
steps:
  - name: short
    at_s: 2
    inject: {component: load/nav_camera, kind: short}
  - expect: {when: "rail.5V_CH2.state == off", within_s: 10, label: isolate the shorted camera}
  - name: clear it
    after_s: 1
    clear: {component: load/nav_camera, kind: short}
  - at_s: 8
    expect: {when: "rail.5V_CH2.state == on", within_s: 5}
  - name: already done
    at_s: 1
    expect: {when: "battery.soc > 0.5", within_s: 1}
"""


def test_an_expect_step_is_validated_as_the_rest_of_the_format():
    sc = parse_scenario(EXPECT, rover=MAPP)
    assert sc.steps[1].expect.within_s == 10 and sc.steps[1].label == "isolate the shorted camera"
    assert sc.steps[3].label == "expect rail.5V_CH2.state == on"  # no label, no name: the condition
    assert sc.steps[4].label == "already done"
    bad = """
scenario: {name: x}
rover: mapp-1
steps:
  - at_s: 1
    expect: {when: "rail.5V_CH9.state == off", within_s: 0, colour: red}
  - at_s: 1
    when: battery.soc < 0.5
    timeout_s: 3
    expect: {when: "battery.charge < 1", within_s: 5}
  - expect: {within_s: 5}
  - at_s: 1
    rail: {name: 12V, on: false}
    expect: {when: "battery.soc < 1", within_s: 5}
"""
    with pytest.raises(ScenarioError) as err:
        parse_scenario(bad, "bad.yaml", MAPP)
    for want in ["steps[0].expect.within_s: must be > 0.0, got 0",
                 "steps[0].expect.colour: unknown field",
                 "steps[0].expect.when: rover mapp-1 has no rail '5V_CH9'",
                 "steps[1].when: an expect step's condition is expect.when",
                 "steps[1].timeout_s: an expect step's condition is expect.when",
                 "steps[1].expect.when: unknown field 'charge' of battery",
                 "steps[2].expect.when: missing required field",
                 "steps[3]: give one action per step, got rail, expect"]:
        assert any(p.startswith(want) for p in err.value.problems), f"{want!r} not in {err.value.problems}"


def test_expectations_are_met_when_their_condition_holds_and_missed_when_their_time_is_up():
    values: dict = {("battery", "state"): {"soc": 0.9}, ("rail", "5V_CH2", "state"): {"state": "on"}}

    def world(t, v):  # the crew switches the rail off at 7 s, and never back on
        if t >= 107:
            v[("rail", "5V_CH2", "state")] = {"state": "off"}
    values["at"] = world
    player, writes = _play(EXPECT, [100 + 0.5 * i for i in range(40)], values)
    r = player.results
    assert [x.status for x in r] == ["fired", "met", "fired", "missed", "met"]
    assert [x.met for x in r] == [None, True, None, False, True]
    # armed when the short fired (2 s), met on the first tick the rail read off (7.5 s)
    assert (r[1].armed_t_s, r[1].met_t_s, r[1].deadline_t_s) == (2.0, 7.5, 12.0)
    assert "rail.5V_CH2.state = off" in r[1].detail
    # the step after it counts from when the expectation was armed, and does not wait for it
    assert r[2].fired_t_s == 3.0
    # armed at 8 s with the rail off: the crew never puts it back on within 5 s
    assert r[3].armed_t_s == 8.0 and r[3].deadline_t_s == 13.0 and "did not hold within 5 s" in r[3].detail
    assert (r[4].armed_t_s, r[4].met_t_s) == (1.0, 1.0)  # held already when armed
    assert [w.step for _, w in writes] == [0, 2]  # expectations write nothing
    assert player.finished and player.end_reason == "every step has played"


def test_the_end_of_a_scenario_scores_what_is_pending_as_missed():
    values = {("battery", "state"): {"soc": 0.1}, ("rail", "5V_CH2", "state"): {"state": "on"}}
    player, _ = _play(EXPECT + "duration_s: 3\n", [float(t) for t in range(6)], values)
    r = player.results
    assert player.end_reason == "duration of 3 s reached"
    assert (r[1].status, r[1].met) == ("missed", False) and "not met when the scenario ended" in r[1].detail
    assert (r[3].status, r[3].met) == ("not fired", False) and "never armed" in r[3].detail
    assert (r[4].status, r[4].met) == ("missed", False)  # soc 0.1: armed at 1 s, out of time at 2 s
    assert "did not hold within 1 s" in r[4].detail


def test_while_an_expectation_is_pending_the_player_says_so():
    values = {("battery", "state"): {"soc": 0.9}, ("rail", "5V_CH2", "state"): {"state": "on"}}
    player = Player(parse_scenario(EXPECT))
    for t in (0.0, 1.0, 2.0, 2.5):
        player.tick(t, _lookup(values))
    said = player.waiting(_lookup(values))
    assert "waiting for step 3 'clear it'" in said
    assert "expecting 'isolate the shorted camera' for 10 s more" in said


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
def test_each_shipped_drill_expects_what_a_crew_can_do_from_its_dashboard(path: Path):
    """Every drill scores the crew: at least one expectation, on what the crew's own controls
    change (SPEC 12a: a rail on, off or reset; the drive stopped) or on what follows from them."""
    rover = {r.id: r for r in (MAPP, LTV)}[load_scenario(path).rover]
    sc = load_scenario(path, rover)
    expects = [s.expect for s in sc.steps if s.expect is not None]
    assert expects, f"{path.name} has no expectation"
    crew_sources = ("rail.", "drive.", "load.")
    for e in expects:
        assert any(c.ref.startswith(crew_sources) for c in parse_condition(e.when).comparisons), e.when
        assert e.label
