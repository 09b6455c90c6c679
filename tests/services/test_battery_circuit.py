"""The equivalent circuit of the second release against numbers derived by hand.

Most tests use a pack with a flat open-circuit curve (4 cells at 4.0 V: ``V_oc = 16 V`` at
every charge), so that the numbers below follow from the circuit alone:

- series resistance ``R0 = 0.1 ohm``; for ``P = 100 W``:
  ``I = 2 P / (16 + sqrt(256 - 4 * 0.1 * 100)) = 200 / (16 + sqrt(216)) = 6.5153077 A``;
- one branch ``R1 = 0.05 ohm``, ``C1 = 200 F``, so ``tau = R1 C1 = 10 s``.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from common.config import Battery
from common.faults import DERIVED, FAULT_CODES, CapacityLoss, Resistance, battery_fault_code
from services.battery.model import BatteryModel
from tests.services.test_battery_model import MAPP_BATTERY

I_100W = 200.0 / (16.0 + math.sqrt(216.0))


def pack_cfg(**over) -> Battery:
    """MAPP's pack with a flat curve at 4.0 V per cell, R0 = 0.1 ohm, no conductance, and the
    fields in ``over`` (``rc_pairs`` etc.)."""
    base = {k: (dict(v) if isinstance(v, dict) else v) for k, v in MAPP_BATTERY.items()}
    base["ocv_curve"] = {"soc": [0.0, 1.0], "volts": [4.0, 4.0]}
    base["internal_resistance_ohm"] = 0.1
    base["thermal"]["conductance_w_per_k"] = 0.0
    base.update(over)
    return msgspec.convert(base, Battery)


ONE_PAIR = [{"resistance_ohm": 0.05, "capacitance_f": 200.0}]


def held_current(pack: BatteryModel, current_a: float) -> None:
    """Demand the power that makes the pack's solution exactly ``current_a``:
    ``P = (V_x - R0 I) I``."""
    v_x = pack.ocv_v - sum(pack.branch_v)
    pack.set_demand((v_x - pack.resistance_ohm * current_a) * current_a)


# -- the branches ------------------------------------------------------------------------------

def test_step_response_of_a_branch():
    # Relaxed branch, I = 6.5153 A held for one step of dt = tau = 10 s:
    # v = (1 - e^-1) R1 I = 0.632121 * 0.05 * 6.515308 = 0.205923 V, and the terminal voltage the
    # next solve starts from is V_x = 16 - v.
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_demand(100.0)
    point = pack.operating_point()
    assert_allclose(point.current_a, I_100W, rtol=1e-12)
    assert_allclose(point.voltage_v, 16.0 - 0.1 * I_100W, rtol=1e-12)  # v = 0: only R0 so far
    pack.step(10.0)
    v1 = (1.0 - math.exp(-1.0)) * 0.05 * I_100W
    assert_allclose(pack.branch_v, [v1], rtol=1e-12)
    assert_allclose(v1, 0.205923, rtol=1e-6)
    assert_allclose(pack.reading().polarisation_v, [v1], rtol=1e-12)
    # the new operating point is solved on V_x = 16 - v1
    v_x = 16.0 - v1
    i = 200.0 / (v_x + math.sqrt(v_x**2 - 40.0))
    assert_allclose(pack.operating_point().current_a, i, rtol=1e-12)


def test_branch_relaxes_with_its_time_constant():
    # With no current the branch decays as v(t) = v0 e^(-t / tau): after 2 tau, v0 e^-2.
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_state({**pack.state(), "polarisation_v": [0.3]})
    pack.step(20.0)
    assert_allclose(pack.branch_v, [0.3 * math.exp(-2.0)], rtol=1e-12)
    # the 0.5 C (v0^2 - v^2) it lost became heat: 0.5 * 200 * 0.09 * (1 - e^-4)
    assert_allclose(pack.books.heat_j, 9.0 * (1.0 - math.exp(-4.0)), rtol=1e-12)


def test_exact_exponential_update_at_large_dt_equals_many_small_steps():
    # I held at 5 A: one step of 60 s (6 tau) and 6000 steps of 0.01 s give the same branch
    # voltage, v = (1 - e^-6) * 0.05 * 5 - exact integration does not depend on the step.
    big, small = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR)), BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    held_current(big, 5.0)
    big.step(60.0)
    for _ in range(6000):
        held_current(small, 5.0)
        small.step(0.01)
    want = (1.0 - math.exp(-6.0)) * 0.25
    assert_allclose(big.branch_v, [want], rtol=1e-12)
    assert_allclose(small.branch_v, [want], rtol=1e-9)
    # and the energy each took out of the store is V_oc I t = 16 * 5 * 60 = 4800 J
    assert_allclose([big.books.drawn_j, small.books.drawn_j], [4800.0, 4800.0], rtol=1e-9)


def test_a_step_s_books_match_the_closed_forms_and_a_quadrature():
    # One step of dt = 10 s at I = 6.5153 A from a relaxed branch (v_inf = R1 I, d = -v_inf,
    # a = e^-1):
    #   drawn     = V_oc I dt
    #   heat      = I^2 R0 dt + (v_inf^2 / R1) (dt - 2 tau (1 - a) + tau / 2 (1 - a^2))
    #   capacitor = C1 v1^2 / 2
    #   delivered = (V_oc - R0 I) I dt - I (v_inf dt - v_inf tau (1 - a))
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_demand(100.0)
    step = pack.step(10.0)
    i, r1, tau, dt, a = I_100W, 0.05, 10.0, 10.0, math.exp(-1.0)
    v_inf = r1 * i
    heat = i * i * 0.1 * dt + v_inf**2 / r1 * (dt - 2 * tau * (1 - a) + tau / 2 * (1 - a * a))
    delivered = (16.0 - 0.1 * i) * i * dt - i * (v_inf * dt - v_inf * tau * (1 - a))
    assert_allclose(step.drawn_j, 16.0 * i * dt, rtol=1e-12)
    assert_allclose(step.heat_j, heat, rtol=1e-12)
    assert_allclose(step.delivered_j, delivered, rtol=1e-12)
    assert_allclose(pack.capacitor_j, 0.5 * 200.0 * pack.branch_v[0] ** 2, rtol=1e-12)
    assert_allclose(step.drawn_j, step.delivered_j + step.heat_j + pack.capacitor_j, rtol=1e-12)
    # an independent check of the closed forms: the trapezoid rule over v(t)
    t = np.linspace(0.0, dt, 200_001)
    v = v_inf * (1.0 - np.exp(-t / tau))
    assert_allclose(step.delivered_j, np.trapezoid((16.0 - 0.1 * i - v) * i, t), rtol=1e-9)
    assert_allclose(step.heat_j, np.trapezoid(i * i * 0.1 + v * v / r1, t), rtol=1e-9)


def test_resistance_curves_are_interpolated_and_held_flat_outside():
    # R0 from 0.2 ohm at soc 0.2 to 0.1 ohm at soc 0.6: at soc 0.5, 0.125 ohm; at soc 0.9
    # (outside the table) 0.1 ohm. A branch curve is read the same way.
    curve = {"soc": [0.2, 0.6], "ohm": [0.2, 0.1]}
    cfg = pack_cfg(internal_resistance_ohm=None, resistance_curve=curve, initial_soc=0.5,
                   rc_pairs=[{"capacitance_f": 100.0, "resistance_curve": curve}])
    pack = BatteryModel(cfg)
    assert_allclose(pack.resistance_ohm, 0.125, rtol=1e-12)
    held_current(pack, 2.0)
    pack.step(0.5)  # v = (1 - e^(-0.5 / 12.5)) * 0.125 * 2
    assert_allclose(pack.branch_v, [(1 - math.exp(-0.04)) * 0.25], rtol=1e-6)
    pack.set_state({**pack.state(), "energy_j": 0.9 * cfg.capacity_j})
    assert_allclose(pack.resistance_ohm, 0.1, rtol=1e-12)


def test_a_resistance_fault_multiplies_every_resistance():
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_faults([Resistance(factor=2.0)])
    assert_allclose(pack.resistance_ohm, 0.2, rtol=1e-12)
    held_current(pack, 4.0)
    pack.step(20.0)  # R1 = 0.1, tau = 20 s: v = (1 - e^-1) * 0.4
    assert_allclose(pack.branch_v, [(1 - math.exp(-1.0)) * 0.4], rtol=1e-12)


def test_state_carries_the_branch_voltages_and_old_states_start_relaxed():
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_demand(100.0)
    pack.step(3.0)
    saved = msgspec.json.decode(msgspec.json.encode(pack.state()))  # JSON-able
    other = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    other.set_state(saved)
    assert other.branch_v == pack.branch_v and other.state() == pack.state()
    first_release = {k: v for k, v in saved.items() if k != "polarisation_v"}
    other.set_state(first_release)
    assert other.branch_v == [0.0]


def test_the_reading_reports_the_heat_of_every_resistance():
    # I = 0 but a charged branch still dissipates v^2 / R1: 0.3^2 / 0.05 = 1.8 W
    pack = BatteryModel(pack_cfg(rc_pairs=ONE_PAIR))
    pack.set_state({**pack.state(), "polarisation_v": [0.3]})
    assert_allclose(pack.reading().heat_w, 1.8, rtol=1e-12)


# -- emptying and filling part-way through a step ------------------------------------------

def test_a_store_that_empties_part_way_delivers_only_for_the_part_it_had():
    # No branch: V_oc = 16 V, I = 6.5153 A, the store gives V_oc I = 104.2449 W. With 50 J left
    # a 1 s step runs the current for 50 / 104.2449 = 0.479640 s: the terminals get
    # 100 W * 0.479640 s = 47.964 J, R0 gets I^2 R0 * 0.479640 s = 2.036 J, and the store is
    # then exactly empty.
    pack = BatteryModel(pack_cfg(capacity_j=1000.0, initial_soc=0.05))
    pack.set_demand(100.0)
    step = pack.step(1.0)
    active = 50.0 / (16.0 * I_100W)
    assert pack.energy_j == 0.0
    assert_allclose(step.active_s, active, rtol=1e-12)
    assert_allclose(step.delivered_j, 100.0 * active, rtol=1e-12)
    assert_allclose(step.power_w, 100.0 * active, rtol=1e-12)  # mean over the step
    assert_allclose(step.heat_j, I_100W**2 * 0.1 * active, rtol=1e-12)
    assert_allclose(step.drawn_j, 50.0, rtol=1e-12)
    r = pack.reading()
    assert not r.operational and "depleted" in r.faults and battery_fault_code(r.faults) == 5
    assert (r.current_a, r.power_w) == (0.0, 0.0)
    # an empty store gives nothing more, however long the demand holds
    for _ in range(50):
        after = pack.step(0.1)
        assert after.delivered_j == 0.0 and after.drawn_j == 0.0
    assert pack.energy_j == 0.0


def test_a_reserve_is_a_floor_the_store_stops_at_exactly():
    pack = BatteryModel(pack_cfg(capacity_j=1000.0, initial_soc=0.1, depleted_soc=0.05))
    pack.set_demand(100.0)
    pack.step(1.0)  # 100 J above the 50 J floor: 0.9593 s of the step, then nothing
    assert pack.energy_j == 50.0 and pack.depleted


def test_charging_stops_at_exactly_full():
    # I = -200 / (16 + sqrt(296)) = -6.023253 A; the store takes 96.372 W. 10 J of room: the
    # current runs for 10 / 96.372 = 0.103765 s of the 1 s step; the terminals put in
    # 100 W * 0.103765 s = 10.376 J of which R0 turns I^2 R0 * 0.103765 s = 0.3765 J into heat.
    pack = BatteryModel(pack_cfg(capacity_j=1000.0, initial_soc=0.99))
    pack.set_demand(-100.0)
    step = pack.step(1.0)
    i = -200.0 / (16.0 + math.sqrt(296.0))
    active = 10.0 / (-16.0 * i)
    assert pack.energy_j == 1000.0 and pack.soc == 1.0
    assert_allclose(step.active_s, active, rtol=1e-12)
    assert_allclose(step.delivered_j, -100.0 * active, rtol=1e-12)
    assert_allclose(step.heat_j, i * i * 0.1 * active, rtol=1e-12)
    assert_allclose(step.drawn_j, -10.0, rtol=1e-12)
    assert pack.operating_point().current_a == 0.0  # full: no more charge accepted
    assert pack.step(1.0).delivered_j == 0.0 and pack.energy_j == 1000.0


# -- the under-voltage cut-off ---------------------------------------------------------------

CUTOFF_CELL = {"cells_series": 1, "ocv_curve": {"soc": [0.0, 1.0], "volts": [3.0, 4.0]},
               "capacity_j": 10_000.0, "initial_soc": 0.2, "cutoff_cell_v": 3.05,
               "rc_pairs": [{"resistance_ohm": 0.2, "capacitance_f": 50.0}]}


def test_cutoff_latches_when_the_terminal_voltage_under_load_falls_below_it():
    # V_oc = 3.2 V at soc 0.2, R0 = 0.1 ohm, 3.1 W: I = (3.2 - sqrt(10.24 - 1.24)) / 0.2 = 1 A,
    # V = 3.1 V at first, above 3.05 V. The branch charges towards R1 I = 0.2 V (tau = 10 s)
    # and pulls the terminals below 3.05 V within seconds: the pack latches off.
    pack = BatteryModel(pack_cfg(**CUTOFF_CELL))
    pack.set_demand(3.1)
    assert_allclose(pack.operating_point().current_a, 1.0, rtol=1e-12)
    steps = 0
    while not pack.uv_cutoff:
        assert pack.operating_point().voltage_v >= 3.05  # supplying until the step it falls below
        pack.step(0.1)
        steps += 1
        assert steps < 200
    assert 5 < steps < 100
    r = pack.reading()
    assert not r.operational and r.current_a == 0.0
    assert "under_voltage_cutoff" in r.faults and battery_fault_code(r.faults) == 12


def test_cutoff_comes_back_only_when_the_pack_can_hold_the_demand():
    # Off, with the PDM's rails off (demand 0), the branch relaxes and V_x recovers to 3.2 V,
    # but at steady state 3.1 W needs I = (3.2 - sqrt(10.24 - 4 * 0.3 * 3.1)) / 0.6 = 1.0777 A
    # through R0 + R1 = 0.3 ohm: V = 2.877 V < 3.05 V. It stays off. Charged, it comes back
    # once V_oc - 0.3 * 3.1 / 3.05 >= 3.05, i.e. V_oc >= 3.354918 V: soc 0.354918.
    pack = BatteryModel(pack_cfg(**CUTOFF_CELL))
    pack.set_demand(3.1)
    while not pack.uv_cutoff:
        pack.step(0.1)
    pack.set_demand(0.0)
    pack.step(600.0)
    assert abs(pack.branch_v[0]) < 1e-6 and pack.uv_cutoff
    pack.set_demand(-2.0)
    while pack.uv_cutoff:
        pack.step(1.0)
        assert pack.soc < 0.356
    assert pack.soc >= 0.354918 and pack.operational
    assert "under_voltage_cutoff" not in pack.reading().faults


def test_the_cutoff_has_a_code_and_a_catalogue_entry():
    assert "under_voltage_cutoff" in DERIVED["battery"]
    codes = [c for _, c, _ in FAULT_CODES]
    assert len(codes) == len(set(codes)) and dict((n, c) for n, c, _ in FAULT_CODES)[
        "under_voltage_cutoff"] == 12


def test_without_a_cutoff_a_first_release_pack_never_latches():
    pack = BatteryModel(pack_cfg(capacity_j=1000.0))
    pack.set_demand(600.0)  # deep brown-out
    pack.step(0.1)
    assert not pack.uv_cutoff


# -- properties ----------------------------------------------------------------------------

curve = st.lists(st.floats(0.001, 2.0), min_size=2, max_size=4).map(
    lambda ohm: {"soc": [k / (len(ohm) - 1) for k in range(len(ohm))], "ohm": ohm})
pair = st.one_of(
    st.builds(lambda r, c: {"resistance_ohm": r, "capacitance_f": c},
              st.floats(1e-4, 10.0), st.floats(1e-3, 1e5)),
    st.builds(lambda k, c: {"resistance_curve": k, "capacitance_f": c}, curve, st.floats(1e-3, 1e5)),
)


@settings(max_examples=120, deadline=None)
@given(
    pairs=st.lists(pair, max_size=3),
    r0=st.floats(0.0, 1.0),
    cutoff=st.one_of(st.none(), st.floats(2.5, 4.1)),
    soc=st.floats(0.0, 1.0),
    capacity_j=st.floats(10.0, 1e7),
    profile=st.lists(st.tuples(st.floats(-300.0, 800.0), st.floats(0.0, 50.0),
                               st.integers(1, 60)), min_size=1, max_size=25),
    faults=st.tuples(st.floats(0.0, 0.9), st.floats(1.0, 5.0)),
)
def test_circuit_books_close_and_nothing_comes_from_nothing(pairs, r0, cutoff, soc, capacity_j,
                                                             profile, faults):
    """Long random profiles of demands and steps: no NaN, the store within [0, capacity],
    soc in [0, 1], no negative heat, nothing delivered from an empty store, and the books
    close to 1e-9 of the energy that flowed."""
    cfg = pack_cfg(rc_pairs=pairs, internal_resistance_ohm=r0, cutoff_cell_v=cutoff,
                   initial_soc=soc, capacity_j=capacity_j, cells_series=1,
                   ocv_curve={"soc": [0.0, 0.1, 1.0], "volts": [3.0, 3.6, 4.2]})
    pack = BatteryModel(cfg)
    pack.set_faults([CapacityLoss(fraction=faults[0]), Resistance(factor=faults[1])])
    e0, cap0 = pack.energy_j + pack.books.lost_j, pack.capacitor_j
    flow = 0.0
    for demand, dt, repeat in profile:
        pack.set_demand(demand)
        for _ in range(repeat):
            empty = pack.energy_j <= 0.0
            step = pack.step(dt)
            r = pack.reading()
            assert all(math.isfinite(x) for x in (r.energy_j, r.voltage_v, r.current_a,
                                                   r.power_w, r.temperature_c, *r.polarisation_v))
            assert 0.0 <= pack.energy_j <= pack.capacity_j and 0.0 <= r.soc <= 1.0
            assert step.heat_j >= 0.0
            if empty:
                assert step.delivered_j <= 0.0  # an empty store only takes charge
            flow += abs(step.drawn_j) + abs(step.delivered_j) + step.heat_j
    b = pack.books
    steps = sum(r for _, _, r in profile)
    assert abs(e0 - pack.energy_j - b.drawn_j - b.lost_j) <= 1e-9 * flow + 1e-15 * steps * capacity_j
    imbalance = b.drawn_j - b.delivered_j - b.heat_j - (pack.capacitor_j - cap0)
    assert abs(imbalance) <= 1e-9 * flow + 1e-12


@pytest.mark.parametrize("rover", ["mapp.yaml", "ltv.yaml", "bc18650.yaml"])
def test_shipped_packs_close_their_books_over_a_long_profile(rover):
    from common.config import load_rover
    from tests.harness import ROVERS
    cfg = load_rover(ROVERS / rover).battery
    pack = BatteryModel(cfg)
    rng = np.random.default_rng(5)
    p_nom = cfg.capacity_j / 20_000.0  # empties in about 6 h
    flow = 0.0
    for demand in rng.normal(p_nom, p_nom, size=2000):
        pack.set_demand(float(demand))
        for _ in range(20):
            s = pack.step(0.1)
            flow += abs(s.drawn_j) + abs(s.delivered_j) + s.heat_j
    b = pack.books
    assert abs(b.drawn_j - b.delivered_j - b.heat_j - pack.capacitor_j) <= 1e-9 * flow
