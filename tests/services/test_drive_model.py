"""The drive model against numbers derived by hand (SPEC §4, Drive).

The reference rover of these tests: m = 10 kg, r = 0.1 m, c_rr = 0.1, eta = 0.5, idle 2 W,
g = 1.625 m/s^2, so m g = 16.25 N; cos 10 deg = 0.98480775, sin 10 deg = 0.17364818.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from common.config import Drive, DriveStart, Radio, RadioSite
from common.faults import Open, Short, Stuck, supplies_device
from common.messages import DriveTraverse, TraverseWaypoint
from common.traverse import Leg, plan
from services.drive.model import (
    DriveModel,
    capped_speed,
    drive_power_w,
    leg_energy_j,
    tractive_force_n,
)
from services.radio.model import RadioModel, relative_to_site

TEN = math.radians(10.0)
REF = Drive(load="drive_motors", mass_kg=10.0, wheel_radius_m=0.1, rolling_resistance=0.1,
            drivetrain_efficiency=0.5, idle_w=2.0, max_speed_m_per_s=0.2, gravity_m_per_s2=1.625)


def model(cfg: Drive = REF, max_w: float = 90.0) -> DriveModel:
    return DriveModel(cfg, max_w)


def legs_of(*points: tuple[float, float, float], speed: float = 0.1,
            start: tuple[float, float, float] = (0.0, 0.0, 0.0), cfg: Drive = REF) -> list[Leg]:
    legs, problems = plan(DriveTraverse([TraverseWaypoint(*p) for p in points], speed), cfg, start)
    assert problems == []
    return legs


def run(m: DriveModel, seconds: float, dt: float = 0.5) -> None:
    for _ in range(round(seconds / dt)):
        m.step(dt)


# -- force, torque, power ------------------------------------------------------------------------


def test_flat_uphill_and_downhill_force_torque_and_power():
    # flat: F = 16.25 * 0.1 = 1.625 N; torque F r = 0.1625 N m; P = 1.625 * 0.1 / 0.5 + 2 = 2.325 W
    assert tractive_force_n(10, 1.625, 0.1, 0.0) == pytest.approx(1.625)
    assert drive_power_w(1.625, 0.1, 0.5, 2.0) == pytest.approx(2.325)
    # 10 deg up: F = 16.25 (0.1 * 0.98480775 + 0.17364818) = 16.25 * 0.27212896 = 4.4220955 N;
    # F v = 0.44220955 W, P = 0.8844191 + 2 = 2.8844191 W
    up = tractive_force_n(10, 1.625, 0.1, TEN)
    assert up == pytest.approx(4.4220955, rel=1e-7)
    assert drive_power_w(up, 0.1, 0.5, 2.0) == pytest.approx(2.8844191, rel=1e-7)
    # 10 deg down: F = 16.25 (0.098480775 - 0.17364818) = -1.2214703 N: braking, so idle only,
    # or 2 - 0.12214703 * 0.5 = 1.9389265 W with half of it regenerated
    down = tractive_force_n(10, 1.625, 0.1, -TEN)
    assert down == pytest.approx(-1.2214703, rel=1e-7)
    assert drive_power_w(down, 0.1, 0.5, 2.0) == 2.0
    assert drive_power_w(down, 0.1, 0.5, 2.0, regen_efficiency=0.5) == pytest.approx(1.9389265)
    # 5 deg down, gentler than atan(c_rr) = 5.71 deg: still pulling,
    # F = 16.25 (0.0996195 - 0.0871557) = 0.2025367 N, P = 0.02025367 / 0.5 + 2 = 2.0405073 W
    gentle = tractive_force_n(10, 1.625, 0.1, math.radians(-5.0))
    assert drive_power_w(gentle, 0.1, 0.5, 2.0) == pytest.approx(2.0405073, rel=1e-7)
    # an acceleration adds m a: 10 kg * 0.2 m/s^2 = 2 N
    assert tractive_force_n(10, 1.625, 0.1, 0.0, 0.2) == pytest.approx(3.625)


def test_the_model_reports_force_torque_and_power_of_the_leg_it_drives():
    m = model()
    rise = 10.0 * math.tan(TEN)  # 10 m north, 1.7632698 m up: a 10 deg leg
    m.start(legs_of((0.0, 10.0, rise)))
    r = m.reading()
    assert r.grade_deg == pytest.approx(10.0) and r.heading_deg == pytest.approx(0.0)
    assert r.tractive_force_n == pytest.approx(4.4220955, rel=1e-7)
    assert r.wheel_torque_nm == pytest.approx(0.44220955, rel=1e-7)  # F r, r = 0.1 m
    assert r.power_w == pytest.approx(2.8844191, rel=1e-7)
    assert r.speed_m_per_s == 0.1 and r.moving and r.status == "driving" and r.waypoint == 0


def test_the_power_cap_slows_the_rover():
    # max_w 2.5 W on the 10 deg leg: 2.884 W > 2.5 W, so v = (2.5 - 2) * 0.5 / 4.4220955
    # = 0.0565343 m/s and the drive draws exactly 2.5 W
    assert capped_speed(4.4220955, 0.1, 0.5, 2.0, 2.5) == pytest.approx(0.0565343, rel=1e-6)
    assert capped_speed(1.625, 0.1, 0.5, 2.0, 2.5) == 0.1  # flat: 2.325 W fits
    assert capped_speed(-1.0, 0.1, 0.5, 2.0, 2.5) == 0.1  # downhill is never capped
    m = model(max_w=2.5)
    m.start(legs_of((0.0, 10.0, 10.0 * math.tan(TEN))))
    r = m.reading()
    assert r.status == "power_limited" and r.moving
    assert r.speed_m_per_s == pytest.approx(0.0565343, rel=1e-6)
    assert r.power_w == pytest.approx(2.5)
    run(m, 10.0)
    assert m.reading().odometer_m == pytest.approx(0.565343, rel=1e-6)  # 10 s at the capped speed


# -- position, waypoints, energy ----------------------------------------------------------------


def square_course() -> list[Leg]:
    """From (0, 0, 0): 5 m flat to (3, 4, 0), heading 36.87 deg (atan2(3, 4)); then 10 m north
    and 1.7632698 m up, a 10 deg leg 10 / cos 10 deg = 10.1542661 m long."""
    return legs_of((3.0, 4.0, 0.0), (3.0, 14.0, 10.0 * math.tan(TEN)))


def test_position_along_the_legs_and_arrival_at_each_waypoint():
    m = model()
    m.start(square_course())
    run(m, 30.0)  # 3 m of the 5 m leg: 0.6 of (3, 4)
    r = m.reading()
    assert (r.x_m, r.y_m, r.z_m) == pytest.approx((1.8, 2.4, 0.0))
    assert r.heading_deg == pytest.approx(36.869898) and r.grade_deg == 0.0
    assert r.odometer_m == pytest.approx(3.0) and r.remaining_m == pytest.approx(2.0 + 10.1542661)
    run(m, 30.0)  # 50 s to the first waypoint, then 10 s = 1 m up the slope
    r = m.reading()
    assert r.waypoint == 1 and r.heading_deg == pytest.approx(0.0) and r.grade_deg == pytest.approx(10.0)
    assert (r.x_m, r.y_m, r.z_m) == pytest.approx((3.0, 4.0 + 0.98480775, 0.17364818))
    # the second leg takes 101.542661 s: at 151.542661 s the rover arrives and stops
    run(m, 91.5)
    assert m.reading().status == "driving"
    run(m, 0.5)
    r = m.reading()
    assert r.status == "arrived" and not r.moving and r.waypoint is None and r.speed_m_per_s == 0.0
    assert (r.x_m, r.y_m, r.z_m) == (3.0, 14.0, 10.0 * math.tan(TEN))
    assert r.odometer_m == pytest.approx(15.1542661) and r.power_w == 2.0
    assert r.tractive_force_n == 0.0 and r.remaining_m == 0.0


def test_a_step_that_passes_a_waypoint_turns_within_the_step():
    m = model()
    m.start(square_course())
    m.step(55.0)  # 50 s to (3, 4, 0), then 5 s = 0.5 m up the 10 deg leg
    r = m.reading()
    assert (r.x_m, r.y_m, r.z_m) == pytest.approx((3.0, 4.0 + 0.5 * 0.98480775, 0.5 * 0.17364818))
    assert r.odometer_m == pytest.approx(5.5)


def test_the_energy_of_a_leg_is_f_d_over_eta_plus_idle_t():
    # the 10 deg leg: F d / eta = 4.4220955 * 10.1542661 / 0.5 = 89.806268 J; t = d / v
    # = 101.542661 s at idle 2 W = 203.085322 J; 292.891590 J in all
    assert leg_energy_j(4.4220955, 10.1542661, 0.1, 0.5, 2.0) == pytest.approx(292.891590, rel=1e-6)
    m = model()
    m.start(square_course())
    run(m, 50.0)
    at_waypoint = m.energy_j
    assert at_waypoint == pytest.approx(1.625 * 5.0 / 0.5 + 2.0 * 50.0)  # the flat leg: 116.25 J
    run(m, 101.5)
    m.step(1.0)  # arrives 0.042661 s into this step, then idles for the rest of it
    assert m.energy_j - at_waypoint == pytest.approx(292.891590 + 2.0 * (1.0 - 0.042661), rel=1e-6)


def test_a_return_to_start_comes_back_over_the_same_legs():
    legs, problems = plan(DriveTraverse([TraverseWaypoint(3.0, 4.0, 0.0),
                                         TraverseWaypoint(3.0, 14.0, 1.0, speed_m_per_s=0.05)],
                                        0.1, return_to_start=True), REF, (0.0, 0.0, 0.0))
    assert problems == []
    assert [(leg.x_m, leg.y_m, leg.z_m, leg.speed_m_per_s, leg.waypoint) for leg in legs] == [
        (3.0, 4.0, 0.0, 0.1, 0), (3.0, 14.0, 1.0, 0.05, 1), (3.0, 4.0, 0.0, 0.05, 2),
        (0.0, 0.0, 0.0, 0.1, 3)]


def test_a_stop_halts_where_it_is_and_idles():
    m = model()
    m.start(square_course())
    run(m, 10.0)
    assert m.stop() and not m.stop()  # nothing left to stop the second time
    r = m.reading()
    assert r.status == "parked" and r.waypoint is None and not r.moving and r.power_w == 2.0
    assert (r.x_m, r.y_m) == pytest.approx((0.6, 0.8))
    e = m.energy_j
    run(m, 10.0)
    assert m.reading().x_m == pytest.approx(0.6) and m.energy_j == pytest.approx(e + 20.0)


def test_without_power_the_rover_halts_and_resumes():
    m = model()
    m.start(square_course())
    run(m, 10.0)
    assert m.set_powered(False) and not m.set_powered(False)
    assert supplies_device(True, []) and supplies_device(True, [Stuck(power_w=1.0)])
    assert not supplies_device(False, []) and not supplies_device(True, [Short()])
    assert not supplies_device(True, [Stuck(power_w=1.0), Open()])
    e = m.energy_j
    run(m, 20.0)
    r = m.reading()
    assert r.status == "unpowered" and not r.moving and r.odometer_m == pytest.approx(1.0)
    assert m.energy_j == e  # an unpowered load draws nothing
    m.set_powered(True)
    run(m, 10.0)
    assert m.reading().odometer_m == pytest.approx(2.0) and m.reading().status == "driving"


def test_reset_and_state_round_trip():
    cfg = Drive(**{**{f: getattr(REF, f) for f in REF.__struct_fields__},
                   "start": DriveStart(x_m=1.0, y_m=2.0, z_m=3.0, heading_deg=450.0)})
    m = model(cfg)
    r = m.reading()
    assert (r.x_m, r.y_m, r.z_m, r.heading_deg, r.status) == (1.0, 2.0, 3.0, 90.0, "parked")
    m.start(legs_of((1.0, 12.0, 3.0), start=(1.0, 2.0, 3.0), cfg=cfg))
    run(m, 30.0)
    copy = model(cfg)
    copy.set_state(m.state())
    assert copy.reading() == pytest.approx(m.reading(), abs=1e-9)  # remaining_m: recomputed
    run(m, 100.0)
    copy.set_state(m.state())
    assert copy.reading() == m.reading() and copy.reading().status == "arrived"
    m.reset()
    assert m.reading() == model(cfg).reading()


def test_a_repeated_waypoint_is_reached_at_once():
    m = model()
    m.start(legs_of((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
    r = m.reading()
    assert r.waypoint == 1 and r.remaining_m == pytest.approx(1.0)
    m.start(legs_of((0.0, 0.0, 0.0)))
    assert m.reading().status == "arrived"


# -- the radio follows the rover ------------------------------------------------------------------


def test_the_point_where_the_radio_goes_out_of_range():
    # A lander radio at the site origin, footprint 400 m east-west by 250 m north-south. From
    # (5, 0) east along the x axis the rover leaves it at x = 400 m: 395 m at 0.1 m/s, 3950 s.
    radio = RadioModel(Radio(name="lander", a_m=400, b_m=250, site=RadioSite(x_m=0, y_m=0)))
    m = model()
    m.x_m = 5.0
    m.start(legs_of((600.0, 0.0, 0.0), start=(5.0, 0.0, 0.0)))
    t = 0.0
    while radio.link().in_range:
        m.step(1.0)
        t += 1.0
        radio.set_position(*relative_to_site(0.0, 0.0, m.x_m, m.y_m))
    assert 3950.0 <= t <= 3951.0  # the whole second at or just past 3950 s
    assert 400.0 < radio.link().x_m <= 400.1
    # north-east, the footprint ends where (x / 400)^2 + (y / 250)^2 = 1 on the diagonal:
    # x = y = 1 / sqrt(1/400^2 + 1/250^2) = 212.0 m, 299.8 m from the radio
    d, angle = relative_to_site(0.0, 0.0, 212.0, 212.0)
    assert (d, angle) == pytest.approx((299.81, 45.0), abs=0.01)
    radio.set_position(d - 0.1, angle)
    assert radio.link().in_range
    radio.set_position(d + 0.1, angle)
    assert not radio.link().in_range


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-2, 2)), min_size=1,
                max_size=6), st.floats(0.01, 0.2), st.floats(0.05, 3.0))
def test_any_traverse_ends_at_its_last_waypoint_with_consistent_books(points, speed, dt):
    m = model(REF.__class__(**{**{f: getattr(REF, f) for f in REF.__struct_fields__},
                              "max_grade_deg": 89.0}))
    legs, problems = plan(DriveTraverse([TraverseWaypoint(*p) for p in points], speed),
                          m.cfg, (0.0, 0.0, 0.0))
    assume(not problems)  # a vertical leg is refused
    m.start(legs)
    total = m.reading().remaining_m
    for _ in range(int(total / speed / dt) + 100):  # never capped: 90 W is far above the need
        if m.reading().status == "arrived":
            break
        before = m.reading()
        m.step(dt)
        after = m.reading()
        assert after.odometer_m - before.odometer_m <= speed * dt + 1e-9
        assert after.remaining_m <= before.remaining_m + 1e-9
        assert after.power_w >= 0.0 and math.isfinite(after.power_w)
    r = m.reading()
    assert r.status == "arrived" and (r.x_m, r.y_m, r.z_m) == points[-1]
    assert r.odometer_m == pytest.approx(total, abs=1e-6)
