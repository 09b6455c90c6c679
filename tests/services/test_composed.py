"""The models composed in one process, on a deterministic clock."""

from __future__ import annotations

import subprocess

import msgspec
import pytest
from numpy.testing import assert_allclose

from common.config import Rover, load_rover
from common.faults import fault_of
from services.composed import ComposedTwin, run_budget
from tests.harness import ROOT, ROVERS, lunaris_cmd


@pytest.fixture
def mapp() -> Rover:
    return load_rover(ROVERS / "mapp.yaml")


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


def test_a_short_trips_the_rail_and_darkens_its_loads(mapp):
    twin = ComposedTwin(mapp, seed=1)
    twin.loads.apply_fault(*fault_of("load/nav_camera/short", {"resistance_ohm": 0.05}))
    twin.step()
    assert twin.power.switches["5V_CH2"].tripped
    assert twin.loads.power("hazard_cameras") == (0.0, False)
    assert twin.battery.demand_w < 100  # the short never reached the battery


def test_lunaris_sim_prints_a_budget():
    run = subprocess.run(lunaris_cmd("sim", str(ROVERS / "mapp.yaml"), "--hours", "0.1"),
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "3600 ticks" in run.stdout and "state of charge" in run.stdout


def test_the_fast_path_computes_what_the_general_path_computes(mapp):
    """The per-rail sums of a block of load samples, resolved in one pass, give the same
    numbers to the bit as the loads and the PDM taken to their fixed point every tick:
    through shedding, a short that trips a rail, its clearing and reset, and depletion."""
    rover = small_pack(mapp, 2e4)
    fast, general = ComposedTwin(rover, seed=4), ComposedTwin(rover, seed=4, fast=False)
    for tick in range(4000):
        if tick == 500:
            for twin in (fast, general):
                twin.loads.apply_fault(*fault_of("load/nav_camera/short", {"resistance_ohm": 0.05}))
        if tick == 800:
            for twin in (fast, general):
                twin.loads.apply_fault(*fault_of("load/nav_camera/short"))
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
