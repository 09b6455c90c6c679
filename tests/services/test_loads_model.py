"""Loads: noisy samples within bounds with the configured mean and spread; faults; a fleet's
loads drawn together."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from common.config import load_rover
from common.faults import Dust, Open, Short, Stuck
from services.loads.model import LoadsFleet, LoadsModel, sample_power
from tests.harness import ROVERS, copies_of


@pytest.fixture
def mapp():
    return load_rover(ROVERS / "mapp.yaml")


def test_samples_stay_within_zero_and_max():
    rng = np.random.default_rng(0)
    nominal, std, max_w = np.array([1.0, 30.0]), np.array([5.0, 8.0]), np.array([2.0, 80.0])
    draws = np.array([sample_power(rng, nominal, std, max_w) for _ in range(20000)])
    assert draws.min() >= 0.0
    assert (draws[:, 0] <= 2.0).all() and (draws[:, 1] <= 80.0).all()
    # A wide spread around 1 W clipped to [0, 2] piles up on both bounds.
    assert (draws[:, 0] == 0.0).mean() > 0.3 and (draws[:, 0] == 2.0).mean() > 0.3


def test_samples_have_the_configured_mean_and_spread():
    # 30 W +- 8 W clipped to [0, 80]: the bounds are 3.75 and 6.25 sigma away, so clipping
    # moves neither the mean nor the spread measurably; with n = 50000 the standard error
    # of the mean is 8 / sqrt(50000) = 0.036 W.
    rng = np.random.default_rng(1)
    draws = np.array([sample_power(rng, np.array([30.0]), np.array([8.0]), np.array([80.0]))[0]
                      for _ in range(50000)])
    assert_allclose(draws.mean(), 30.0, atol=0.15)
    assert_allclose(draws.std(), 8.0, rtol=0.02)


def test_a_load_draws_nothing_while_its_rail_is_off(mapp):
    m = LoadsModel(mapp, seed=3)
    m.sample()
    assert m.power("nav_camera")[0] > 0.0
    m.set_rail("5V_CH2", False)
    assert m.power("nav_camera") == (0.0, False)
    assert m.power("hazard_cameras") == (0.0, False)
    assert m.power("flight_computer")[1] is True


def test_an_open_load_on_a_rail_off_at_the_fault_draws_nothing_once_the_rail_is_on(mapp):
    """What the crew's symptom of an open load rests on (common.response): on a dead rail it
    says 0 W and off, as every load there; once the rail is on, 0 W and on."""
    m = LoadsModel(mapp, seed=3)
    m.set_rail("5V_CH2", False)
    m.set_faults("nav_camera", [Open()])
    m.sample()
    assert m.power("nav_camera") == (0.0, False)
    assert m.set_rail("5V_CH2", True)
    assert m.power("nav_camera") == (0.0, True) and m.power("hazard_cameras")[0] > 0.0
    assert ("nav_camera", 0.0, "5V_CH2", True) in m.powers()


def test_faults_short_open_stuck(mapp):
    m = LoadsModel(mapp, seed=3)
    m.set_faults("nav_camera", [Short(resistance_ohm=0.05)])
    assert_allclose(m.power("nav_camera")[0], 5.0**2 / 0.05)  # V_rail^2 / R = 500 W
    assert m.alarms("nav_camera", 500.0) == ["over_current"]  # above its max_w of 5 W
    m.set_faults("drive_motors", [Stuck(power_w=77.0)])
    assert m.power("drive_motors")[0] == 77.0 and m.alarms("drive_motors", 77.0) == []  # max 90 W
    m.set_faults("imu", [Open()])
    assert m.power("imu")[0] == 0.0 and m.alarms("imu", 0.0) == []
    assert not m.supplied("imu") and not m.supplied("nav_camera") and m.supplied("drive_motors")
    m.set_faults("nav_camera", [])
    m.sample()
    assert 0.0 <= m.power("nav_camera")[0] <= 5.0 and m.supplied("nav_camera")
    # several on one load: a short, then an open circuit, then stuck; whatever their order
    m.set_faults("imu", [Stuck(power_w=1.2), Open()])
    assert m.power("imu")[0] == 0.0
    m.set_faults("imu", [Stuck(power_w=1.2), Short(resistance_ohm=3.3), Open()])
    assert_allclose(m.power("imu")[0], 3.3**2 / 3.3)  # 3.3 W on the 3.3 V rail
    with pytest.raises(ValueError, match="a load has no fault kind 'dust'"):
        m.set_faults("imu", [Dust(fraction=0.1)])
    with pytest.raises(ValueError, match="no load 'wheel'"):
        m.set_faults("wheel", [])


def test_the_drive_load_draws_what_the_drive_sets_and_its_faults_still_win(mapp):
    m = LoadsModel(mapp, seed=3)
    m.sample()
    assert m.power("drive_motors") == (3.0, True)  # the drive's idle_w, not a sample
    assert m.set_driven("drive_motors", 9.5) and not m.set_driven("drive_motors", 9.5)
    assert not m.set_driven("nav_camera", 1.0)  # the drive owns only its load
    m.sample()
    assert m.power("drive_motors") == (9.5, True)
    m.set_faults("drive_motors", [Stuck(power_w=77.0)])
    assert m.power("drive_motors")[0] == 77.0
    m.set_faults("drive_motors", [Stuck(power_w=77.0), Short(resistance_ohm=0.5)])
    assert_allclose(m.power("drive_motors")[0], 12.0**2 / 0.5)  # a short wins: 288 W
    m.set_rail("12V", False)
    assert m.power("drive_motors") == (0.0, False)
    m.reset_driven()
    assert m.driven_w == {"drive_motors": 3.0}


def test_a_fleet_draws_every_load_of_every_rover_in_one_block(mapp):
    fleet = LoadsFleet(copies_of(mapp, 3), seed=5, block_ticks=4)
    for _ in range(4):  # 3 rovers x 4 ticks: the rows of one block
        for rover in ("r0", "r1", "r2"):
            fleet.sample(rover)
    assert fleet.draws == 1
    fleet.sample("r1")  # r1 has used its rows: a new block for all
    assert fleet.draws == 2
    for _ in range(3):
        fleet.sample("r0")
    assert fleet.draws == 2  # r0 starts afresh in the new block: 4 rows of it
    fleet.sample("r0")
    fleet.sample("r0")
    assert fleet.draws == 3


def test_a_fleets_samples_are_the_block_drawn_for_all_its_loads(mapp):
    # The same numbers as sample_power draws for the 3 x 10 loads side by side, 2 ticks at once.
    fleet = LoadsFleet(copies_of(mapp, 3), seed=5, block_ticks=2)
    n = len(mapp.loads)
    expected = sample_power(np.random.default_rng(5), np.tile(fleet.models["r0"].nominal_w, 3),
                            np.tile(fleet.models["r0"].std_w, 3),
                            np.tile(fleet.models["r0"].max_w, 3), ticks=2)
    for row in range(2):
        for k, rover in enumerate(("r0", "r1", "r2")):
            fleet.sample(rover)
            assert_allclose(fleet.models[rover].sampled_w, expected[row, k * n:(k + 1) * n],
                            rtol=0, atol=0)
    # ... so two copies of one rover do not draw the same noise (one generator per rover
    # seeded alike would)
    assert (fleet.models["r0"].sampled_w != fleet.models["r1"].sampled_w).any()


def test_a_fleets_loads_have_their_nominal_power_without_spread(mapp):
    # std_w 0: each sample is nominal_w (the drive's motors at 40 W; every load under its max).
    fleet = LoadsFleet(copies_of(mapp, 2, std_w=0.0), seed=1)
    for _ in range(40):  # across blocks of 16
        fleet.sample("r0")
    assert fleet.draws == 3
    assert fleet.models["r0"].sampled_w.tolist() == [ld.nominal_w for ld in mapp.loads]
    # one over its max is clipped to it: 7 W at most 5 W
    clipped = copies_of(mapp, 1, std_w=0.0, nominal_w=7.0, max_w=5.0)
    one = LoadsFleet(clipped, seed=1)
    one.sample("r0")
    assert one.models["r0"].sampled_w.tolist() == [5.0] * len(mapp.loads)


def test_a_fleets_samples_have_the_configured_mean_and_spread(mapp):
    # As for one load above: 30 W +- 8 W within [0, 80] for every load of 4 rovers, 2,500
    # ticks each (interleaved): 10,000 samples per load position, standard error 0.08 W.
    fleet = LoadsFleet(copies_of(mapp, 4, nominal_w=30.0, std_w=8.0, max_w=80.0), seed=2)
    draws = []
    for _ in range(2500):
        for rover in ("r0", "r1", "r2", "r3"):
            fleet.sample(rover)
            draws.append(fleet.models[rover].sampled_w.copy())
    d = np.array(draws)
    assert_allclose(d.mean(axis=0), 30.0, atol=0.35)
    assert_allclose(d.std(axis=0), 8.0, rtol=0.04)


def test_a_fleets_rovers_keep_their_own_rails_faults_and_drive(mapp):
    fleet = LoadsFleet(copies_of(mapp, 2, std_w=0.0), seed=1)
    a, b = fleet.models["r0"], fleet.models["r1"]
    fleet.sample("r0")
    fleet.sample("r1")
    b.set_faults("nav_camera", [Short(resistance_ohm=0.05)])
    b.set_rail("3V3_CH1", False)
    b.set_driven("drive_motors", 9.5)
    assert_allclose(b.power("nav_camera")[0], 5.0**2 / 0.05)  # 500 W
    assert a.power("nav_camera") == (3.5, True)
    assert b.power("imu") == (0.0, False) and a.power("imu") == (1.0, True)
    assert b.power("drive_motors") == (9.5, True) and a.power("drive_motors") == (3.0, True)


def test_powers_is_power_of_each_load(mapp):
    m = LoadsModel(mapp, seed=4)
    m.sample()
    m.set_faults("nav_camera", [Short(resistance_ohm=0.05)])
    m.set_faults("imu", [Open()])
    m.set_faults("uhf_radio", [Stuck(power_w=7.0)])
    m.set_rail("3V3_CH2", False)
    m.set_driven("drive_motors", 12.5)
    assert m.powers() == [(name, *m.power(name)[:1], rail, m.power(name)[1])
                          for name, rail in zip(m.names, m.rails, strict=True)]
    assert dict((n, p) for n, p, _, _ in m.powers())["uhf_radio"] == 7.0
