"""The battery model against NASA ProgPy's BatteryCircuit on the same cell (SPEC §10).

``config/rovers/bc18650.yaml`` is BatteryCircuit's default 18650 as a Lunaris pack, generated
by ``tools/derive_bc18650.py`` from ProgPy's own equations. Both models run ProgPy's example
current profile and constant-power discharges (``tests/progpy_cell.py``). Targets: end of
discharge within 0.5 %, terminal voltage RMSE under 5 mV.
"""

from __future__ import annotations

import importlib.util

import pytest

from tests import progpy_cell as pc
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
