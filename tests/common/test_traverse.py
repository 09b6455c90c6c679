"""Traverse files and plans: every problem named with its path, legs checked against the drive."""

from __future__ import annotations

import math

import pytest

from common.config import load_rover
from common.messages import DriveTraverse, TraverseWaypoint
from common.traverse import TraverseError, length_and_duration, load_traverse, parse_traverse, plan
from tests.harness import ROOT, ROVERS, static_rover

MAPP = load_rover(ROVERS / "mapp.yaml")
LTV = load_rover(ROVERS / "ltv.yaml")
TRAVERSES = sorted((ROOT / "config" / "traverses").glob("*.yaml"))

GOOD = """
traverse: {name: A short loop, description: test}
speed_m_per_s: 0.08
return_to_start: true
waypoints:
  - {x_m: 5, y_m: 30, z_m: 0}
  - {x_m: 45, y_m: 60, z_m: 1, speed_m_per_s: 0.05}
"""


@pytest.mark.parametrize("path", TRAVERSES, ids=[p.name for p in TRAVERSES])
def test_the_shipped_traverses_are_valid_for_their_rover(path):
    rover = MAPP if path.name.startswith("mapp") else LTV
    t = load_traverse(path, rover)
    assert t.traverse.name and len(t.waypoints) >= 4
    assert path.read_text().lstrip().startswith("#")


def test_a_traverse_file_reads_into_the_input_it_sends():
    t = parse_traverse(GOOD, rover=MAPP)
    cmd = t.command()
    assert cmd == DriveTraverse([TraverseWaypoint(5, 30, 0), TraverseWaypoint(45, 60, 1, 0.05)], 0.08, True)
    legs, problems = plan(cmd, MAPP.drive, (5.0, 0.0, 0.0))
    assert problems == []
    # out: (5,0,0) -> (5,30,0) 30 m at 0.08; -> (45,60,1) sqrt(40^2 + 30^2 + 1) = 50.00999 m at 0.05
    # back over the same legs at the same speeds: -> (5,30,0) at 0.05, -> (5,0,0) at 0.08
    assert [(leg.x_m, leg.y_m, leg.z_m, leg.speed_m_per_s, leg.waypoint) for leg in legs] == [
        (5, 30, 0, 0.08, 0), (45, 60, 1, 0.05, 1), (5, 30, 0, 0.05, 2), (5, 0, 0, 0.08, 3)]
    length, duration = length_and_duration((5.0, 0.0, 0.0), legs)
    d = math.sqrt(40 ** 2 + 30 ** 2 + 1)
    assert length == pytest.approx(2 * (30 + d))
    assert duration == pytest.approx(2 * (30 / 0.08 + d / 0.05))
    # without a speed, the rover's maximum
    no_speed = DriveTraverse([TraverseWaypoint(5, 30, 0)])
    assert plan(no_speed, MAPP.drive, (5.0, 0.0, 0.0))[0][0].speed_m_per_s == 0.1


def test_a_bad_traverse_file_reports_every_problem_with_its_path():
    bad = """
traverse: {name: bad, colour: red}
speed_m_per_s: -1
waypoints:
  - {x_m: .nan, y_m: 0, z_m: 0}
  - {x_m: 1, y_m: 2}
  - {x_m: 1, y_m: 2, z_m: 3, speed_m_per_s: 500}
  - {x_m: 1, y_m: 2, z_m: 3, heading: 4}
return_to_start: maybe
"""
    with pytest.raises(TraverseError) as err:
        parse_traverse(bad, "bad.yaml")
    assert err.value.problems == [
        "traverse.colour: unknown field",
        "waypoints[0].x_m: must be finite, got nan",
        "waypoints[1].z_m: missing required field",
        "waypoints[2].speed_m_per_s: must be <= 100.0, got 500",
        "waypoints[3].heading: unknown field",
        "speed_m_per_s: must be > 0.0, got -1",
        "return_to_start: expected true or false, got a string",
    ]
    assert str(err.value).startswith("bad.yaml: 7 problem(s)")
    with pytest.raises(TraverseError, match="cannot read file"):
        load_traverse(ROOT / "no-such-traverse.yaml")
    with pytest.raises(TraverseError, match="not valid YAML"):
        parse_traverse("waypoints: [", "x")


def test_a_traverse_is_checked_against_the_rover_that_drives_it():
    too_fast_and_steep = GOOD.replace("speed_m_per_s: 0.08", "speed_m_per_s: 0.2").replace(
        "{x_m: 45, y_m: 60, z_m: 1, speed_m_per_s: 0.05}", "{x_m: 5, y_m: 40, z_m: 6, speed_m_per_s: 1}")
    with pytest.raises(TraverseError) as err:
        parse_traverse(too_fast_and_steep, rover=MAPP)
    assert err.value.problems == [
        "speed_m_per_s: 0.2 m/s is above the rover's max_speed_m_per_s (0.1)",
        "waypoints[1].speed_m_per_s: 1 m/s is above the rover's max_speed_m_per_s (0.1)",
        "waypoints[1]: the leg from waypoints[0] climbs 31.0 deg (6 m over 10 m), steeper than the "
        "rover's max_grade_deg (25)",
    ]
    with pytest.raises(TraverseError, match="rover mapp-1 has no drive section"):
        parse_traverse(GOOD, rover=load_rover(static_rover("mapp.yaml")))
    # the first leg starts where the rover is: from the start (5, 0, 0), a cliff
    cliff = DriveTraverse([TraverseWaypoint(5, 0, 2)])
    assert plan(cliff, MAPP.drive, (5.0, 0.0, 0.0))[1] == [
        "waypoints[0]: the leg from the rover's position climbs 90.0 deg (2 m over 0 m), steeper "
        "than the rover's max_grade_deg (25)"]
    down = DriveTraverse([TraverseWaypoint(5, 10, -5)])
    assert "descends 26.6 deg" in plan(down, MAPP.drive, (5.0, 0.0, 0.0))[1][0]
    assert plan(DriveTraverse([]), MAPP.drive, (0.0, 0.0, 0.0)) == (
        [], ["waypoints: a traverse needs at least one waypoint"])
