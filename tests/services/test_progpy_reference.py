"""The battery model against NASA ProgPy's BatteryCircuit on the same cell (SPEC §10).

``config/rovers/bc18650.yaml`` is BatteryCircuit's default 18650 as a Lunaris pack, generated
by ``tools/derive_bc18650.py`` from ProgPy's own equations. Both models run ProgPy's example
current profile and constant-power discharges (``testbed/progpy_cell.py``). Targets: end of
discharge within 0.5 %, terminal voltage RMSE under 5 mV.
"""

from __future__ import annotations

import importlib.util

import pytest

from testbed import progpy_cell as pc
from tests.harness import ROOT


@pytest.fixture(scope="module")
def comparisons() -> dict[str, pc.Comparison]:
    return {p.name: pc.compare(p) for p in pc.PROFILES}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("profile", [p.name for p in pc.PROFILES])
def test_end_of_discharge_and_voltage_follow_battery_circuit(comparisons, profile):
    c = comparisons[profile]
    assert abs(c.eod_error) < 0.005, c
    assert c.rmse_v < 0.005, c
    assert c.eod_progpy_s > 1000.0  # a real discharge, not a cut-off at the first load step


@pytest.mark.timeout(120)
def test_without_its_branches_the_cell_misses_the_targets():
    """The first release's model of the same cell (one resistance, the sum of BatteryCircuit's
    at full charge; no branches) ends the 15 W discharge late: what the circuit is for."""
    import msgspec
    raw = msgspec.to_builtins(pc.reference_cell())
    battery = raw["battery"]
    battery["internal_resistance_ohm"] = 0.0538926 + 0.0697776
    battery["rc_pairs"] = []
    rover = msgspec.convert(raw, type(pc.reference_cell()))
    run = pc.lunaris_run(pc.PROFILES[2], rover)
    reference = pc.progpy_run(pc.PROFILES[2])
    assert run.eod_s / reference.eod_s - 1.0 > 0.005


@pytest.mark.timeout(120)
def test_the_committed_reference_cell_is_what_the_script_derives():
    spec = importlib.util.spec_from_file_location("derive_bc18650", ROOT / "tools" / "derive_bc18650.py")
    assert spec is not None and spec.loader is not None
    derive = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(derive)
    assert derive.render(derive.derive()) == derive.TARGET.read_text(), (
        "config/rovers/bc18650.yaml is stale: run tools/derive_bc18650.py")


@pytest.mark.timeout(180)
def test_end_of_discharge_distribution_matches_progpy_monte_carlo():
    """The same cell from 30 % charge (BatteryCircuit's own SOC), the same noise: every 1 s
    step each future draws ``clip(N(8, 3), 0, 20)`` W. ProgPy's MonteCarlo predictor (40
    futures, RK4 at the same 1 s step, ``i = P / v``) and Lunaris's prediction (2000 futures,
    the rover's tick = 1 s, the loads' own draw) end their discharges (about 850 s, spread
    about 20 s) at the same median within 1.5 % (the sampling error of 40 futures' median is
    about 0.5 %) and with the same spread within its sampling error (the std of a 40-sample
    std is 11 %)."""
    import msgspec
    import numpy as np

    from common.config import Rover
    from services.battery.prediction import predict, start_of
    from services.composed import ComposedTwin

    raw = msgspec.to_builtins(pc.reference_cell())
    raw["tick_hz"] = 1.0
    raw["battery"]["initial_soc"] = pc.energy_soc(0.3)
    raw["battery"]["uncertainty"] = {}
    raw["loads"][0].update(nominal_w=8.0, std_w=3.0, max_w=20.0)
    rover = msgspec.convert(raw, Rover)
    ours = predict(start_of(ComposedTwin(rover)), 2000.0, 2000, seed=11, step_ticks=1)
    theirs = pc.progpy_monte_carlo(40, 0.3, 8.0, 3.0, 20.0, dt_s=1.0, seed=12)
    assert np.isfinite(ours.time_to_empty_s).all() and np.isfinite(theirs).all()
    assert 700 < np.median(theirs) < 1200
    assert abs(np.median(ours.time_to_empty_s) / np.median(theirs) - 1.0) < 0.015
    ratio = np.std(ours.time_to_empty_s) / np.std(theirs)
    assert 0.6 < ratio < 1.6, ratio
