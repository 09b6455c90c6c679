"""The PDM: rail currents and bus draw, trips, switching, protection and shedding."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from common.config import load_rover
from common.faults import Dust, Fail
from common.messages import PowerSummary, RailState
from services.power.model import PowerModel, RailReading, Summary
from tests.harness import ROVERS


@pytest.fixture
def pdm():
    m = PowerModel(load_rover(ROVERS / "mapp.yaml"))
    m.set_battery(1.0, True, 16.5)
    return m


def rails(m):
    readings, summary = m.compute()
    return {r.name: r for r in readings}, summary


def test_rail_current_and_bus_draw_through_efficiency(pdm):
    pdm.load_power_w.update(drive_motors=48.0, survival_heater=12.0, flight_computer=6.0)
    r, s = rails(pdm)
    assert_allclose(r["12V"].current_a, 60.0 / 12.0)
    assert_allclose(r["12V"].power_w, 60.0)
    assert_allclose(r["5V_CH1"].current_a, 6.0 / 5.0)
    assert_allclose(s.load_power_w, 66.0)
    assert_allclose(s.bus_power_w, 60.0 / 0.93 + 6.0 / 0.90)
    assert s.bus_voltage_v == 16.5


def test_net_battery_power_is_draw_minus_generation_through_the_solar_rail(pdm):
    pdm.load_power_w.update(drive_motors=93.0)
    pdm.panel_power_w.update(left=20.0, right=20.0)
    pdm.umbilical_w = 30.0
    r, s = rails(pdm)
    assert_allclose(s.generation_w, 40.0 * 0.95 + 30.0)
    assert_allclose(s.net_battery_power_w, 93.0 / 0.93 - 68.0)
    assert_allclose(r["SOLAR"].current_a, 40.0 / 18.0)


def test_a_rail_trips_exactly_above_its_limit_and_stays_off_until_reset(pdm):
    pdm.load_power_w.update(nav_camera=20.0, hazard_cameras=5.0)  # 25 W / 5 V = 5.0 A: at the limit
    r, _ = rails(pdm)
    assert r["5V_CH2"].state == "on"
    pdm.load_power_w.update(hazard_cameras=5.0 + 1e-9)  # a hair over 5 A
    r, _ = rails(pdm)
    assert r["5V_CH2"].state == "tripped" and r["5V_CH2"].current_a == 0.0
    assert "tripped" in pdm.derived_faults("5V_CH2")
    pdm.load_power_w.update(nav_camera=3.0, hazard_cameras=2.0)  # the load is back to normal ...
    assert rails(pdm)[0]["5V_CH2"].state == "tripped"  # ... but the trip is latched
    pdm.command("5V_CH2", reset=True)
    assert rails(pdm)[0]["5V_CH2"].state == "on"


def test_rails_switch_by_command(pdm):
    pdm.load_power_w.update(imu=1.0)
    pdm.command("3V3_CH1", on=False)
    r, s = rails(pdm)
    assert r["3V3_CH1"].state == "off" and r["3V3_CH1"].power_w == 0.0 and s.load_power_w == 0.0
    pdm.command("3V3_CH1", on=True)
    assert rails(pdm)[0]["3V3_CH1"].state == "on"


def test_every_rail_goes_off_while_the_battery_is_non_operational(pdm):
    pdm.load_power_w.update(drive_motors=40.0)
    pdm.set_battery(0.0, False, 0.0)
    r, s = rails(pdm)
    assert {x.state for n, x in r.items() if n != "SOLAR"} == {"off"}
    assert s.bus_power_w == 0.0
    pdm.set_battery(0.5, True, 15.0)
    assert rails(pdm)[0]["12V"].state == "on"


def test_shedding_and_restoring_with_hysteresis(pdm):
    # 5V_CH2 sheds below 0.15 and comes back at 0.15 + 0.05 = 0.20; 3V3_CH2 sheds below 0.25.
    for soc, ch2, ch3 in [(0.30, "on", "on"), (0.24, "on", "shed"), (0.149, "shed", "shed"),
                          (0.17, "shed", "shed"), (0.199, "shed", "shed"), (0.20, "on", "shed"),
                          (0.29, "on", "shed"), (0.30, "on", "on"), (0.26, "on", "on"),
                          (0.16, "on", "shed")]:
        pdm.set_battery(soc, True, 15.0)
        r, _ = rails(pdm)
        assert (r["5V_CH2"].state, r["3V3_CH2"].state) == (ch2, ch3), soc
    assert rails(pdm)[0]["12V"].state == "on"  # essential rails are never shed


def test_a_failed_converter_gives_zero_volts(pdm):
    pdm.load_power_w.update(flight_computer=6.0)
    pdm.set_faults("5V_CH1", [Fail()])
    r, _ = rails(pdm)
    assert (r["5V_CH1"].state, r["5V_CH1"].voltage_v, r["5V_CH1"].power_w) == ("failed", 0.0, 0.0)
    pdm.set_faults("5V_CH1", [])
    r, _ = rails(pdm)
    assert (r["5V_CH1"].state, r["5V_CH1"].voltage_v, r["5V_CH1"].power_w) == ("on", 5.0, 6.0)
    pdm.set_faults("SOLAR", [Fail()])  # the panels' own rail
    assert pdm.solar_failed and rails(pdm)[0]["SOLAR"].state == "failed"
    with pytest.raises(ValueError, match="a rail has no fault kind 'dust'"):
        pdm.set_faults("5V_CH1", [Dust(fraction=0.1)])
    with pytest.raises(ValueError, match="no rail '48V'"):
        pdm.set_faults("48V", [Fail()])


@settings(max_examples=200, deadline=None)
@given(
    powers=st.lists(st.one_of(st.just(0.0), st.floats(0.0, 1e300)), min_size=10, max_size=10),
    soc=st.floats(0.0, 1.0),
    operational=st.booleans(),
    panels=st.lists(st.floats(0.0, 1e12), min_size=2, max_size=2),
)
def test_no_input_gives_nan_or_negative_power(powers, soc, operational, panels):
    m = PowerModel(load_rover(ROVERS / "mapp.yaml"))
    m.set_battery(soc, operational, 15.0)
    m.load_power_w.update(zip(m.load_power_w, powers, strict=True))
    m.panel_power_w.update(left=panels[0], right=panels[1])
    readings, summary = m.compute()
    for r in readings:
        assert all(math.isfinite(v) and v >= 0.0 for v in (r.voltage_v, r.current_a, r.power_w))
        if r.name != "SOLAR" and r.state == "on":
            assert r.current_a <= r.current_limit_a  # anything above has tripped
    assert all(math.isfinite(v) for v in summary)
    assert summary.bus_power_w >= summary.load_power_w >= 0.0
    tripped = {n for n, sw in m.switches.items() if sw.tripped}
    m.load_power_w.update(dict.fromkeys(m.load_power_w, 0.0))
    m.compute()
    assert tripped == {n for n, sw in m.switches.items() if sw.tripped}  # latched


def test_a_rail_returning_power_feeds_the_bus_through_its_converter(pdm):
    # a drive regenerating 20 W on 12V (efficiency 0.93) with the 12 W heater: -8 W on the
    # rail, -8 * 0.93 = -7.44 W on the bus (not -8 / 0.93: the converter loses either way)
    pdm.load_power_w.update(drive_motors=-20.0, survival_heater=12.0)
    r, s = rails(pdm)
    assert r["12V"].state == "on" and r["12V"].power_w == -8.0
    assert_allclose(r["12V"].current_a, -8.0 / 12.0)
    assert_allclose(s.bus_power_w, -8.0 * 0.93)


def test_a_reading_is_its_messages_fields_in_order():
    # The service builds RailState(t_s, *reading[1:]) and PowerSummary(t_s, *summary): a field
    # added or moved in one but not the other must fail here, not mislabel a dashboard.
    assert RailState.__struct_fields__ == ("t_s", *RailReading._fields[1:])
    assert PowerSummary.__struct_fields__ == ("t_s", *Summary._fields)
