"""The Monte Carlo prediction: with no noise every future is the composed twin's run; the
noise and the uncertainty it draws have the statistics the rover file gives them."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from common.config import Rover, load_rover
from common.faults import Dust, Heating, Stuck
from services.battery.circuit import solve_bus
from services.battery.packs import Packs
from services.battery.prediction import clipped_moments, percentiles, predict, start_of
from services.composed import ComposedTwin
from tests.harness import static_rover


def variant(name: str, **battery) -> Rover:
    """A shipped rover with every load's noise and the pack's uncertainty removed, and the
    battery fields in ``battery`` changed; ``tick_hz``, ``umbilical`` at the top level."""
    raw = msgspec.to_builtins(load_rover(static_rover(name)))  # parked without a drive: it drains
    for ld in raw["loads"]:
        ld["std_w"] = 0.0
    raw["battery"]["uncertainty"] = {}
    for key in ("tick_hz", "umbilical"):
        if key in battery:
            raw[key] = battery.pop(key)
    if "sun_angle_deg" in battery:
        raw["solar"]["sun_angle_deg"] = battery.pop("sun_angle_deg")
    raw["battery"].update(battery)
    return msgspec.convert(raw, Rover)


def twin_run(rover: Rover, ticks: int, setup=None) -> tuple[list[float], float, ComposedTwin]:
    """The composed twin's state of charge after every tick, when it first went empty, and
    the twin at the end."""
    twin = made(rover, setup)
    socs, empty = [], math.inf
    for n in range(1, ticks + 1):
        twin.step()
        socs.append(twin.battery.soc)
        if math.isinf(empty) and (twin.battery.depleted or twin.battery.uv_cutoff):
            empty = n * twin.dt_s
    return socs, empty, twin


def made(rover: Rover, setup=None) -> ComposedTwin:
    twin = ComposedTwin(rover, seed=0)
    if setup:
        setup(twin)
        twin.summary = twin._resolve()
    return twin


def rises_then_falls(socs: list[float]) -> bool:
    """Charged while cut off, then supplying again."""
    d = np.diff(socs)
    first_rise = int(np.argmax(d > 0.0))
    return bool(d[first_rise] > 0.0 and (d[first_rise:] < 0.0).any())


# name: (rover, ticks, what the twin shows at the end, set-up)
SCENARIOS = {
    "mapp: shedding, depletion, recovery": (
        variant("mapp.yaml", capacity_j=2e4), 5000,
        lambda t, socs: not t.battery.depleted and t.power.switches["5V_CH2"].shed, None),
    # the sun (72 W) holds the pack with both low rails shed but not with 5V_CH2 on:
    # 5V_CH2 sheds at 0.15, the pack charges to 0.20, it is restored, and again
    "mapp: shed and restore": (
        variant("mapp.yaml", capacity_j=5e3, initial_soc=0.3, sun_angle_deg=36.87), 4000,
        lambda t, socs: max(socs[len(socs) // 2:]) > 0.19 and min(socs) < 0.151, None),
    "reference cell: cut-off": (
        variant("bc18650.yaml", initial_soc=0.1), 4000, lambda t, socs: t.battery.uv_cutoff, None),
    "reference cell: cut-off and recovery": (
        variant("bc18650.yaml", initial_soc=0.01, umbilical={"connected": True, "power_w": 2.0}),
        6000, lambda t, socs: rises_then_falls(socs), None),
    "mapp: thermal cut-off": (
        variant("mapp.yaml"), 600, lambda t, socs: t.battery.thermal_cutoff,
        lambda t: t.set_faults("battery", None, [Heating(heat_w=3000.0)])),
    "mapp: trip, command, dust": (
        variant("mapp.yaml", capacity_j=1e4), 5000,
        lambda t, socs: t.power.switches["5V_CH1"].tripped and min(socs) == 0.0,
        lambda t: (t.set_faults("load", "uhf_radio", [Stuck(power_w=30.0)]),
                   t.power.command("3V3_CH2", on=False),
                   t.set_faults("solar", "left", [Dust(fraction=0.5)]))),
}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_without_noise_every_future_is_the_composed_twin_s_run(scenario):
    rover, ticks, shows, setup = SCENARIOS[scenario]
    socs, empty, end = twin_run(rover, ticks, setup)
    assert shows(end, socs), "the scenario must do what it is named for"
    for n in sorted({ticks // 7, ticks // 3, ticks // 2, ticks}):
        out = predict(start_of(made(rover, setup)), n / rover.tick_hz, samples=3, step_ticks=1,
                      seed=1)
        assert out.horizon_s == pytest.approx(n / rover.tick_hz)
        assert_allclose(out.soc_at_horizon, socs[n - 1], rtol=1e-9, atol=1e-12)
        want = empty if empty <= n / rover.tick_hz + 1e-9 else math.inf
        assert_allclose(out.time_to_empty_s, want, rtol=1e-12)


@pytest.mark.timeout(120)
def test_a_longer_step_is_the_twin_of_a_slower_clock():
    """Steps of k ticks with no noise: the composed twin of the same rover at tick_hz / k."""
    rover = variant("mapp.yaml", capacity_j=2e4)
    slow = msgspec.convert({**msgspec.to_builtins(rover), "tick_hz": 1.0}, Rover)
    socs, empty, _ = twin_run(slow, 400)
    out = predict(start_of(ComposedTwin(rover, seed=0)), 400.0, samples=2, step_ticks=10)
    assert out.step_s == 1.0
    assert_allclose(out.soc_at_horizon, socs[-1], rtol=1e-9)
    assert_allclose(out.time_to_empty_s, empty, rtol=1e-12)


def test_the_default_step_keeps_a_long_horizon_within_max_steps():
    rover = load_rover(static_rover("mapp.yaml"))
    out = predict(start_of(ComposedTwin(rover)), 8 * 3600.0, samples=2, seed=0)
    assert out.step_s == pytest.approx(2.9)  # 29 ticks: 8 h in 9931 steps
    assert out.horizon_s == pytest.approx(8 * 3600.0, abs=out.step_s)


def test_clipped_normal_moments_match_a_large_sample():
    # The mean and variance of clip(N(3, 2), 0, 4) by their closed forms, against 2e6 draws.
    rng = np.random.default_rng(0)
    x = np.clip(rng.normal(3.0, 2.0, 2_000_000), 0.0, 4.0)
    mean, var = clipped_moments(3.0, 2.0, 0.0, 4.0)
    assert_allclose(mean, x.mean(), rtol=2e-3)
    assert_allclose(var, x.var(), rtol=5e-3)
    assert clipped_moments(3.0, 0.0, 0.0, 2.5) == (2.5, 0.0)
    assert_allclose(clipped_moments(3.0, 1e-3, -np.inf, np.inf), (3.0, 1e-6), rtol=1e-9)


def test_percentiles_interpolate_and_say_none_where_not_reached():
    v = np.array([10.0, 20.0, 30.0, 40.0, np.inf])
    # positions 0.2, 2 and 3.8 of 0..4: 12, 30, and between 40 and inf: not reached
    assert percentiles(v) == {"p05": 12.0, "p50": 30.0, "p95": None}
    assert percentiles(np.full(4, np.inf)) == {"p05": None, "p50": None, "p95": None}


@pytest.mark.timeout(120)
def test_load_noise_spreads_the_futures_around_the_noiseless_one():
    """MAPP's loads with their noise: the futures spread, the noiseless run sits inside the
    spread, and a one-tick step (draws exactly as the loads service) and a 20-tick step
    (their per-rail mean) agree on the median and the spread."""
    base = msgspec.to_builtins(load_rover(static_rover("mapp.yaml")))
    base["battery"]["capacity_j"] = 2e4
    base["battery"]["uncertainty"] = {}
    rover = msgspec.convert(base, Rover)
    quiet = predict(start_of(ComposedTwin(variant("mapp.yaml", capacity_j=2e4))), 600.0, 1,
                    step_ticks=1)
    fine = predict(start_of(ComposedTwin(rover)), 600.0, 300, seed=2, step_ticks=1)
    coarse = predict(start_of(ComposedTwin(rover)), 600.0, 300, seed=3, step_ticks=20)
    for out in (fine, coarse):
        assert np.isfinite(out.time_to_empty_s).all()
        lo, mid, hi = np.percentile(out.time_to_empty_s, [5, 50, 95])
        assert lo < quiet.time_to_empty_s[0] < hi and hi > lo
    assert_allclose(np.median(fine.time_to_empty_s), np.median(coarse.time_to_empty_s), rtol=0.01)
    assert_allclose(np.std(fine.time_to_empty_s), np.std(coarse.time_to_empty_s), rtol=0.35)


def test_uncertainty_spreads_capacity_resistance_and_generation():
    """capacity_frac 0.05 alone: the time to empty spreads by about 5 % (it is nearly
    proportional to the capacity); none: every future is the same; the resistance and the
    generation spread it too."""
    def run(**unc) -> np.ndarray:
        raw = msgspec.to_builtins(variant("mapp.yaml", capacity_j=2e4))
        raw["battery"]["uncertainty"] = unc
        rover = msgspec.convert(raw, Rover)
        out = predict(start_of(ComposedTwin(rover)), 900.0, 400, seed=5, step_ticks=10)
        assert np.isfinite(out.time_to_empty_s).all()
        return out.time_to_empty_s
    none = run()
    assert np.ptp(none) == 0.0
    cap = run(capacity_frac=0.05)
    assert 0.035 < np.std(cap) / np.mean(cap) < 0.065
    assert np.std(run(resistance_frac=0.3)) > 0.0
    gen = run(generation_frac=0.05)
    assert 0.01 < np.std(gen) / np.mean(gen) < 0.1


def test_bad_arguments_are_refused():
    start = start_of(ComposedTwin(load_rover(static_rover("mapp.yaml"))))
    with pytest.raises(ValueError, match="horizon_s must be finite and > 0"):
        predict(start, 0.0, 10)
    with pytest.raises(ValueError, match="samples must be >= 1"):
        predict(start, 10.0, 0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(
    st.one_of(st.just(0.0), st.floats(-5.0, 500.0)),  # V_x
    st.one_of(st.just(0.0), st.floats(0.0, 2.0)),  # R0
    st.one_of(st.just(0.0), st.floats(-1e4, 1e5)),  # demand
), min_size=1, max_size=12))
def test_the_vectorised_bus_solution_is_the_scalar_one_to_the_bit(cases):
    """Every element of Packs.solve_bus equals circuit.solve_bus on the same numbers, in
    every branch: no source, no demand, no resistance, a brown-out, charging, and arrays that
    mix them."""
    v_x, r0, demand = (np.array(c) for c in zip(*cases, strict=True))
    voltage, current, brownout = Packs.solve_bus(v_x, r0, demand)
    for k, (v, r, p) in enumerate(cases):
        want = solve_bus(v, r, p)
        assert (voltage[k], current[k], bool(brownout[k])) == (
            want.voltage_v, want.current_a, want.brownout), (v, r, p)


TRAVERSE = """
traverse: {name: a short climb}
speed_m_per_s: 0.1
return_to_start: true
waypoints:
  - {x_m: 8, y_m: 6, z_m: 0.5}
  - {x_m: 12, y_m: 9, z_m: 2.5}
"""


def test_a_traverse_profile_without_noise_is_the_composed_twin_driving_it():
    """The drive load following a traverse, tick by tick, in every future: with no noise and
    no uncertainty, the state of charge where the composed twin arrives (it drives the same
    traverse, its drive coupled to the pack) is the prediction's, to a part in 10^4."""
    from common.traverse import parse_traverse
    from services.composed.budget import power_profile, run_traverse
    from tests.harness import ROVERS

    raw = msgspec.to_builtins(load_rover(ROVERS / "mapp.yaml"))
    for ld in raw["loads"]:
        ld["std_w"] = 0.0
    raw["battery"]["uncertainty"] = {}
    rover = msgspec.convert(raw, Rover)
    # a short traverse with a climb and a descent (4,000 ticks; the shipped crater rim's
    # 120,000 took 78 s of the unit tests to the same end)
    cmd = parse_traverse(TRAVERSE, "short.yaml", rover).command()
    ticks = power_profile(rover, cmd)
    budget = run_traverse(rover, cmd, 0.2, 4.0, 0)
    assert budget.outcome == "arrived"
    start = start_of(ComposedTwin(rover))._replace(profile=(rover.drive.load, tuple(ticks)))
    out = predict(start, len(ticks) / rover.tick_hz, 3, step_ticks=1)
    assert_allclose(out.soc_at_horizon, budget.final_soc, rtol=1e-4)
    parked = predict(start_of(ComposedTwin(rover)), len(ticks) / rover.tick_hz, 1, step_ticks=1)
    assert out.soc_at_horizon[0] < parked.soc_at_horizon[0] - 0.001  # the drive cost shows (0.0028)


def test_the_notes_say_what_every_prediction_assumes_and_a_spread_of_none():
    """Found by a vehicle engineer: a rover file without uncertainty gave p05 = p95 with
    nothing saying the spread was zero."""
    from common.config import parse_rover
    from services.battery.prediction import assumptions
    from testbed.twin import ROVERS

    text = (ROVERS / "mapp.yaml").read_text()
    held, spread = assumptions(parse_rover(text, "mapp"))
    assert held.startswith("held over the whole horizon: the sun and the generation as now")
    assert spread.startswith("each future draws its own capacity 3%, resistance 15%, generation 10%")
    cut = text[:text.index("  uncertainty:")] + text[text.index("  max_discharge_a:"):]
    assert assumptions(parse_rover(cut, "certain"))[1] == (
        "the rover file gives no battery.uncertainty: the futures differ by the loads' noise only")
