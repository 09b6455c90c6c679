"""Battery model against numbers derived by hand (see the derivations in each test)."""

from __future__ import annotations

import math

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from common.config import Battery, load_rover
from common.faults import (
    CATALOGUE,
    DERIVED,
    CapacityLoss,
    Disconnect,
    Dust,
    Heating,
    Resistance,
    battery_fault_code,
)
from services.battery.model import BatteryModel, ocv, solve_bus, thermal_step
from tests.harness import ROVERS

SOC = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
VOLTS = [3.60, 3.68, 3.73, 3.77, 3.81, 3.85, 3.90, 3.96, 4.03, 4.11, 4.20]


# The MAPP pack as the first release described it: R = 0.06 ohm, no branches, no cut-off.
MAPP_BATTERY = {k: v for k, v in msgspec.to_builtins(load_rover(ROVERS / "mapp.yaml").battery).items()
                if k not in ("resistance_curve", "rc_pairs", "cutoff_cell_v", "uncertainty")}
MAPP_BATTERY["internal_resistance_ohm"] = 0.06


def battery_cfg(**over) -> Battery:
    """The MAPP pack with some parameters changed (``thermal_<name>`` for the thermal ones)."""
    base = {k: (dict(v) if isinstance(v, dict) else v) for k, v in MAPP_BATTERY.items()}
    for k, v in over.items():
        if k.startswith("thermal_"):
            base["thermal"][k[len("thermal_"):]] = v
        else:
            base[k] = v
    return msgspec.convert(base, Battery)


# -- open-circuit voltage --------------------------------------------------------------------

@pytest.mark.parametrize(("soc", "expected_v"), [
    (0.0, 4 * 3.60),             # first point
    (1.0, 4 * 4.20),             # last point
    (0.5, 4 * 3.85),             # on a point
    (0.05, 4 * 3.64),            # halfway between 3.60 and 3.68
    (0.55, 4 * 3.875),           # halfway between 3.85 and 3.90
    (0.925, 4 * (4.11 + 0.25 * (4.20 - 4.11))),  # a quarter of the way along the last segment
    (-0.2, 4 * 3.60),            # held flat outside [0, 1]
    (1.3, 4 * 4.20),
])
def test_ocv_interpolates_the_curve(soc, expected_v):
    assert_allclose(ocv(soc, SOC, VOLTS, 4), expected_v, rtol=1e-12)


# -- the bus solution --------------------------------------------------------------------------

def test_bus_solution_discharging():
    # V_oc = 16 V, R = 0.1 ohm, P = 100 W: I = (16 - sqrt(256 - 40)) / 0.2 = 6.515307 A
    p = solve_bus(16.0, 0.1, 100.0)
    assert_allclose(p.current_a, (16 - math.sqrt(216)) / 0.2, rtol=1e-12)
    assert_allclose(p.voltage_v, 16 - 0.1 * p.current_a, rtol=1e-12)
    assert_allclose(p.voltage_v * p.current_a, 100.0, rtol=1e-12)
    assert not p.brownout


def test_bus_solution_with_zero_resistance_is_p_over_voc():
    p = solve_bus(16.0, 0.0, 80.0)
    assert (p.voltage_v, p.current_a, p.power_w, p.brownout) == (16.0, 5.0, 80.0, False)


@pytest.mark.parametrize("power_w", [0.0, 50.0, -50.0, 1e12])
def test_bus_solution_with_no_source_voltage_is_zero_not_nan(power_w):
    p = solve_bus(0.0, 0.1, power_w)
    assert p.voltage_v == 0.0 and p.current_a == 0.0 and p.power_w == 0.0


def test_bus_solution_beyond_max_power_browns_out_at_the_maximum_power_point():
    # P_max = V_oc^2 / 4R = 256 / 0.4 = 640 W, delivered at V = 8 V, I = 80 A
    p = solve_bus(16.0, 0.1, 1000.0)
    assert p.brownout
    assert_allclose((p.voltage_v, p.current_a, p.power_w), (8.0, 80.0, 640.0), rtol=1e-12)


def test_bus_solution_exactly_at_max_power_is_delivered():
    p = solve_bus(16.0, 0.1, 640.0)
    assert not p.brownout
    assert_allclose((p.voltage_v, p.current_a), (8.0, 80.0), rtol=1e-9)


def test_bus_solution_charging():
    # P = -100 W: I = 2P / (V_oc + sqrt(V_oc^2 - 4RP)) = -200 / (16 + sqrt(296)) = -6.02325 A
    p = solve_bus(16.0, 0.1, -100.0)
    assert_allclose(p.current_a, -200.0 / (16.0 + math.sqrt(296.0)), rtol=1e-12)
    assert p.voltage_v > 16.0  # charging lifts the terminal voltage above V_oc
    assert_allclose(p.power_w, -100.0, rtol=1e-12)


def test_bus_solution_refuses_non_finite_power():
    with pytest.raises(ValueError, match="power_w must be finite"):
        solve_bus(16.0, 0.1, float("nan"))


# -- energy and heat bookkeeping ------------------------------------------------------------

def test_energy_pays_for_delivered_power_and_joule_heat():
    cfg = battery_cfg(thermal_conductance_w_per_k=0.0)
    pack = BatteryModel(cfg)
    pack.set_demand(60.0)
    e0, t0 = pack.energy_j, pack.temperature_c
    delivered = heat = 0.0
    for _ in range(5000):
        point = pack.operating_point()
        delivered += point.power_w * 0.1
        heat += point.current_a**2 * cfg.internal_resistance_ohm * 0.1
        pack.step(0.1)
    # Every joule that left the store was either delivered or became heat.
    assert_allclose(e0 - pack.energy_j, delivered + heat, rtol=1e-9)
    assert_allclose(delivered, 60.0 * 500.0, rtol=1e-9)
    # With no conductance, all the heat warms the pack: dT = Q / C.
    assert_allclose(pack.temperature_c - t0, heat / cfg.thermal.heat_capacity_j_per_k, rtol=1e-9)


def test_thermal_step_follows_the_exponential_to_steady_state():
    # C = 1500 J/K, G = 0.8 W/K, Q = 10 W, T_env = 20 C: T_inf = 32.5 C, tau = C / G = 1875 s
    t = thermal_step(20.0, 10.0, 0.8, 1500.0, 20.0, 1875.0)
    assert_allclose(t, 32.5 - 12.5 * math.exp(-1.0), rtol=1e-12)
    # Integrating in small steps gives the same answer as one big one (exact integration).
    small = 20.0
    for _ in range(1875):
        small = thermal_step(small, 10.0, 0.8, 1500.0, 20.0, 1.0)
    assert_allclose(small, t, rtol=1e-12)


def test_charging_is_limited_and_stops_when_full():
    pack = BatteryModel(battery_cfg(initial_soc=0.5))
    pack.set_demand(-1000.0)  # far more than max_charge_w = 150 W
    assert_allclose(pack.operating_point().power_w, -150.0, rtol=1e-12)
    pack.energy_j = pack.capacity_j
    assert pack.operating_point().power_w == 0.0
    pack.step(10.0)
    assert pack.energy_j == pack.capacity_j


def test_time_to_empty_from_current_draw():
    pack = BatteryModel(battery_cfg())
    pack.set_demand(100.0)
    r = pack.reading()
    assert_allclose(r.time_to_empty_s, r.energy_j / (r.ocv_v * r.current_a), rtol=1e-12)
    pack.set_demand(-10.0)
    assert pack.reading().time_to_empty_s is None


def test_draining_to_empty_depletes_the_pack_with_fault_code_5():
    pack = BatteryModel(battery_cfg(capacity_j=1000.0))
    pack.set_demand(100.0)
    for _ in range(200):
        pack.step(0.1)
    r = pack.reading()
    assert r.energy_j == 0.0 and r.soc == 0.0
    assert not r.operational and "depleted" in r.faults
    assert battery_fault_code(r.faults) == 5
    assert pack.operating_point().current_a == 0.0


def test_depleted_pack_recovers_only_above_the_hysteresis():
    pack = BatteryModel(battery_cfg(capacity_j=1000.0, initial_soc=0.0, depleted_soc=0.0,
                                    depleted_hysteresis_soc=0.05))
    assert pack.depleted
    pack.set_demand(-10.0)  # charging is allowed while depleted
    pack.step(2.0)  # ~20 J of 1000: soc ~0.02, still below 0.05
    assert pack.depleted
    pack.step(5.0)
    assert not pack.depleted and pack.operational


def test_capacity_loss_loses_energy_above_the_new_capacity():
    pack = BatteryModel(battery_cfg())
    pack.set_faults([CapacityLoss(fraction=0.4)])
    assert_allclose(pack.energy_j, 0.6 * 5.3e5)
    assert_allclose(pack.soc, 1.0)
    assert pack.reading().faults == []  # the pack's own alarms only: a smaller capacity_j shows it
    assert_allclose(pack.reading().capacity_j, 0.6 * 5.3e5)
    pack.set_faults([])  # cleared: capacity back, the lost energy is not
    assert_allclose(pack.soc, 0.6)


def test_overheating_raises_alarm_then_cutoff_then_recovers_below_max():
    pack = BatteryModel(battery_cfg())
    pack.set_faults([Heating(heat_w=200.0)])  # T_inf = 20 + 200 / 0.8 = 270 C
    pack.step(1.0)
    assert pack.temperature_c > 20.0 and pack.reading().faults == []  # rising, no alarm yet
    assert pack.reading().heat_w == 0.0  # idle: no losses; the injected 200 W is not told (12b)
    while pack.temperature_c <= 60.0:
        pack.step(1.0)
    assert "over_temperature" in pack.derived_faults() and pack.operational
    assert pack.reading().faults == ["over_temperature"] and battery_fault_code(["over_temperature"]) == 1
    while pack.temperature_c <= 75.0:
        pack.step(1.0)
    assert pack.thermal_cutoff and not pack.operational
    assert battery_fault_code(pack.reading().faults) == 6
    pack.set_faults([])
    while pack.temperature_c >= 60.0:
        pack.step(10.0)
    assert not pack.thermal_cutoff and pack.operational


def test_disconnected_pack_supplies_nothing():
    pack = BatteryModel(battery_cfg())
    pack.set_faults([Disconnect()])
    pack.set_demand(50.0)
    r = pack.reading()
    assert (r.voltage_v, r.current_a, r.operational) == (0.0, 0.0, False)
    assert r.faults == ["no_output"] and battery_fault_code(r.faults) == 7  # what its BMS sees
    pack.set_faults([])
    assert pack.reading().operational and pack.reading().faults == []


def test_the_pack_applies_every_fault_it_is_given_and_refuses_another_components():
    # R0 = 0.06 ohm x 2 = 0.12; 20 W of heat; 30 % of 5.3e5 J lost; then the list replaced whole
    pack = BatteryModel(battery_cfg())
    pack.set_faults([Resistance(factor=2.0), Heating(heat_w=20.0), CapacityLoss(fraction=0.3)])
    assert_allclose((pack.resistance_ohm, pack.injected_heat_w, pack.capacity_j),
                    (0.12, 20.0, 0.7 * 5.3e5))
    pack.set_faults([Heating(heat_w=5.0)])  # the others cleared: what is not given is not in effect
    assert_allclose((pack.resistance_ohm, pack.injected_heat_w, pack.capacity_j), (0.06, 5.0, 5.3e5))
    with pytest.raises(ValueError, match="the battery has no fault kind 'dust'"):
        pack.set_faults([Dust(fraction=0.5)])
    assert pack.injected_heat_w == 5.0  # nothing changed


@pytest.mark.parametrize("fault", [Heating(heat_w=0.0), Resistance(factor=1.0),
                                   CapacityLoss(fraction=0.0), Heating(heat_w=3.0),
                                   Resistance(factor=4.0), CapacityLoss(fraction=0.5), Disconnect()])
def test_the_pack_names_no_injected_fault(fault):
    """SPEC §12b: the reading carries the pack's own alarms only; a fault of any parameters,
    a zero-change one too, never shows by its name (the fault book lists it)."""
    pack = BatteryModel(battery_cfg())
    pack.set_faults([fault])
    pack.set_demand(20.0)
    pack.step(1.0)
    faults = pack.reading().faults
    assert set(faults) <= set(DERIVED["battery"])
    assert not set(faults) & set(CATALOGUE["battery"])


# -- properties ----------------------------------------------------------------------------

extreme = st.one_of(st.just(0.0), st.floats(-1e15, 1e15, allow_nan=False),
                    st.sampled_from([1e300, -1e300, 5e-324, -5e-324]))


@settings(max_examples=300, deadline=None)
@given(
    demands=st.lists(extreme, min_size=1, max_size=20),
    dts=st.lists(st.one_of(st.just(0.0), st.floats(0.0, 1e6)), min_size=1, max_size=20),
    r_ohm=st.one_of(st.just(0.0), st.floats(0.0, 1e3)),
    capacity_j=st.floats(1e-3, 1e12),
    soc=st.floats(0.0, 1.0),
    heat=st.floats(0.0, 1e6),
    loss=st.floats(0.0, 1.0),
    factor=st.floats(1.0, 1e6),
)
def test_no_input_gives_nan_negative_energy_or_soc_outside_0_1(demands, dts, r_ohm, capacity_j, soc,
                                                                heat, loss, factor):
    pack = BatteryModel(battery_cfg(internal_resistance_ohm=r_ohm, capacity_j=capacity_j,
                                    initial_soc=soc))
    pack.set_faults([Heating(heat_w=heat), Resistance(factor=factor), CapacityLoss(fraction=loss)])
    for demand, dt in zip(demands, dts * len(demands), strict=False):
        pack.set_demand(demand)
        pack.step(dt)
        r = pack.reading()
        values = [r.energy_j, r.soc, r.voltage_v, r.current_a, r.power_w, r.temperature_c, r.ocv_v]
        assert all(math.isfinite(v) for v in values), r
        assert r.energy_j >= 0.0
        assert 0.0 <= r.soc <= 1.0
        assert r.time_to_empty_s is None or (math.isfinite(r.time_to_empty_s)
                                             and r.time_to_empty_s >= 0.0)


def test_discharge_current_is_limited_by_the_bms():
    # MAPP: V_oc = 16.8 V at full charge, R = 0.06 ohm, limit 30 A.
    # 600 W needs I = (16.8 - sqrt(16.8^2 - 0.24 * 600)) / 0.12 = 43.5 A > 30 A.
    pack = BatteryModel(battery_cfg())
    pack.set_demand(600.0)
    p = pack.operating_point()
    assert p.current_limited and p.brownout
    assert_allclose((p.current_a, p.voltage_v), (30.0, 16.8 - 30.0 * 0.06), rtol=1e-12)
    assert {"over_current", "brownout"} <= set(pack.derived_faults())
    assert battery_fault_code(pack.reading().faults) == 4


def test_every_derived_fault_is_in_the_catalogue_of_derived_faults():
    pack = BatteryModel(battery_cfg())
    pack.temperature_c = 200.0
    pack.energy_j = 0.0
    pack._update_latches()
    pack.set_demand(1e6)
    assert set(pack.derived_faults()) <= set(DERIVED["battery"])


# -- what "empty" means in numbers (issue 26.5) -----------------------------------------------


def test_battery_state_says_where_the_pack_stops():
    from services.battery.service import limits
    # MAPP: 4 cells in series cut off at 3.2 V each: 12.8 V; empty at 0 % charge
    assert limits(load_rover(ROVERS / "mapp.yaml").battery) == pytest.approx((0.0, 12.8))
    # LTV: 96 cells at 3.2 V: 307.2 V; a 5 % reserve counts as empty
    assert limits(load_rover(ROVERS / "ltv.yaml").battery) == pytest.approx((0.05, 307.2))
    # no cut-off in the file: null, never 0 V
    assert limits(battery_cfg(depleted_soc=0.1)) == (0.1, None)
