"""Rover definitions: the shipped rovers load; a broken file lists every problem with its path."""

from __future__ import annotations

import copy
import subprocess

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from common.budget import budget_warnings
from common.config import ConfigError, load_rover, parse_rover
from tests.harness import ROOT, ROVERS, lunaris_cmd

MAPP = (ROVERS / "mapp.yaml").read_text()


def broken(text: str, *edits: tuple[str, str]) -> str:
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


BROKEN_MAPP = broken(
    MAPP,
    ("4.11, 4.20]", "4.11]"),                                       # curve too short
    ("cells_series: 4", "cells_series: four"),                       # wrong type
    ("rail: 5V_CH2,  nominal_w: 3.5", "rail: 5V_CH9,  nominal_w: 3.5"),  # unknown rail
    ("tick_hz: 10", "tick_hz: 10\nbogus: 1"),                        # unknown field
    ("initial_soc: 1.0", "initial_soc: 1.5"),                        # out of range
    ("max_c: 60", "max_c: 80"),                                      # max_c above cutoff_c
    ("{name: right, area_m2: 0.12", "{name: left, area_m2: 0.12"),   # duplicate panel
    ("  capacity_j: 5.3e5\n", ""),                                   # missing field
    ("a_m: 400", "a_m: .nan"),                                       # not finite
)
EXPECTED = [
    "battery.ocv_curve.volts: expected 11 values, got 10",
    "battery.cells_series: expected an integer, got a string",
    "loads[4] (nav_camera).rail: no rail named '5V_CH9'",
    "bogus: unknown field",
    "battery.initial_soc: must be <= 1.0, got 1.5",
    "battery.thermal: expected min_c < max_c < cutoff_c, got -20, 80, 75",
    "solar.panels: name 'left' is used more than once",
    "battery.capacity_j: missing required field",
    "radios[0] (lander).a_m: must be finite, got nan",
]


@pytest.mark.parametrize("name", ["mapp.yaml", "ltv.yaml"])
def test_shipped_rovers_load(name):
    rover = load_rover(ROVERS / name)
    assert rover.battery.capacity_j > 0 and rover.rails and rover.loads


def test_mapp_has_the_channels_the_issue_asks_for():
    rover = load_rover(ROVERS / "mapp.yaml")
    assert [r.name for r in rover.rails] == ["12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2"]
    assert isinstance(rover.battery.capacity_j, float)  # 5.3e5 is a number (YAML 1.2 floats)


def test_every_problem_is_reported_with_its_path():
    with pytest.raises(ConfigError) as info:
        parse_rover(BROKEN_MAPP, "broken.yaml")
    problems = info.value.problems
    for want in EXPECTED:
        assert any(p.startswith(want) for p in problems), (want, problems)
    assert len(problems) == len(EXPECTED), problems


def test_empty_sections_are_allowed():
    text = broken(MAPP, ("radios:\n", "radios: []\n_x:\n"))
    text = text.replace("_x:\n", "").split("radios: []")[0] + "radios: []\n"
    assert parse_rover(text).radios == []


def test_not_yaml_and_not_a_mapping():
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_rover("rover: [", "x.yaml")
    with pytest.raises(ConfigError, match="file: expected a mapping, got a list"):
        parse_rover("- 1\n- 2\n", "x.yaml")


def test_a_yaml_mistake_names_the_file_and_a_key_given_twice_is_one():
    """Found by a vehicle engineer: a syntax error named the file "<unicode string>", a second
    tick_hz below the first was taken without a word, and a typo read as two unrelated
    problems (an unknown field, a missing one)."""
    with pytest.raises(ConfigError) as err:
        parse_rover("rover:\n  id: x\nrails: [1, 2\n", "scout.yaml")
    assert "in scout.yaml, line 3" in str(err.value) and "<unicode string>" not in str(err.value)
    with pytest.raises(ConfigError, match=r"'tick_hz' is given twice in one mapping \(lines 7 and 9\)"):
        parse_rover(MAPP.replace("tick_hz: 10\n", "tick_hz: 10\n\ntick_hz: 0.5\n", 1), "scout.yaml")
    with pytest.raises(ConfigError) as err:
        parse_rover(MAPP.replace("max_discharge_a:", "max_dischage_a:"), "scout.yaml")
    assert "battery.max_dischage_a: unknown field (did you mean 'max_discharge_a'?)" in err.value.problems
    assert "battery.max_discharge_a: missing required field" in err.value.problems


def test_lunaris_check_lists_every_problem_and_exits_non_zero(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text(BROKEN_MAPP)
    run = subprocess.run(lunaris_cmd("check", str(bad)), capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert run.returncode == 1
    for want in EXPECTED:
        assert want in run.stderr, want
    ok = subprocess.run(lunaris_cmd("check", str(ROVERS / "mapp.yaml")), capture_output=True,
                        text=True, cwd=ROOT, timeout=60)
    assert ok.returncode == 0 and "mapp-1" in ok.stdout


def test_a_service_given_a_broken_file_refuses_to_start_with_the_same_message(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text(BROKEN_MAPP)
    run = subprocess.run(lunaris_cmd("run", "battery", "--rover", str(bad), "--connect",
                                     "tcp/127.0.0.1:9"), capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert run.returncode == 2
    for want in EXPECTED:
        assert want in run.stderr, want


def test_check_warns_of_a_rail_its_loads_can_trip(tmp_path):
    # 5V_CH1 carries flight_computer (max 9 W) and uhf_radio (max 8 W): 17 W / 5 V = 3.4 A.
    tight = tmp_path / "tight.yaml"
    tight.write_text(broken(MAPP, ("voltage_v: 5.0,  current_limit_a: 5.0,  efficiency: 0.90, essential",
                                   "voltage_v: 5.0,  current_limit_a: 3.0,  efficiency: 0.90, essential")))
    run = subprocess.run(lunaris_cmd("check", str(tight)), capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert run.returncode == 0  # valid, but ...
    assert "warning: rails.5V_CH1: its loads can draw 3.4 A" in run.stdout
    for shipped in ("mapp.yaml", "ltv.yaml"):  # the shipped rovers are sized right
        assert budget_warnings(load_rover(ROVERS / shipped)) == []


def test_check_warns_of_a_pack_that_cannot_carry_its_loads_or_never_charges():
    """Found by a vehicle engineer: a BMS limit below the parked demand, and a pack no panel
    could charge, both passed check without a word. MAPP parked at night: 3 + 12 W on 12V
    (0.93), 10 W on 5V_CH1 and 6 W on 5V_CH2 (0.90), 1.5 + 6.5 W on the 3.3 V rails (0.88):
    43.0 W on the bus; at half charge 4 x 3.85 V = 15.4 V, so 2.79 A."""
    text = (ROVERS / "mapp.yaml").read_text()
    weak = parse_rover(text.replace("max_discharge_a: 30", "max_discharge_a: 2"), "weak")
    (said,) = budget_warnings(weak)
    assert said.startswith("battery.max_discharge_a: the loads at their nominal power need 43.0 W")
    assert "2.79 A from the pack at half charge (15.4 V), above max_discharge_a 2 A" in said
    assert budget_warnings(parse_rover(text.replace("max_discharge_a: 30", "max_discharge_a: 2.8"),
                                       "enough")) == []
    (said,) = budget_warnings(parse_rover(text.replace("max_charge_w: 150", "max_charge_w: 0"), "x"))
    assert said == "battery.max_charge_w: 0, so neither the panels nor the umbilical ever charge the pack"


def test_the_drive_section_and_radio_sites():
    mapp = load_rover(ROVERS / "mapp.yaml")
    d = mapp.drive
    assert d is not None and d.load == "drive_motors" and d.regen_efficiency == 0.0
    assert (d.start.x_m, d.start.y_m, d.start.heading_deg) == (5.0, 0.0, 90.0)
    assert mapp.radios[0].site is not None and (mapp.radios[0].site.x_m, mapp.radios[0].site.y_m) == (0, 0)
    ltv = load_rover(ROVERS / "ltv.yaml")
    assert ltv.drive is not None and ltv.drive.mass_kg >= 1000 and ltv.drive.regen_efficiency > 0
    # defaults: the Moon's gravity, the site origin, no regeneration, 30 deg
    minimal = broken(MAPP, ("  gravity_m_per_s2: 1.625\n", ""), ("  max_grade_deg: 25 ", "  #"),
                     ("  start: {x_m: 5, y_m: 0, z_m: 0, heading_deg: 90}", ""))
    m = parse_rover(minimal).drive
    assert m is not None and (m.gravity_m_per_s2, m.max_grade_deg, m.start.x_m) == (1.625, 30.0, 0.0)
    bad = broken(MAPP, ("load: drive_motors", "load: wheels"), ("mass_kg: 10.0", "mass_kg: 0"),
                 ("drivetrain_efficiency: 0.05", "drivetrain_efficiency: 1.5"),
                 ("max_grade_deg: 25", "max_grade_deg: 90"), ("site: {x_m: 0, y_m: 0}", "site: {x_m: 0}"))
    with pytest.raises(ConfigError) as info:
        parse_rover(bad, "bad.yaml")
    assert sorted(info.value.problems) == sorted([
        "drive.mass_kg: must be > 0.0, got 0",
        "drive.drivetrain_efficiency: must be <= 1.0, got 1.5",
        "drive.max_grade_deg: must be < 90.0, got 90",
        "radios[0] (lander).site.y_m: missing required field",
    ])  # the load is checked once the section is well formed:
    with pytest.raises(ConfigError) as info:
        parse_rover(broken(MAPP, ("load: drive_motors", "load: wheels")))
    assert info.value.problems == ["drive.load: no load named 'wheels' (loads: drive_motors, "
                                   "survival_heater, flight_computer, uhf_radio, nav_camera, "
                                   "hazard_cameras, imu, sun_sensor, nir_spectrometer, thermal_imager)"]
    with pytest.raises(ConfigError) as info:
        parse_rover(broken(MAPP, ("idle_w: 3.0", "idle_w: 90")))
    assert info.value.problems == ["drive.idle_w: must be below the max_w of load drive_motors (90 W), "
                                   "or the rover could never move; got 90"]


def test_check_describes_the_drive_and_warns_of_one_too_weak_for_its_speed(tmp_path):
    weak = tmp_path / "weak.yaml"  # 20 W at most: 16.25 * 0.2 * 0.1 / 0.05 + 3 = 9.5 W fits,
    weak.write_text(broken(MAPP, ("max_speed_m_per_s: 0.10", "max_speed_m_per_s: 0.5")))  # 35.5 W not
    text = weak.read_text().replace("nominal_w: 40.0, max_w: 90.0", "nominal_w: 20.0, max_w: 20.0")
    weak.write_text(text)
    run = subprocess.run(lunaris_cmd("check", str(weak)), capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "drive - 10 kg, up to 0.5 m/s and 25 deg; drive_motors draws 3 W parked, 35.5 W" in run.stdout
    assert "warning: drive: on the flat at max_speed_m_per_s the drive needs 35.5 W, above the max_w " \
           "20 W of load drive_motors" in run.stdout
    assert "nominal load 39.0 W parked" in run.stdout  # the drive load at its idle_w


# Any value, anywhere: the loader answers with problems, never with a crash.
_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner,
                                                                max_size=3),
    max_leaves=8,
)
_MAPP_DATA = yaml.safe_load(MAPP.replace("5.3e5", "530000.0"))


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


_ALL_PATHS = [p for p in _paths(_MAPP_DATA) if p]


@settings(max_examples=300, deadline=None)
@given(path=st.sampled_from(_ALL_PATHS), value=_values)
def test_any_value_anywhere_gives_problems_not_a_crash(path, value):
    data = copy.deepcopy(_MAPP_DATA)
    node = data
    for chunk in path[:-1]:
        node = node[chunk]
    node[path[-1]] = value
    try:
        parse_rover(yaml.safe_dump(data))
    except ConfigError as exc:
        assert exc.problems and all(isinstance(p, str) for p in exc.problems)


def test_lunaris_check_names_every_problem_of_a_file_in_one_run(tmp_path):
    """Issue 24: a missing field, a bad efficiency, a short curve and a load on an unknown
    rail, all four in one run (the unknown rail used to show only once the others were fixed:
    a rail that was not well formed hid every rail's name)."""
    bad = tmp_path / "four.yaml"
    bad.write_text(broken(
        MAPP,
        ("{name: 12V,     voltage_v: 12.0, current_limit_a: 10.0,", "{name: 12V,     voltage_v: 12.0,"),
        ("current_limit_a: 5.0,  efficiency: 0.90, essential",
         "current_limit_a: 5.0,  efficiency: 1.5, essential"),
        ("4.11, 4.20]", "4.11]"),
        ("rail: 5V_CH2,  nominal_w: 3.5", "rail: 5V_CH9,  nominal_w: 3.5"),
    ))
    run = subprocess.run(lunaris_cmd("check", str(bad)), capture_output=True, text=True,
                         cwd=ROOT, timeout=60)
    assert run.returncode == 1
    assert "4 problem(s)" in run.stderr, run.stderr
    for want in ("rails[0] (12V).current_limit_a: missing required field",
                 "rails[1] (5V_CH1).efficiency: must be <= 1.0, got 1.5",
                 "battery.ocv_curve.volts: expected 11 values, got 10",
                 "loads[4] (nav_camera).rail: no rail named '5V_CH9' "
                 "(rails: 12V, 5V_CH1, 5V_CH2, 3V3_CH1, 3V3_CH2)"):
        assert want in run.stderr, (want, run.stderr)


def test_a_radio_s_load_and_the_umbilical_s_cable():
    mapp = load_rover(ROVERS / "mapp.yaml")
    assert mapp.radios[0].load == "uhf_radio"
    assert (mapp.umbilical.cable_m, mapp.umbilical.follows_rover) == (10.0, False)
    ltv = load_rover(ROVERS / "ltv.yaml")
    assert [r.load for r in ltv.radios] == ["s_band_radio", "s_band_radio"]
    with pytest.raises(ConfigError) as info:
        parse_rover(broken(MAPP, ("load: uhf_radio}", "load: walkie_talkie}"),
                           ("  cable_m: 10 ", "  follows_rover: true\n  #"),
                           ("rail: 5V_CH1,  nominal_w: 4.0,  max_w: 8.0,  std_w: 0.6}",
                            "rail: 5V_CH1,  nominal_w: -4.0,  max_w: 8.0,  std_w: 0.6}")))
    assert sorted(info.value.problems) == sorted([
        "loads[3] (uhf_radio).nominal_w: must be >= 0.0, got -4.0",  # not well formed: its name still counts
        "radios[0] (lander).load: no load named 'walkie_talkie' (loads: drive_motors, survival_heater, "
        "flight_computer, uhf_radio, nav_camera, hazard_cameras, imu, sun_sensor, "
        "nir_spectrometer, thermal_imager)",
        "umbilical.follows_rover: a cable that follows the rover needs its length, cable_m",
    ])
    minimal = broken(MAPP, (", site: {x_m: 0, y_m: 0},\n     load: uhf_radio}", ", site: {x_m: 0, y_m: 0}}"),
                     ("  cable_m: 10 ", "  #"))
    r = parse_rover(minimal)
    assert r.radios[0].load is None and r.umbilical.cable_m is None  # always powered; no slack
