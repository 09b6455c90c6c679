"""The rover file's second-release battery fields: every problem reported with its path."""

from __future__ import annotations

import pytest

from common.config import ConfigError, load_rover, parse_rover
from tests.common.test_config import MAPP
from tests.harness import ROVERS

FIRST_RELEASE = MAPP[:MAPP.index("  # Equivalent circuit")] + "  internal_resistance_ohm: 0.06\n" + \
    MAPP[MAPP.index("  max_discharge_a"):]
R0_LINE = "  internal_resistance_ohm: 0.06\n"


def problems_of(text: str) -> list[str]:
    with pytest.raises(ConfigError) as info:
        parse_rover(text, "x.yaml")
    return info.value.problems


def with_battery(extra: str, drop_r0: bool = False) -> str:
    text = FIRST_RELEASE.replace(R0_LINE, "") if drop_r0 else FIRST_RELEASE
    assert "  depleted_soc: 0.0\n" in text
    return text.replace("  depleted_soc: 0.0\n", "  depleted_soc: 0.0\n" + extra, 1)


def test_the_series_resistance_is_given_once():
    assert R0_LINE in FIRST_RELEASE
    assert problems_of(FIRST_RELEASE.replace(R0_LINE, "")) == [
        "battery.internal_resistance_ohm: missing required field (or give battery.resistance_curve)"]
    both = with_battery("  resistance_curve: {soc: [0.0, 1.0], ohm: [0.1, 0.06]}\n")
    assert problems_of(both) == [
        "battery.resistance_curve: replaces internal_resistance_ohm; give one of them, not both"]
    curve_only = with_battery("  resistance_curve: {soc: [0.0, 0.1, 1.0], ohm: [0.4, 0.1, 0.06]}\n",
                              drop_r0=True)
    assert parse_rover(curve_only).battery.series_resistance.ohm == [0.4, 0.1, 0.06]


def test_every_circuit_problem_is_reported_with_its_path():
    text = with_battery(
        "  resistance_curve: {soc: [0.0, 0.5, 0.4], ohm: [0.1, 0.1]}\n"
        "  rc_pairs:\n"
        "    - {resistance_ohm: 0.05, capacitance_f: -1}\n"
        "    - {resistance_ohm: 0.05, capacitance_f: 200, resistance_curve: {soc: [0.0], ohm: [0.1]}}\n"
        "    - {capacitance_f: 15}\n"
        "    - {capacitance_f: 15, resistance_curve: {soc: [0.0, 1.0], ohm: [0.0, 0.1]}}\n"
        "  cutoff_cell_v: 4.3\n"
        "  uncertainty: {capacity_frac: 2, resistance_frac: 0.1, bogus: 1}\n", drop_r0=True)
    assert sorted(problems_of(text)) == sorted([
        "battery.resistance_curve.ohm: expected 3 values, got 2",
        "battery.resistance_curve.soc: must be strictly increasing",
        "battery.rc_pairs[0].capacitance_f: must be > 0.0, got -1",
        "battery.rc_pairs[1]: give resistance_ohm or resistance_curve (exactly one), got both",
        "battery.rc_pairs[2]: give resistance_ohm or resistance_curve (exactly one), got neither",
        "battery.rc_pairs[3].resistance_curve.ohm: a branch resistance must be > 0",
        "battery.cutoff_cell_v: must be below the full cell's open-circuit voltage (4.2 V), got 4.3: "
        "the pack could never supply",
        "battery.uncertainty.capacity_frac: must be <= 1.0, got 2",
        "battery.uncertainty.bogus: unknown field",
    ])


def test_the_reference_cell_is_the_circuit_of_progpy_s_battery_circuit():
    cell = load_rover(ROVERS / "bc18650.yaml").battery
    curve = cell.ocv_curve
    low = [v for s, v in zip(curve.soc, curve.volts, strict=True) if s < 0.1]
    assert len(low) >= 20 and curve.volts[0] == pytest.approx(2.932, abs=1e-3)
    assert curve.volts[-1] == pytest.approx(4.183, abs=1e-3)  # BatteryCircuit's V0
    assert cell.cutoff_cell_v == 3.0 and cell.internal_resistance_ohm == 0.0
    rs, rcp = cell.rc_pairs
    assert (rs.resistance_ohm, rs.capacitance_f) == (0.0538926, 234.387)
    assert rcp.capacitance_f == 14.8223 and rcp.resistance_curve is not None
    assert rcp.resistance_curve.ohm[0] == pytest.approx(0.290, abs=1e-3)  # Rcp at SOC 0


@pytest.mark.parametrize("name", ["mapp.yaml", "ltv.yaml"])
def test_shipped_rovers_have_a_circuit_and_a_cutoff(name):
    b = load_rover(ROVERS / name).battery
    assert b.rc_pairs and b.cutoff_cell_v is not None and b.resistance_curve is not None
    assert b.uncertainty.capacity_frac > 0.0


def test_a_first_release_file_is_still_valid():
    b = parse_rover(FIRST_RELEASE).battery
    assert b.series_resistance == 0.06 and b.rc_pairs == [] and b.cutoff_cell_v is None
