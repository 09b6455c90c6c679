"""The models composed in one process, on a deterministic clock."""

from __future__ import annotations

import csv
import subprocess

import msgspec
import pytest
from numpy.testing import assert_allclose

from common.config import Rover, load_rover
from common.faults import Short
from common.messages import DriveTraverse, TraverseWaypoint
from common.traverse import plan
from services.composed import ComposedTwin, run_budget
from services.composed.budget import power_profile, run_traverse
from services.drive.model import umbilical_holds
from tests.harness import ROOT, ROVERS, lunaris_cmd, static_rover


@pytest.fixture
def mapp() -> Rover:
    """The MAPP rover without its drive: the budget of the first release (drive_motors ~40 W)."""
    return load_rover(static_rover("mapp.yaml"))


def small_pack(rover: Rover, capacity_j: float) -> Rover:
    raw = msgspec.to_builtins(rover)
    raw["battery"]["capacity_j"] = capacity_j
    return msgspec.convert(raw, Rover)


def test_runs_are_deterministic_for_a_seed(mapp):
    a, b = run_budget(mapp, 0.05, seed=7), run_budget(mapp, 0.05, seed=7)
    assert a == b
    assert run_budget(mapp, 0.05, seed=8).energy_used_j != a.energy_used_j


def test_energy_drawn_matches_the_net_demand_over_a_run(mapp):
    twin = ComposedTwin(mapp, seed=1)
    e0 = twin.battery.energy_j
    chemical = 0.0
    for _ in range(3000):
        b = twin.battery
        point = b.operating_point()
        chemical += b.ocv_v * point.current_a * twin.dt_s  # what the next step takes out
        twin.step()
    assert_allclose(e0 - twin.battery.energy_j, chemical, rtol=1e-9)
    assert twin.t_s == pytest.approx(300.0)


def test_a_long_run_sheds_in_order_then_depletes(mapp):
    # ~60 W net on 20 kJ: about 5.5 min. 3V3_CH2 sheds at 0.25, 5V_CH2 at 0.15, then empty.
    budget = run_budget(small_pack(mapp, 2e4), 0.2, seed=3)
    assert list(budget.shed_at_s) == ["3V3_CH2", "5V_CH2"]
    assert budget.shed_at_s["3V3_CH2"] < budget.shed_at_s["5V_CH2"] < budget.depleted_at_s
    assert budget.final_soc < 0.05 + 1e-9  # held near empty: rails cycle around recovery


def test_a_demand_the_pack_cannot_give_is_counted_not_averaged_away(mapp):
    """Found by a vehicle engineer: a BMS limit below the loads' draw ran 'never depleted' with
    nothing said of the demand never met. The static MAPP draws ~76 W of loads, ~83 W on the
    bus; without the sun, at a 2 A limit on a ~16.5 V pack (~33 W) every tick is ~50 W short:
    ~2.5 Wh in 3 min. With the shipped 30 A, none."""
    raw = msgspec.to_builtins(mapp)
    raw["battery"]["max_discharge_a"] = 2.0
    raw["solar"]["sun_angle_deg"] = 90.0
    budget = run_budget(msgspec.convert(raw, Rover), 0.05, seed=3)
    assert budget.short_s == pytest.approx(180.0)  # the whole 0.05 h
    assert 2.2 < budget.unmet_j / 3600 < 2.8
    assert run_budget(mapp, 0.05, seed=3).short_s == 0.0


def test_a_short_trips_the_rail_and_darkens_its_loads(mapp):
    twin = ComposedTwin(mapp, seed=1)
    twin.set_faults("load", "nav_camera", [Short(resistance_ohm=0.05)])
    assert twin.power.switches["5V_CH2"].tripped  # at once, as the services do
    twin.step()
    assert twin.power.switches["5V_CH2"].tripped
    assert twin.loads.power("hazard_cameras") == (0.0, False)
    assert twin.battery.demand_w < 100  # the short never reached the battery


def test_a_run_s_series_is_sampled_on_its_grid_and_at_its_end(mapp):
    """Every 100 s of a 720 s run, and at its end: the sheds of the run above, where the
    budget says they happen (3V3_CH2 below 25 % at 389.6 s, 5V_CH2 below 15 % at 454.1 s)."""
    seen: list[tuple[float, float, list[str]]] = []
    budget = run_budget(small_pack(mapp, 2e4), 0.2, seed=3, sample=lambda t: seen.append(
        (t.t_s, t.battery.soc, sorted(n for n, sw in t.power.switches.items() if sw.shed))),
        sample_every_s=100)
    assert [round(t, 6) for t, _, _ in seen] == [100, 200, 300, 400, 500, 600, 700, 720]
    assert seen[-1][1] == budget.final_soc
    assert [shed for _, _, shed in seen[2:5]] == [[], ["3V3_CH2"], ["3V3_CH2", "5V_CH2"]]
    assert 300 < budget.shed_at_s["3V3_CH2"] < 400 < budget.shed_at_s["5V_CH2"] < 500


def test_lunaris_sim_writes_a_series_for_a_spreadsheet(tmp_path):
    rover = tmp_path / "mapp.yaml"
    rover.write_text(static_rover("mapp.yaml").read_text().replace(
        "{name: 3V3_CH2,", "{name: 3V3_CH2, initially_on: false,"))
    assert "initially_on: false" in rover.read_text()
    out = tmp_path / "run.csv"
    run = subprocess.run(lunaris_cmd("sim", str(rover), "--hours", "0.5", "--csv", str(out),
                                     "--every", "600"), capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert run.returncode == 0, run.stderr
    assert f"series            3 rows, one every 600 s, in {out}" in run.stdout  # the end on the grid
    rows = list(csv.DictReader(out.open()))
    assert [float(r["t_s"]) for r in rows] == [600.0, 1200.0, 1800.0]
    assert {r["rails_not_on"] for r in rows} == {"3V3_CH2:off"}
    assert all(float(r["energy_j"]) == pytest.approx(float(r["soc"]) * 5.3e5, abs=1) for r in rows)
    final = float(run.stdout.split("state of charge")[1].split()[0])
    assert float(rows[-1]["soc"]) == pytest.approx(final, abs=5e-5)
    bad = subprocess.run(lunaris_cmd("sim", str(rover), "--csv", str(out), "--every", "0"),
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert bad.returncode == 2 and "--every must be > 0" in bad.stderr


def test_lunaris_sim_prints_a_budget():
    run = subprocess.run(lunaris_cmd("sim", str(ROVERS / "mapp.yaml"), "--hours", "0.1"),
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "3600 ticks" in run.stdout and "state of charge" in run.stdout


# -- the drive ----------------------------------------------------------------------------------
# mapp.yaml's drive: 16.25 N of weight, c_rr 0.2, eta 0.05, idle 3 W; on the flat at 0.1 m/s
# F = 3.25 N and the drive load draws 3.25 * 0.1 / 0.05 + 3 = 9.5 W.


@pytest.fixture
def driving() -> Rover:
    return load_rover(ROVERS / "mapp.yaml")


def north(metres: float, rover: Rover) -> DriveTraverse:
    assert rover.drive is not None
    s = rover.drive.start
    return DriveTraverse([TraverseWaypoint(s.x_m, s.y_m + metres, s.z_m)], 0.1)


def test_the_drive_moves_and_sets_its_load_in_the_composed_twin(driving):
    twin = ComposedTwin(driving, seed=1)
    assert twin.drive is not None and twin.loads.power("drive_motors") == (3.0, True)  # parked
    twin.drive.start(plan(north(100.0, driving), driving.drive, (5.0, 0.0, 0.0))[0])
    for _ in range(10):
        twin.step()
    assert twin.drive.y_m == pytest.approx(0.1)  # 10 ticks of 0.1 s at 0.1 m/s
    assert twin.loads.power("drive_motors") == (pytest.approx(9.5), True)
    # a short on the 12 V rail's heater trips it: the drive loses its power and halts
    twin.set_faults("load", "survival_heater", [Short(resistance_ohm=0.05)])
    twin.step()
    assert twin.power.switches["12V"].tripped
    y = twin.drive.y_m
    for _ in range(10):
        twin.step()
    assert twin.drive.status == "unpowered" and twin.drive.y_m == y
    assert twin.loads.power("drive_motors") == (0.0, False)


def test_run_traverse_drives_to_the_end_and_books_the_energy(driving):
    # 10 m north at 0.1 m/s: 100 s, arriving on the 1000th tick; 9.5 W for 100 s = 950 J
    b = run_traverse(driving, north(10.0, driving), reserve_soc=0.2)
    assert b.outcome == "arrived" and b.ok and b.below_reserve is None
    assert b.planned_length_m == 10.0 and b.planned_duration_s == pytest.approx(100.0)
    assert b.arrived_at_s == pytest.approx(100.0, abs=0.1) and b.odometer_m == pytest.approx(10.0)
    assert b.drive_energy_j == pytest.approx(950.0, abs=9.5 * 0.1)
    assert b.peak_drive_w == pytest.approx(9.5) and b.power_limited_s == 0.0
    profile = power_profile(driving, north(1.0, driving), dt_s=1.0)
    assert profile == [pytest.approx(9.5)] * 10


def test_run_traverse_says_where_the_rover_leaves_a_radios_footprint(driving):
    """Found by a vehicle engineer: a traverse answered YES with the rover beyond both radio
    footprints at its far end, and nothing said. MAPP starts at (5, 0); the lander's ellipse
    (400 x 250 m around the origin) ends at y = 250 * sqrt(1 - (5 / 400)^2) = 249.98 m: 300 m
    north at 0.1 m/s leaves it at ~250 m along, then 50 m (500 s) out of range."""
    b = run_traverse(driving, north(300.0, driving), reserve_soc=0.2)
    cov = dict(b.coverage)["lander"]
    assert cov.first_out is not None and cov.first_out.y_m == pytest.approx(249.98, abs=0.02)
    assert cov.out_s == pytest.approx(500.2, abs=0.3)
    assert dict(run_traverse(driving, north(10.0, driving)).coverage)["lander"] == (0.0, None)


def test_run_traverse_says_where_the_reserve_is_crossed(driving):
    # a 20 kJ pack, the MAPP parked already drains: the reserve goes on the way
    b = run_traverse(small_pack(driving, 2e4), north(500.0, driving), reserve_soc=0.5)
    assert not b.ok and b.below_reserve is not None
    assert 0 < b.below_reserve.odometer_m < 500 and b.below_reserve.waypoint == 0
    assert b.below_reserve.y_m == pytest.approx(b.below_reserve.odometer_m, abs=1e-6)
    with pytest.raises(ValueError, match="above the rover's max_speed_m_per_s"):
        run_traverse(driving, DriveTraverse([TraverseWaypoint(5, 10, 0)], 1.0))
    with pytest.raises(ValueError, match="has no drive section"):
        run_traverse(load_rover(static_rover("mapp.yaml")), north(1.0, driving))
    with pytest.raises(ValueError, match="has no drive section"):
        power_profile(load_rover(static_rover("mapp.yaml")), north(1.0, driving))
    with pytest.raises(ValueError, match="steeper than"):
        power_profile(driving, DriveTraverse([TraverseWaypoint(5, 1, 5)]))
    short = run_traverse(driving, north(500.0, driving), max_hours=0.01)
    assert short.outcome == "time limit" and short.arrived_at_s is None


def test_lunaris_sim_answers_the_traverse_question(tmp_path):
    traverse = ROOT / "config" / "traverses" / "mapp-crater-rim.yaml"
    yes = subprocess.run(lunaris_cmd("sim", str(ROVERS / "mapp.yaml"), "--traverse", str(traverse)),
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert yes.returncode == 0, yes.stderr
    assert "answer: YES - it arrives with" in yes.stdout and "8 waypoint(s), 520 m" in yes.stdout
    no = subprocess.run(lunaris_cmd("sim", str(ROVERS / "mapp.yaml"), "--traverse", str(traverse),
                                    "--reserve", "0.99"), capture_output=True, text=True, cwd=ROOT,
                        timeout=120)
    assert no.returncode == 1 and "answer: NO - it arrives, but the charge falls below the 99%" in no.stdout
    assert "below 99%" in no.stdout
    for args, error in (
            (["--traverse", str(traverse), "--reserve", "2"], "--reserve is a state of charge"),
            (["--return"], "--return needs --traverse"),
            (["--traverse", str(tmp_path / "none.yaml")], "cannot read file")):
        bad = subprocess.run(lunaris_cmd("sim", str(ROVERS / "mapp.yaml"), *args), capture_output=True,
                             text=True, cwd=ROOT, timeout=60)
        assert bad.returncode == 2 and error in bad.stderr, (args, bad.stderr)
    static = subprocess.run(lunaris_cmd("sim", str(static_rover("mapp.yaml")), "--traverse", str(traverse)),
                            capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert static.returncode == 2 and "has no drive section" in static.stderr


def test_the_fast_path_computes_what_the_general_path_computes(mapp):
    """The per-rail sums of a block of load samples, resolved in one pass, give the same
    numbers to the bit as the loads and the PDM taken to their fixed point every tick:
    through shedding, a short that trips a rail, its clearing and reset, and depletion."""
    rover = small_pack(mapp, 2e4)
    fast, general = ComposedTwin(rover, seed=4), ComposedTwin(rover, seed=4, fast=False)
    for tick in range(4000):
        if tick == 500:
            for twin in (fast, general):
                twin.set_faults("load", "nav_camera", [Short(resistance_ohm=0.05)])
        if tick == 800:
            for twin in (fast, general):
                twin.set_faults("load", "nav_camera", [])
                twin.power.command("5V_CH2", reset=True)
        if tick == 1200:
            for twin in (fast, general):
                twin.solar.sun_angle_deg = 80.0
        fast.step()
        general.step()
        assert fast.summary == general.summary, tick
        assert fast.battery.state() == general.battery.state(), tick
        assert fast.loads.rail_on == general.loads.rail_on, tick
    assert fast.battery.depleted or fast.battery.uv_cutoff  # the run went all the way down
    assert fast.power.state() == general.power.state()


# -- the umbilical's cable (SPEC §12e) ---------------------------------------------------------


def plugged_in(rover: Rover, **umbilical) -> Rover:
    raw = msgspec.to_builtins(rover)
    raw["umbilical"] = {"connected": True, "power_w": 120.0, **umbilical}
    return msgspec.convert(raw, Rover)


def test_a_traverse_does_not_start_plugged_in_unless_the_cable_follows(driving):
    assert umbilical_holds(driving.umbilical, plugged=False) is None
    with pytest.raises(ValueError, match="the umbilical is plugged in and it has no slack"):
        run_traverse(plugged_in(driving), north(1.0, driving))
    with pytest.raises(ValueError, match="its 10 m cable does not follow the rover"):
        run_traverse(plugged_in(driving, cable_m=10.0), north(1.0, driving))
    # a cable that follows: 1 m north at 0.1 m/s, plugged in all the way (1 m < 10 m)
    b = run_traverse(plugged_in(driving, cable_m=10.0, follows_rover=True), north(1.0, driving))
    assert b.outcome == "arrived"


def test_driving_past_the_cable_pulls_it_out_in_the_composed_twin(driving):
    # 2.5 m of tether from the start (5, 0, 0), driving north at 0.1 m/s: past it after 25 s
    twin = ComposedTwin(plugged_in(driving, cable_m=2.5, follows_rover=True), seed=1)
    assert twin.drive is not None and twin.summary.generation_w > 119.0  # 120 W and the sun
    twin.drive.start(plan(north(10.0, driving), driving.drive, (5.0, 0.0, 0.0))[0])
    for _ in range(250):  # 25.0 s: 2.5 m, on the cable's reach
        twin.step()
    assert twin.solar.umbilical_plugged and twin.drive.y_m == pytest.approx(2.5)
    twin.step()  # 2.51 m
    assert not twin.solar.umbilical_plugged
    assert twin.power.umbilical_w == 0.0 and twin.summary.generation_w < 50.0  # the sun only
