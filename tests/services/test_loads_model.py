"""Loads: noisy samples within bounds with the configured mean and spread; faults."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from common.config import load_rover
from common.faults import fault_of
from services.loads.model import LoadsModel, sample_power
from tests.harness import ROVERS


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


def test_faults_short_open_stuck(mapp):
    m = LoadsModel(mapp, seed=3)
    m.apply_fault(*fault_of("load/nav_camera/short", {"resistance_ohm": 0.05}))
    assert_allclose(m.power("nav_camera")[0], 5.0**2 / 0.05)  # V_rail^2 / R = 500 W
    m.apply_fault(*fault_of("load/drive_motors/stuck", {"power_w": 77.0}))
    assert m.power("drive_motors")[0] == 77.0
    m.apply_fault(*fault_of("load/imu/open", {}))
    assert m.power("imu")[0] == 0.0
    m.apply_fault(*fault_of("load/nav_camera/short"))
    m.sample()
    assert 0.0 <= m.power("nav_camera")[0] <= 5.0


def test_the_drive_load_draws_what_the_drive_sets_and_its_faults_still_win(mapp):
    m = LoadsModel(mapp, seed=3)
    m.sample()
    assert m.power("drive_motors") == (3.0, True)  # the drive's idle_w, not a sample
    assert m.set_driven("drive_motors", 9.5) and not m.set_driven("drive_motors", 9.5)
    assert not m.set_driven("nav_camera", 1.0)  # the drive owns only its load
    m.sample()
    assert m.power("drive_motors") == (9.5, True)
    m.apply_fault(*fault_of("load/drive_motors/stuck", {"power_w": 77.0}))
    assert m.power("drive_motors")[0] == 77.0
    m.apply_fault(*fault_of("load/drive_motors/short", {"resistance_ohm": 0.5}))
    assert_allclose(m.power("drive_motors")[0], 12.0**2 / 0.5)  # a short wins: 288 W
    m.set_rail("12V", False)
    assert m.power("drive_motors") == (0.0, False)
    m.reset_driven()
    assert m.driven_w == {"drive_motors": 3.0}
