"""Solar panels, the radio ellipse and the clock against numbers derived by hand."""

from __future__ import annotations

import math

import msgspec
import pytest
from numpy.testing import assert_allclose

from common.config import Radio, Rover, load_rover
from common.faults import Degraded, Disconnect, Dust, Failure, Short
from services.clock.model import ClockModel
from services.radio.model import RadioModel, in_range, position_xy
from services.solar.model import SolarModel, panel_power
from tests.harness import ROVERS


@pytest.mark.parametrize(("angle", "dust", "degradation", "expected"), [
    (0.0, 0.0, 0.0, 1361 * 0.12 * 0.29),                    # 47.3628 W facing the sun
    (60.0, 0.0, 0.0, 1361 * 0.12 * 0.29 * 0.5),             # cos 60 = 1/2
    (60.0, 0.3, 0.0, 1361 * 0.12 * 0.29 * 0.5 * 0.7),       # dust 0.3 cuts 30 %
    (35.0, 0.0, 0.1, 1361 * 0.12 * 0.29 * math.cos(math.radians(35)) * 0.9),
    (-60.0, 0.0, 0.0, 1361 * 0.12 * 0.29 * 0.5),            # symmetric
    (120.0, 0.0, 0.0, 0.0),                                 # sun behind the panel
    (180.0, 0.0, 0.0, 0.0),
])
def test_panel_power_formula(angle, dust, degradation, expected):
    assert_allclose(panel_power(1361, 0.12, 0.29, angle, dust, degradation), expected,
                    rtol=1e-12, atol=1e-12)


def test_panel_faults_and_umbilical():
    m = SolarModel(load_rover(ROVERS / "mapp.yaml"))
    m.set_panel_faults("left", [Dust(fraction=0.3)])
    m.set_panel_faults("right", [Disconnect()])
    panels = {name: (p, dust) for name, p, dust in m.panels()}
    assert_allclose(panels["left"][0], 1361 * 0.12 * 0.29 * 0.5 * 0.7)
    assert panels["left"][1] == 0.0  # the environment's dust: a dust fault shows as less power
    assert panels["right"] == (0.0, 0.0)
    assert (m.umbilical_connected, m.umbilical_power_w) == (False, 0.0)
    m.plug(True)
    assert m.umbilical_power_w == 120.0
    m.set_umbilical_faults([Disconnect()])
    assert m.umbilical_power_w == 0.0 and m.umbilical_plugged  # no supply, still plugged in
    m.set_umbilical_faults([])
    assert m.umbilical_power_w == 120.0
    m.set_panel_faults("left", [Dust(fraction=0.0)])  # in effect, and changes nothing
    assert_allclose(m.panels()[0][1], 1361 * 0.12 * 0.29 * 0.5)
    with pytest.raises(ValueError, match="a panel has no fault kind 'short'"):
        m.set_panel_faults("left", [Short()])
    with pytest.raises(ValueError, match="the umbilical has no fault kind 'dust'"):
        m.set_umbilical_faults([Dust(fraction=0.1)])


# Ellipse a = 400, b = 250 centred at (100, -50).
@pytest.mark.parametrize(("x", "y", "inside"), [
    (100.0, -50.0, True),          # centre
    (500.0, -50.0, True),          # on the end of the major axis
    (100.0, 200.0, True),          # on the end of the minor axis
    (100.0, -300.0, True),
    (500.0001, -50.0, False),      # just outside
    (0.0, 0.0, True),              # the radio itself: (-100/400)^2 + (50/250)^2 = 0.1025
    (400.0, 150.0, False),         # (300/400)^2 + (200/250)^2 = 1.2025
    (-300.0, -50.0, True),         # on the far end
])
def test_points_inside_on_and_outside_an_offset_ellipse(x, y, inside):
    assert in_range(x, y, 400.0, 250.0, 100.0, -50.0) is inside


def test_position_from_distance_and_angle():
    assert_allclose(position_xy(200.0, 90.0), (0.0, 200.0), atol=1e-12)
    assert_allclose(position_xy(200.0, 30.0), (200 * math.sqrt(3) / 2, 100.0), rtol=1e-12)


def test_radio_faults():
    m = RadioModel(Radio(name="lander", a_m=400, b_m=250, offset_x_m=100, offset_y_m=0))
    m.distance_m, m.angle_deg = 450.0, 0.0      # ((450 - 100) / 400)^2 = 0.766: in range
    assert m.link().in_range
    m.set_faults([Degraded(range_scale=0.5)])  # ((350) / 200)^2 = 3.06: out
    assert not m.link().in_range
    m.set_faults([Degraded(range_scale=0.0)])  # zero size holds nothing
    m.distance_m = 100.0
    assert not m.link().in_range
    m.set_faults([Failure()])
    assert not m.link().in_range
    m.set_faults([])
    assert m.link().in_range and m.alarms() == []  # a failure is no alarm: the link is lost


def test_clock_ticks_scales_and_pauses():
    c = ClockModel(10.0)
    assert c.tick().dt_s == pytest.approx(0.1)
    c.set_scale(20.0)
    t = c.tick()
    assert (t.dt_s, t.seq) == (pytest.approx(2.0), 2)
    c.paused = True
    t = c.tick()
    assert t.dt_s == 0.0 and t.t_s == pytest.approx(2.1) and t.paused
    with pytest.raises(ValueError, match="time_scale must be > 0"):
        c.set_scale(0.0)


def test_dust_as_an_input_is_a_second_layer_over_the_dust_fault():
    m = SolarModel(load_rover(ROVERS / "mapp.yaml"))
    clean = {name: p for name, p, _ in m.panels()}["left"]
    m.set_input_dust("left", 0.5)
    (name, power, dust), _ = m.panels()
    assert (name, dust) == ("left", 0.5)  # exact with one layer
    assert_allclose(power, clean * 0.5)
    m.set_panel_faults("left", [Dust(fraction=0.3)])
    _, power, dust = m.panels()[0]
    assert dust == 0.5  # the environment's, the input: never the fault's
    assert_allclose(power, clean * 0.7 * 0.5)  # 1 - (1 - 0.3)(1 - 0.5) = 0.65 of it gone
    assert m.state()["input_dust"] == {"left": 0.5}  # kept across a restart
    m.set_input_dust("left", None)
    assert m.panels()[0][2] == 0.0
    assert_allclose(m.panels()[0][1], clean * 0.7)
    with pytest.raises(ValueError, match="no panel 'wing'"):
        m.set_input_dust("wing", 0.1)


# -- the parts agree (SPEC §12e) ------------------------------------------------------------


def test_a_radio_without_power_is_out_of_range_whatever_the_distance():
    m = RadioModel(Radio(name="lander", a_m=400, b_m=250, load="uhf_radio"))
    m.set_position(10.0, 0.0)  # (10 / 400)^2 = 0.000625: deep inside
    assert m.link().in_range and m.alarms() == []
    assert m.set_powered(False) and not m.set_powered(False)
    assert not m.link().in_range and m.alarms() == ["unpowered"]
    assert m.link().x_m == pytest.approx(10.0)  # the position is still known
    assert m.set_powered(True) and m.link().in_range and m.alarms() == []


def cabled(cable_m: float | None, follows: bool = False) -> SolarModel:
    """The MAPP (drive start (5, 0, 0)) with an umbilical of ``cable_m``, plugged in at the start."""
    raw = msgspec.to_builtins(load_rover(ROVERS / "mapp.yaml"))
    raw["umbilical"] = {"connected": True, "power_w": 120.0, "cable_m": cable_m,
                        "follows_rover": follows}
    return SolarModel(msgspec.convert(raw, Rover))


def test_a_rover_that_drives_past_its_cable_pulls_the_umbilical_out():
    m = cabled(10.0, follows=True)
    assert m.umbilical_plugged and m.plugged_at_m == (5.0, 0.0, 0.0)
    # (5, 0, 0) -> (11, 8, 0): sqrt(6^2 + 8^2) = 10.0 m, on the cable's reach: still plugged
    assert m.move_rover(11.0, 8.0, 0.0) is None and m.umbilical_power_w == 120.0
    # (5, 0, 0) -> (11, 8, 0.5): sqrt(100 + 0.25) = 10.0125 m: pulled out
    assert m.move_rover(11.0, 8.0, 0.5) == pytest.approx(math.sqrt(100.25))
    assert not m.umbilical_plugged and m.umbilical_power_w == 0.0 and m.plugged_at_m is None
    assert m.move_rover(50.0, 0.0, 0.0) is None  # unplugged: nothing more to pull out
    m.plug(True)  # plugged in again where the rover is now: (50, 0, 0)
    assert m.plugged_at_m == (50.0, 0.0, 0.0) and m.move_rover(45.0, 0.0, 0.0) is None
    assert m.move_rover(39.0, 0.0, 0.0) == pytest.approx(11.0)


def test_without_a_cable_length_any_move_pulls_it_out_and_state_keeps_the_plug():
    m = cabled(None)
    assert m.cable_m == 0.0 and m.move_rover(5.0, 0.0, 0.0) is None  # parked where plugged
    saved = m.state()
    assert saved["plugged_at_m"] == [5.0, 0.0, 0.0]
    assert m.move_rover(5.0, 0.001, 0.0) == pytest.approx(0.001) and not m.umbilical_plugged
    m.set_state(saved)  # a snapshot restored: plugged in where it was
    assert m.umbilical_plugged and m.plugged_at_m == (5.0, 0.0, 0.0)
    m.reset()  # the rover file: plugged in at the drive's start
    assert m.umbilical_plugged and m.plugged_at_m == (5.0, 0.0, 0.0)


# -- what a map draws (issue 26.3) -------------------------------------------------------------


def test_the_radio_footprint_is_the_rover_files_whatever_the_faults():
    # The crew reads the footprint: a degradation must show only as a link lost sooner.
    m = RadioModel(Radio(name="lander", a_m=400, b_m=250, offset_x_m=100, offset_y_m=-20))
    assert m.footprint == (400.0, 250.0, 100.0, -20.0)
    m.set_position(450.0, 0.0)
    m.set_faults([Degraded(range_scale=0.5)])
    assert not m.link().in_range  # ((450 - 100) / 200)^2 = 3.06: the scaled ellipse is applied
    assert m.footprint == (400.0, 250.0, 100.0, -20.0)
    m.set_faults([Failure()])
    assert m.footprint._asdict() == {"a_m": 400.0, "b_m": 250.0, "offset_x_m": 100.0,
                                     "offset_y_m": -20.0}


def test_where_the_umbilical_was_plugged_in_reads_as_connected_does():
    m = cabled(10.0, follows=True)
    assert m.umbilical_cfg.cable_m == 10.0 and m.umbilical_plugged_at == (5.0, 0.0, 0.0)
    # a disconnect fault cuts the supply: the cable reads as unplugged, as connected does, so
    # the crew cannot tell the fault from a plug pulled out
    m.set_umbilical_faults([Disconnect()])
    assert not m.umbilical_connected and m.umbilical_plugged_at is None
    m.set_umbilical_faults([])
    assert m.umbilical_plugged_at == (5.0, 0.0, 0.0)
    m.move_rover(8.0, 4.0, 0.0)  # 5 m away: still plugged in where it was
    assert m.umbilical_plugged_at == (5.0, 0.0, 0.0)
    m.move_rover(20.0, 0.0, 0.0)  # 15 m: pulled out
    assert m.umbilical_plugged_at is None
    m.plug(True)
    assert m.umbilical_plugged_at == (20.0, 0.0, 0.0)
    assert cabled(None).umbilical_cfg.cable_m is None  # no slack: null, not 0


def test_sessions_begun_in_a_burst_keep_the_wall_clocks_second_and_never_collide():
    """Found by an adversary: 100 session switches in a burst gave ids 89 s ahead of the wall
    clock (one second later each). Within one second they are counted (.001, .002 ...), sort in
    the order they began, and the next second's id sorts after them all."""
    from services.clock.model import session_id
    wall = 1736884392.7  # 2025-01-14 19:53:12.7 UTC
    ids = [session_id(wall)]
    for _ in range(99):
        ids.append(session_id(wall + 0.001, after=ids[-1]))
    assert ids[:2] == ["20250114-195312", "20250114-195312.001"] and ids[-1] == "20250114-195312.099"
    assert ids == sorted(ids) and len(set(ids)) == 100
    assert session_id(wall + 1.0, after=ids[-1]) == "20250114-195313" > ids[-1]
    assert session_id(wall - 5.0, after="20250114-195312") == "20250114-195312.001"  # a clock put back
    many = "20250114-195312.999"
    assert session_id(wall, after=many) == "20250114-195313"  # the count full: the next second
    from common.messages import SESSION_ID
    assert all(SESSION_ID.match(i) for i in [*ids, many])
