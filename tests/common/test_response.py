"""The crew's response measured from hand-made sample streams (common.response, SPEC §12d):
each fault kind's symptom, its resolution, the crew's actions in order, no symptom -> null,
sessions that never mix, expectations from the journal and the runner's progress."""

from __future__ import annotations

import itertools
import random

import pytest

from common.messages import Event
from common.response import Response
from common.symptoms import SYMPTOMS

pytestmark = pytest.mark.timeout(60)

R = "mapp-1"
P = f"lunaris/{R}/"
_seq = itertools.count(1)


def ev(r: Response, t: float, kind: str, key: str, *, actor: str = "instructor", params=None,
       message: str = "", session: str = "", severity: str = "info", source: str = "x") -> str:
    """An event: as its JSON object (a recording's), or, every other one without a session id,
    as the Struct (the mirror's)."""
    e = Event(t_s=t, severity=severity, source=source, kind=kind, key=P + key, message=message or kind,
              params=params, source_id="s", seq=next(_seq), actor=actor)
    if session or e.seq % 2 == 0:
        return r.event({f: getattr(e, f) for f in e.__struct_fields__} | (
            {"session": session} if session else {}))
    return r.event(e)


def clock(r: Response, t: float, epoch: int = 0, session: str = "") -> str:
    c = {"t_s": t, "dt_s": 0.1, "seq": 0, "time_scale": 1.0, "paused": False, "epoch": epoch}
    if session:
        c["session"] = session
    return r.value(["clock"], c)


def inject(r: Response, t: float, path: str, params=None, actor: str = "instructor", **kw) -> str:
    return ev(r, t, "fault_injected", "fault/" + path, actor=actor, params=params or {}, **kw)


def clear(r: Response, t: float, path: str, **kw) -> str:
    return ev(r, t, "fault_cleared", "fault/" + path, **kw)


def crew(r: Response, t: float, key: str, *, kind: str = "command", params=None, message: str = "") -> None:
    ev(r, t, kind, key, actor="crew", params=params, message=message)


def ticks(t0: float, t1: float, dt: float = 0.1):
    n = round((t1 - t0) / dt)
    return [round(t0 + i * dt, 6) for i in range(n)]


def only(r: Response):
    (s,) = r.sessions()
    return s


def fault_of(r: Response, path: str):
    (f,) = [f for s in r.sessions() for f in s.faults if f.fault == path]
    return f


# -- a short: the rail trips, the crew safes it, the short is cleared, the rail comes back -----------


def _pdm(r: Response, t: float, camera_w: float, rail: str) -> None:
    clock(r, t)
    r.value(["load", "nav_camera", "power"], {"t_s": t, "power_w": camera_w, "rail": "5V_CH2", "on": True,
                                              "faults": []})
    r.value(["rail", "5V_CH2", "state"], {"t_s": t, "state": rail, "voltage_v": 5.0})


def test_a_short_trips_its_rail_and_the_crews_actions_are_listed_in_order_until_the_rail_is_back():
    r = Response(R)
    rng = random.Random(1)
    for t in ticks(0, 30):
        _pdm(r, t, 3.5 + rng.gauss(0, 0.3), "on")
    inject(r, 30.0, "load/nav_camera/short", {"resistance_ohm": 0.1}, actor="scenario")
    _pdm(r, 30.1, 250.0, "tripped")
    ev(r, 30.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin", severity="critical")
    for t in ticks(30.2, 40):
        _pdm(r, t, 0.0, "tripped")
    crew(r, 40.0, "cmd/rail/5V_CH3", kind="rejected", message="rejected: rover mapp-1 has no rail '5V_CH3'")
    crew(r, 41.0, "cmd/rail/5V_CH2", params={"on": False, "reset": False, "state": "off"})
    _pdm(r, 41.1, 0.0, "off")
    ev(r, 41.1, "fault_resolved", "rail/5V_CH2/tripped", actor="twin")
    crew(r, 43.0, "cmd/rail/5V_CH2", params={"on": None, "reset": True, "state": "off"})
    clear(r, 44.0, "load/nav_camera/short", actor="scenario")
    crew(r, 50.0, "cmd/rail/5V_CH2", params={"on": True, "reset": False, "state": "on"})
    _pdm(r, 50.1, 3.4, "on")
    crew(r, 60.0, "input/drive/traverse", kind="input", message="traverse stopped at (5.0, 0.0, 0.0) m")

    s = only(r)
    assert (s.session, s.trainee, s.rover) == ("", None, R)  # no session id: one session
    (f,) = s.faults
    assert f.key == P + "fault/load/nav_camera/short" and f.kind == "short" and f.injected_by == "scenario"
    assert f.injected_t_s == 30.0 and f.first_symptom_t_s == 30.1
    # the refused command named a rail the short does not touch: no action on it (SPEC 13a)
    assert f.first_crew_action_t_s == 41.0 and f.response_s == pytest.approx(10.9)
    assert [(a.t_s, a.action, a.target, a.accepted) for a in f.crew_actions] == [
        (41.0, "rail off", "5V_CH2", True),
        (43.0, "rail reset", "5V_CH2", True),
        (50.0, "rail on", "5V_CH2", True)]  # the stop at 60 s is after the rail came back
    # the trip's alarm cleared at 41.1 but the rail was off, not on as before: resolved when cleared
    assert f.resolved_t_s == 44.0 and f.resolved_by == "cleared" and f.cleared_t_s == 44.0
    assert not f.active


def test_a_fault_resolved_by_the_crew_is_resolved_when_its_alarms_cleared_and_its_rail_is_back():
    r = Response(R)
    for t in ticks(0, 10):
        _pdm(r, t, 3.5, "on")
    inject(r, 10.0, "load/nav_camera/short")
    _pdm(r, 10.1, 200.0, "tripped")
    ev(r, 10.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin")
    crew(r, 20.0, "cmd/rail/5V_CH2", params={"reset": True, "on": True})
    _pdm(r, 20.1, 3.5, "on")  # (as if the short had healed)
    ev(r, 20.1, "fault_resolved", "rail/5V_CH2/tripped", actor="twin")
    f = fault_of(r, "load/nav_camera/short")
    assert f.resolved_t_s == 20.1 and "alarms cleared" in f.resolved_by and "5V_CH2 back on" in f.resolved_by
    assert f.active  # still injected: resolved as the crew sees it
    _pdm(r, 25.0, 200.0, "tripped")  # it trips again: not resolved after all
    ev(r, 25.0, "fault_raised", "rail/5V_CH2/tripped", actor="twin")
    f = fault_of(r, "load/nav_camera/short")
    assert f.resolved_t_s is None
    assert [a.action for a in f.crew_actions] == ["rail reset and on"]


def test_a_loads_own_over_current_is_no_symptom_the_crew_sees_its_rails_trip_is():
    """The camera's over-current alarm, raised at its surge just before its rail trips, is on
    no crew topic (the dashboard's PDM measures rails, not loads: services.bridge.crew): heard
    first, at the trip's tick, it is not the symptom; the rail's trip is, in the same tick. It
    still holds the fault unresolved until it clears."""
    r = Response(R)
    for t in ticks(0, 10):
        _pdm(r, t, 3.5, "on")
    inject(r, 10.0, "load/nav_camera/short")
    ev(r, 10.1, "fault_raised", "load/nav_camera/over_current", actor="twin", severity="critical")
    f = fault_of(r, "load/nav_camera/short")
    assert f.first_symptom_t_s is None and f.symptom == ""  # nothing the crew could see yet
    ev(r, 10.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin", severity="critical")
    _pdm(r, 10.1, 0.0, "tripped")
    f = fault_of(r, "load/nav_camera/short")
    assert f.first_symptom_t_s == 10.1 and f.symptom == "alarm rail/5V_CH2/tripped"
    crew(r, 20.0, "cmd/rail/5V_CH2", params={"reset": True, "on": True})
    _pdm(r, 20.1, 3.5, "on")
    ev(r, 20.1, "fault_resolved", "rail/5V_CH2/tripped", actor="twin")
    assert fault_of(r, "load/nav_camera/short").resolved_t_s is None  # the camera's alarm is up
    ev(r, 20.2, "fault_resolved", "load/nav_camera/over_current", actor="twin")
    assert fault_of(r, "load/nav_camera/short").resolved_t_s == 20.2


# -- each kind's symptom ------------------------------------------------------------------------------


def _battery(r: Response, t: float, **over) -> None:
    b = {"t_s": t, "capacity_j": 5.3e5, "voltage_v": 16.5, "temperature_c": 20.0, "operational": True,
         "soc": 0.9, "current_a": 2.0}
    b.update(over)
    clock(r, t)
    r.value(["battery", "state"], b)


def test_heating_shows_when_the_temperature_rises_beyond_the_trend_it_had():
    r = Response(R)
    for t in ticks(0, 60):
        _battery(r, t, temperature_c=20.0 + 0.002 * t)  # warming slowly already
    inject(r, 60.0, "battery/heating", {"heat_w": 45})
    for t in ticks(60, 80):  # now 0.03 C/s faster: 0.2 C above the trend after 0.2 / 0.03 = 6.7 s
        _battery(r, t, temperature_c=20.0 + 0.002 * t + 0.03 * (t - 60.0))
    f = fault_of(r, "battery/heating")
    assert f.first_symptom_t_s == pytest.approx(66.8, abs=0.15)
    assert "temperature" in f.symptom and "°C" in f.symptom and "above" in f.symptom


def test_heating_that_changes_nothing_the_crew_sees_has_no_symptom():
    r = Response(R)
    for t in ticks(0, 60):
        _battery(r, t, temperature_c=20.0 + 0.002 * t)
    inject(r, 60.0, "battery/heating", {"heat_w": 0})
    for t in ticks(60, 200):
        _battery(r, t, temperature_c=20.0 + 0.002 * t)  # the same trend: nothing to see
    f = fault_of(r, "battery/heating")
    assert f.first_symptom_t_s is None and f.symptom == "" and f.resolved_t_s is None


@pytest.mark.parametrize("path, params, field, before, after", [
    ("battery/capacity_loss", {"fraction": 0.5}, "capacity_j", 5.3e5, 2.65e5),
    ("battery/resistance", {"factor": 3}, "voltage_v", 16.5, 15.9),
    ("battery/disconnect", {}, "operational", True, False),
])
def test_battery_faults_show_on_the_battery_state(path, params, field, before, after):
    r = Response(R)
    for t in ticks(0, 10):
        _battery(r, t, **{field: before})
    inject(r, 10.0, path, params)
    for t in ticks(10.1, 12):
        _battery(r, t, **{field: after})
    assert fault_of(r, path).first_symptom_t_s == 10.1


def test_a_disconnected_pack_raises_no_output_and_is_resolved_when_the_alarm_clears():
    r = Response(R)
    for t in ticks(0, 5):
        _battery(r, t)
    inject(r, 5.0, "battery/disconnect")
    ev(r, 5.05, "fault_raised", "battery/no_output", actor="twin", severity="critical")
    _battery(r, 5.1, operational=False)
    clear(r, 9.0, "battery/disconnect")
    ev(r, 9.1, "fault_resolved", "battery/no_output", actor="twin")
    f = fault_of(r, "battery/disconnect")
    assert f.first_symptom_t_s == 5.05 and f.symptom == "alarm battery/no_output"
    assert f.resolved_t_s == 9.0  # cleared before its alarm resolved


def _load(r: Response, name: str, t: float, power_w: float, rail: str = "12V", on: bool = True) -> None:
    """A load's sample; ``on``: its rail is live (off: it draws 0 W, as the loads service says)."""
    clock(r, t)
    r.value(["load", name, "power"], {"t_s": t, "power_w": power_w if on else 0.0, "rail": rail, "on": on,
                                      "faults": []})


def test_a_stuck_load_shows_when_its_power_changes_and_not_when_stuck_where_it_was():
    r = Response(R)
    rng = random.Random(2)
    for t in ticks(0, 60):
        _load(r, "survival_heater", t, min(15.0, 12.0 + rng.gauss(0, 0.5)))
        _load(r, "imu", t, 1.0, "3V3_CH1")
    inject(r, 60.0, "load/survival_heater/stuck", {"power_w": 15})
    inject(r, 60.0, "load/imu/stuck", {"power_w": 1.0})
    for t in ticks(60.1, 120):
        _load(r, "survival_heater", t, 15.0)
        _load(r, "imu", t, 1.0, "3V3_CH1")
    assert fault_of(r, "load/survival_heater/stuck").first_symptom_t_s == 60.1
    assert fault_of(r, "load/imu/stuck").first_symptom_t_s is None  # what it drew anyway


def test_an_open_load_shows_when_its_power_falls():
    r = Response(R)
    for t in ticks(0, 10):
        _load(r, "imu", t, 1.0, "3V3_CH1")
    inject(r, 10.0, "load/imu/open")
    for t in ticks(10.1, 11):
        _load(r, "imu", t, 0.0, "3V3_CH1")
    assert fault_of(r, "load/imu/open").first_symptom_t_s == 10.1


def test_an_open_load_on_a_rail_off_at_the_fault_shows_when_the_rail_comes_on_and_it_draws_nothing():
    """The instructor's training day: the camera's rail off, the camera opened, the crew switches
    the rail on at 20 s and sees the camera at 0 W. Nothing before (the rail off: 0 W is what
    any load draws there); the symptom is the first sample on the live rail, at 20.0 s."""
    r = Response(R)
    for t in ticks(0, 10):
        _load(r, "nav_camera", t, 3.5, "5V_CH2", on=False)
    inject(r, 10.0, "load/nav_camera/open")
    for t in ticks(10, 20):
        _load(r, "nav_camera", t, 0.0, "5V_CH2", on=False)
    assert fault_of(r, "load/nav_camera/open").first_symptom_t_s is None  # nothing to see yet
    for t in ticks(20, 21):
        _load(r, "nav_camera", t, 0.0, "5V_CH2", on=True)
    f = fault_of(r, "load/nav_camera/open")
    assert f.first_symptom_t_s == 20.0
    assert f.symptom == "load/nav_camera power 0 W on a live rail"


def test_an_open_load_whose_rail_never_comes_on_has_no_symptom():
    r = Response(R)
    for t in ticks(0, 10):
        _load(r, "nav_camera", t, 3.5, "5V_CH2", on=False)
    inject(r, 10.0, "load/nav_camera/open")
    for t in ticks(10, 100):
        _load(r, "nav_camera", t, 0.0, "5V_CH2", on=False)
    f = fault_of(r, "load/nav_camera/open")
    assert f.first_symptom_t_s is None and f.symptom == ""


def test_a_loads_power_on_a_dead_rail_is_no_part_of_its_band():
    """0 W while the rail was off says nothing of what the load draws: the imu at 1.0 W on its
    live rail, its rail off 5 s to 8 s, then opened at 10 s: 0 W at 10.1 s is below the 1.0 W
    band (less 0.05 W), a symptom at 10.1 s (with the off spell in the band, its band went down
    to 0 W and nothing was ever below it)."""
    r = Response(R)
    for t in ticks(0, 10):
        _load(r, "imu", t, 1.0, "3V3_CH1", on=not 5.0 <= t < 8.0)
    inject(r, 10.0, "load/imu/open")
    _load(r, "imu", 10.1, 0.0, "3V3_CH1")
    f = fault_of(r, "load/imu/open")
    assert f.first_symptom_t_s == 10.1 and f.symptom == "load/imu power 0 W, below 1 W before"


def test_a_loads_power_on_a_dead_rail_is_no_symptom():
    """A stuck load at the power it drew, its rail switched off after the fault: 0 W on a dead
    rail is what any load draws there, no symptom of it (it was one, at the switch-off)."""
    r2 = Response(R)
    for t in ticks(0, 10):
        _load(r2, "imu", t, 1.0, "3V3_CH1")
    inject(r2, 10.0, "load/imu/stuck", {"power_w": 1.0})
    for t in ticks(10, 30):
        _load(r2, "imu", t, 1.0, "3V3_CH1", on=t < 15.0)  # the crew switched the rail off at 15 s
    assert fault_of(r2, "load/imu/stuck").first_symptom_t_s is None


def test_a_failed_rail_shows_as_its_state_and_is_resolved_when_cleared():
    r = Response(R)
    for t in ticks(0, 5):
        clock(r, t)
        r.value(["rail", "12V", "state"], {"t_s": t, "state": "on"})
    inject(r, 5.0, "rail/12V/fail")
    r.value(["rail", "12V", "state"], {"t_s": 5.1, "state": "failed"})
    clear(r, 8.0, "rail/12V/fail")
    r.value(["rail", "12V", "state"], {"t_s": 8.1, "state": "on"})
    f = fault_of(r, "rail/12V/fail")
    assert f.first_symptom_t_s == 5.1 and "on -> failed" in f.symptom and f.resolved_t_s == 8.0


def _panel(r: Response, t: float, power_w: float) -> None:
    clock(r, t)
    r.value(["solar", "left", "power"], {"t_s": t, "power_w": power_w, "sun_angle_deg": 60.0, "dust": 0.0})


def test_dust_shows_when_the_panels_power_falls_faster_than_the_setting_sun_takes_it():
    r = Response(R)
    for t in ticks(0, 60):
        _panel(r, t, 20.0 - 0.05 * t)  # the sun sinking: 0.05 W/s less
    inject(r, 60.0, "solar/left/dust", {"fraction": 0.0})  # no dust at all: nothing to see
    inject(r, 60.0, "solar/right/dust", {"fraction": 0.3})
    for t in ticks(60, 200):
        _panel(r, t, 20.0 - 0.05 * t)
        r.value(["solar", "right", "power"], {"t_s": t, "power_w": 20.0 if t < 61 else 14.0})
    assert fault_of(r, "solar/left/dust").first_symptom_t_s is None
    assert fault_of(r, "solar/right/dust").first_symptom_t_s is None  # no value before: no band
    r2 = Response(R)
    for t in ticks(0, 60):
        _panel(r2, t, 20.0)
    inject(r2, 60.0, "solar/left/disconnect")
    _panel(r2, 60.1, 0.0)
    assert fault_of(r2, "solar/left/disconnect").first_symptom_t_s == 60.1


def test_an_umbilical_that_supplied_nothing_shows_no_symptom_when_disconnected():
    r = Response(R)
    for t in ticks(0, 5):
        clock(r, t)
        r.value(["umbilical", "state"], {"t_s": t, "connected": False, "power_w": 0.0})
    inject(r, 5.0, "umbilical/disconnect")
    r.value(["umbilical", "state"], {"t_s": 5.1, "connected": False, "power_w": 0.0})
    assert fault_of(r, "umbilical/disconnect").first_symptom_t_s is None
    r2 = Response(R)
    for t in ticks(0, 5):
        r2.value(["umbilical", "state"], {"t_s": t, "connected": True, "power_w": 120.0})
    inject(r2, 5.0, "umbilical/disconnect")
    r2.value(["umbilical", "state"], {"t_s": 5.1, "connected": True, "power_w": 0.0})
    assert fault_of(r2, "umbilical/disconnect").first_symptom_t_s == 5.1


def _umbilical(r: Response, t: float, connected: bool, power_w: float) -> None:
    clock(r, t)
    r.value(["umbilical", "state"], {"t_s": t, "connected": connected, "power_w": power_w})


def test_an_umbilical_cut_while_unplugged_shows_when_it_is_plugged_in_and_supplies_nothing():
    """Cut while unplugged (0 W, as any unplugged umbilical): nothing to see. Plugged in at
    20 s (the solar service says so after its state of that tick, connected false, 0 W): the
    crew plugged it in and it supplies nothing, a symptom at 20.0 s. Unplugged again, then cut
    and never plugged: none."""
    r = Response(R)
    for t in ticks(0, 10):
        _umbilical(r, t, False, 0.0)
    inject(r, 10.0, "umbilical/disconnect")
    for t in ticks(10, 20.1):
        _umbilical(r, t, False, 0.0)
    assert fault_of(r, "umbilical/disconnect").first_symptom_t_s is None
    ev(r, 20.0, "input", "input/umbilical", actor="crew", params={"connected": True},
       message="umbilical plugged in")
    f = fault_of(r, "umbilical/disconnect")
    assert f.first_symptom_t_s == 20.0 and f.symptom == "umbilical power 0 W plugged in"
    r2 = Response(R)
    for t in ticks(0, 10):
        _umbilical(r2, t, False, 0.0)
    inject(r2, 10.0, "umbilical/disconnect")
    for t in ticks(10, 100):
        _umbilical(r2, t, False, 0.0)
    assert fault_of(r2, "umbilical/disconnect").first_symptom_t_s is None


def test_an_umbilical_plugged_in_at_the_start_and_cut_shows_when_its_supply_falls():
    """Plugged in (connected, 120 W) with no event saying so (the rover file's): cut at 5 s,
    its state says not connected, 0 W at 5.1 s: still plugged in, below 120 W, a symptom at
    5.1 s (its state alone says it is not connected, as an unplugged one)."""
    r = Response(R)
    for t in ticks(0, 5):
        _umbilical(r, t, True, 120.0)
    inject(r, 5.0, "umbilical/disconnect")
    _umbilical(r, 5.1, False, 0.0)
    f = fault_of(r, "umbilical/disconnect")
    assert f.first_symptom_t_s == 5.1 and f.symptom == "umbilical power 0 W, below 120 W before"


def _link(r: Response, name: str, t: float, in_range: bool) -> None:
    clock(r, t)
    r.value(["radio", name, "link"], {"t_s": t, "in_range": in_range, "x_m": 0.0, "y_m": 0.0})


def test_a_degraded_radio_shows_only_when_the_link_goes_out_of_range():
    r = Response(R)
    for t in ticks(0, 5):
        _link(r, "lander", t, True)
        _link(r, "relay", t, False)
    inject(r, 5.0, "radio/lander/degraded", {"range_scale": 0.5})
    inject(r, 5.0, "radio/relay/failure")  # out of range anyway: nothing to see
    for t in ticks(5, 20):
        _link(r, "lander", t, True)
        _link(r, "relay", t, False)
    assert fault_of(r, "radio/lander/degraded").first_symptom_t_s is None
    _link(r, "lander", 20.0, False)
    f = fault_of(r, "radio/lander/degraded")
    assert f.first_symptom_t_s == 20.0 and "out of range" in f.symptom
    assert fault_of(r, "radio/relay/failure").first_symptom_t_s is None


def test_every_fault_kind_of_the_catalogue_has_its_symptom_in_words():
    from common.faults import CATALOGUE
    kinds = {(c, k) for c, ks in CATALOGUE.items() for k in ks}
    assert set(SYMPTOMS) == kinds
    assert all(spec.words for spec in SYMPTOMS.values())


def test_an_injection_heard_after_its_effect_still_finds_the_symptom_at_the_effects_time():
    r = Response(R)
    for t in ticks(0, 10):
        _load(r, "imu", t, 1.0, "3V3_CH1")
    _load(r, "imu", 10.1, 0.0, "3V3_CH1")  # the effect arrived first
    ev(r, 10.1, "fault_raised", "load/imu/over_current", actor="twin")  # (an alarm too)
    inject(r, 10.0, "load/imu/open")
    f = fault_of(r, "load/imu/open")
    assert f.first_symptom_t_s == 10.1


def test_an_alarm_raised_before_the_injection_is_not_its_symptom():
    r = Response(R)
    ev(r, 1.0, "fault_raised", "battery/over_temperature", actor="twin")
    inject(r, 5.0, "battery/heating", {"heat_w": 5})
    assert fault_of(r, "battery/heating").first_symptom_t_s is None


def test_a_fault_injected_again_keeps_its_first_injection_and_takes_the_new_parameters():
    r = Response(R)
    inject(r, 5.0, "load/imu/stuck", {"power_w": 1.2})
    inject(r, 9.0, "load/imu/stuck", {"power_w": 1.4})
    (f,) = only(r).faults
    assert f.injected_t_s == 5.0 and f.params == {"power_w": 1.4}
    clear(r, 12.0, "load/imu/stuck")
    inject(r, 15.0, "load/imu/stuck", {"power_w": 1.1})  # a second life: a second entry
    assert [(f.injected_t_s, f.cleared_t_s) for f in only(r).faults] == [(5.0, 12.0), (15.0, None)]


# -- sessions -----------------------------------------------------------------------------------------


A, B = "20261125-090000", "20261125-100000"  # session ids as the clock makes them (UTC, growing)


def _opened(r: Response, t: float, sid: str, trainee: str) -> str:
    """The clock's event that opens a session (SPEC 12c)."""
    return ev(r, t, "session", "control/session", session=sid, source="clock", params={
        "session": sid, "trainee": trainee, "from_snapshot": None, "started_wall": 1.7e9, "start_t_s": t})


def test_the_clocks_sessions_never_mix_and_a_reset_within_one_begins_none():
    r = Response(R)
    for t in ticks(0, 5):
        clock(r, t, session=A)
        _load(r, "imu", t, 1.0, "3V3_CH1")
    assert _opened(r, 0.0, A, "Ada") == A
    inject(r, 5.0, "load/imu/open", session=A)
    _load(r, "imu", 5.1, 0.0, "3V3_CH1")
    crew(r, 6.0, "cmd/rail/3V3_CH1", params={"on": False})  # no id: the running session
    # a reset within the session: a new epoch, the same session
    ev(r, 6.5, "session", "control/reset", message="session reset", session=A)
    assert clock(r, 0.0, epoch=1, session=A) == A
    # the next trainee: the closing event of A, the first tick of B, the opening of B
    ev(r, 0.5, "session", "sessions", session=A, params={"session": A, "trainee": "Ada", "end_t_s": 0.5})
    assert clock(r, 0.0, epoch=2, session=B) == B
    assert _opened(r, 0.0, B, "Bob") == B
    assert clear(r, 0.1, "load/imu/open", session=A) == A  # the end's clearing: A's, heard late
    assert clock(r, 7.1, epoch=1, session=A) == B  # a late tick of A: B runs on
    for t in ticks(0.1, 5):
        clock(r, t, epoch=2, session=B)
        _load(r, "imu", t, 1.0, "3V3_CH1")
    inject(r, 5.0, "battery/heating", {"heat_w": 30}, session=B)
    crew(r, 6.0, "cmd/rail/12V", params={"on": False})
    one, two = r.sessions()
    assert [(s.session, s.trainee) for s in (one, two)] == [(A, "Ada"), (B, "Bob")]
    assert [f.fault for f in one.faults] == ["load/imu/open"]
    assert [f.fault for f in two.faults] == ["battery/heating"]
    (f1,) = one.faults
    assert f1.resolved_t_s is None and not f1.active and f1.cleared_t_s is None  # ended with it
    assert [a.target for a in f1.crew_actions] == ["3V3_CH1"]
    assert two.faults[0].crew_actions == []  # the 12 V rail is nothing the heating touches
    assert r.session(B) == two and r.session("nope") is None and r.session_id == B


def test_what_comes_before_the_first_session_id_is_that_sessions_and_a_late_session_never_runs():
    r = Response(R)
    clock(r, 10.0)  # a tick without a session (heard before the clock named one)
    assert inject(r, 10.0, "load/imu/stuck", {"power_w": 1.3}) == ""
    assert clock(r, 10.1, session=B) == B  # the first id names what came before
    assert _opened(r, 0.0, A, "Ada") == A and r.session_id == B  # heard late, older: B runs on
    assert inject(r, 3.0, "battery/heating", {"heat_w": 10}, session=A) == A
    clock(r, 10.2, session=B)
    a, b = r.sessions()
    assert (a.session, a.trainee, [f.fault for f in a.faults]) == (A, "Ada", ["battery/heating"])
    assert (b.session, b.trainee, [f.fault for f in b.faults]) == (B, None, ["load/imu/stuck"])
    assert not a.faults[0].active and b.faults[0].active and r.session_id == B
    assert [f.fault for f in r.live().faults] == ["load/imu/stuck"]


def test_a_clock_that_names_its_session_moves_the_telemetry_to_it():
    r = Response(R)
    clock(r, 1.0, session=A)
    clock(r, 0.0, epoch=1, session=B)
    assert r.session_id == B
    assert [s.session for s in r.sessions()] == [A, B]


# -- expectations -------------------------------------------------------------------------------------


def _progress(t: float, rel: float, met, met_rel=None, state: str = "playing") -> dict:
    return {"t_s": t, "scenario": "drill", "rover": R, "state": state, "t_rel_s": rel, "waiting": "",
            "message": "", "steps": [
                {"index": 0, "label": "short", "trigger": "at 2 s", "action": "inject", "status": "fired"},
                {"index": 1, "label": "isolate", "trigger": "", "action": "", "armed_t_s": 2.0,
                 "status": "armed" if met is None else "met", "expect": {
                     "label": "isolate the shorted camera", "condition": "rail.5V_CH2.state == off",
                     "within_s": 60.0, "met": met, "met_t_s": met_rel, "deadline_t_s": 62.0}}]}


def test_expectations_come_from_the_progress_while_pending_and_from_the_journal_once_scored():
    r = Response(R)
    r.value(["scenario", "progress"], _progress(12.0, 10.0, None))  # started at sim t 2
    (e,) = only(r).expectations
    assert (e.label, e.met, e.at_t_s, e.within_s, e.armed_t_s, e.deadline_t_s) == (
        "isolate the shorted camera", None, None, 60.0, 4.0, 64.0)
    v = r.version
    r.value(["scenario", "progress"], _progress(13.0, 11.0, None))  # the same: no change
    assert r.version == v
    ev(r, 20.0, "scenario", "control/scenario", params={
        "scenario": "drill", "what": "expect", "step": 2, "expectation": {
            "index": 1, "label": "isolate the shorted camera", "condition": "rail.5V_CH2.state == off",
            "within_s": 60.0, "met": True, "at_t_s": 19.5, "armed_t_s": 4.0, "start_t_s": 2.0}})
    (e,) = only(r).expectations
    assert (e.met, e.at_t_s, e.deadline_t_s) == (True, 19.5, 64.0)
    assert r.version > v


def test_a_cached_progress_of_an_earlier_run_is_not_this_sessions():
    r = Response(R)
    r.value(["scenario", "progress"], _progress(500.0, 90.0, True, 20.0, state="ended"))
    assert r.sessions() == []


def test_live_says_since_when_each_fault_is_in_effect_and_whether_the_crew_acted():
    r = Response(R)
    clock(r, 1.0)
    _load(r, "imu", 1.0, 1.0, "3V3_CH1")  # the load's rail, known from its telemetry
    inject(r, 2.0, "load/imu/stuck", {"power_w": 1.4})
    clock(r, 12.5)
    live = r.live()
    (f,) = live.faults
    assert (live.session, live.t_s, f.since_injection_s, f.crew_acted) == ("", 12.5, 10.5, False)
    crew(r, 13.0, "cmd/rail/3V3_CH1", params={"on": False})
    clear(r, 14.0, "load/imu/stuck")
    clock(r, 15.0)
    (f,) = r.live().faults
    assert f.crew_acted and f.since_injection_s is None and not f.active


def test_a_crew_action_heard_before_the_injection_at_its_tick_is_the_faults():
    """Each service's events come their own way: the power service's answer to the crew can
    arrive before the loads service's injection event of the same tick."""
    r = Response(R)
    for t in ticks(0, 3):
        _pdm(r, t, 3.5, "on")
    ev(r, 3.0, "fault_raised", "rail/5V_CH2/tripped", actor="twin")
    crew(r, 3.0, "cmd/rail/5V_CH2", params={"on": False})
    crew(r, 2.0, "cmd/rail/12V", params={"on": False})  # before the fault: not its
    inject(r, 3.0, "load/nav_camera/short")
    f = fault_of(r, "load/nav_camera/short")
    assert f.first_symptom_t_s == 3.0 and [a.target for a in f.crew_actions] == ["5V_CH2"]


def test_a_reset_within_a_session_ends_its_faults_and_keeps_what_came_before_from_the_next():
    """Faults injected by hand, the crew acting on them, then a drill that begins with a reset
    in the same session (the clock back at 0, a new epoch). Found by an instructor: the
    drill's fault showed as acted upon with the crew's actions from before the reset (at times
    later than its injection), and the faults before the reset were resolved by the reset's
    clearings, at times before their own injection."""
    r = Response(R)
    for t in ticks(0, 40):
        clock(r, t, session=A)
        _pdm(r, t, 3.5, "on")
    inject(r, 40.0, "battery/heating", {"heat_w": 30}, session=A)
    inject(r, 41.0, "load/nav_camera/short", {"resistance_ohm": 0.1}, session=A)
    _pdm(r, 41.1, 250.0, "tripped")
    ev(r, 41.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin", severity="critical", session=A)
    crew(r, 86.0, "cmd/rail/5V_CH2", params={"on": False, "reset": False, "state": "off"})
    crew(r, 90.0, "cmd/rail/5V_CH2", params={"on": None, "reset": True, "state": "off"})
    # the drill: a reset (epoch 1, the clock at 0), then its own short at 46 s
    ev(r, 95.0, "session", "control/reset", message="session reset", session=A)
    for t in ticks(0.0, 46.0):
        clock(r, t, epoch=1, session=A)
        _pdm(r, t, 3.5, "on")
    clear(r, 0.0, "battery/heating", session=A)  # the reset's clearings, heard after its tick
    clear(r, 0.0, "load/nav_camera/short", session=A)
    ev(r, 0.1, "fault_resolved", "rail/5V_CH2/tripped", actor="twin", session=A)
    inject(r, 46.0, "load/nav_camera/short", {"resistance_ohm": 0.05}, actor="scenario", session=A)
    _pdm(r, 46.1, 250.0, "tripped")
    ev(r, 46.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin", severity="critical", session=A)
    crew(r, 60.0, "cmd/rail/5V_CH2", params={"on": False, "reset": True, "state": "off"})

    (s,) = r.sessions()
    heating, before, drill = s.faults
    assert (before.fault, before.injected_t_s, drill.injected_t_s) == ("load/nav_camera/short", 41.0, 46.0)
    # before the reset: the crew's two actions, unresolved and no longer in effect after it
    assert [a.t_s for a in before.crew_actions] == [86.0, 90.0]
    assert heating.crew_actions == []  # the camera's rail is nothing the heating touches
    for f in (heating, before):
        assert f.resolved_t_s is None and f.cleared_t_s is None and not f.active, f
    # the drill's short: its own symptom and only the action after the reset
    assert drill.first_symptom_t_s == 46.1 and drill.active
    assert [a.t_s for a in drill.crew_actions] == [60.0]
    assert drill.response_s == pytest.approx(13.9)
    assert [f.fault for f in r.live().faults if f.active] == ["load/nav_camera/short"]


def test_three_faults_at_once_and_the_crew_acting_on_one_credits_only_that_one():
    """Found by an instructor: dust on a panel, the pack heating and a short on the thermal
    imager; the crew acted on the imager's rail only, and the dust and the heating were each
    said to have been acted on (SPEC 13a: an action counts for what the fault touches)."""
    r = Response(R)
    for t in ticks(0, 20):
        clock(r, t)
        _pdm(r, t, 3.5, "on")
        _battery(r, t)
        _panel(r, t, 40.0)
    inject(r, 20.0, "solar/left/dust", {"fraction": 0.6})
    inject(r, 20.0, "battery/heating", {"heat_w": 30})
    inject(r, 21.0, "load/nav_camera/short", {"resistance_ohm": 0.1})
    _pdm(r, 21.1, 250.0, "tripped")
    ev(r, 21.1, "fault_raised", "rail/5V_CH2/tripped", actor="twin", severity="critical")
    for t in ticks(21.2, 30):
        clock(r, t)
        _panel(r, t, 16.0)
    crew(r, 30.0, "cmd/rail/5V_CH2", params={"on": False, "reset": False, "state": "off"})
    crew(r, 32.0, "cmd/rail/5V_CH2", params={"on": None, "reset": True, "state": "off"})
    by = {f.fault: f for f in only(r).faults}
    short = by["load/nav_camera/short"]
    assert [a.t_s for a in short.crew_actions] == [30.0, 32.0] and short.first_crew_action_t_s == 30.0
    for path in ("solar/left/dust", "battery/heating"):
        assert by[path].crew_actions == [] and by[path].first_crew_action_t_s is None, path
        assert by[path].response_s is None
    live = {f.fault: f.crew_acted for f in r.live().faults}
    assert live == {"solar/left/dust": False, "battery/heating": False, "load/nav_camera/short": True}


def test_an_action_on_a_loads_rail_counts_for_the_loads_fault_and_another_rails_does_not():
    r = Response(R)
    for t in ticks(0, 5):
        clock(r, t)
        _load(r, "imu", t, 1.0, "3V3_CH1")
    inject(r, 5.0, "load/imu/open")
    ev(r, 5.1, "fault_raised", "load/imu/no_output", actor="twin")
    crew(r, 8.0, "cmd/rail/3V3_CH1", params={"on": False, "reset": True, "state": "off"})
    crew(r, 9.0, "cmd/rail/12V", params={"on": False, "reset": False, "state": "off"})
    (f,) = only(r).faults
    assert [a.target for a in f.crew_actions] == ["3V3_CH1"]


def test_the_progress_of_a_drill_played_in_another_session_is_none_of_this_ones():
    """SPEC 13a: a drill's progress names its session; heard once the next one has begun (the
    runner had not seen its first tick yet), its expectations are not the next trainee's."""
    A, B = "20261129T050000Z", "20261129T051000Z"
    r = Response(R)
    clock(r, 1.0, session=A)
    r.value(["scenario", "progress"], {**_progress(12.0, 10.0, None), "session": A})
    assert [e.label for e in r.live().expectations] == ["isolate the shorted camera"]
    clock(r, 0.0, epoch=1, session=B)
    r.value(["scenario", "progress"], {**_progress(13.0, 11.0, None), "session": A})
    assert r.live().session == B and r.live().expectations == []


def test_a_sessions_times_are_its_own_from_its_first_tick_with_its_wall_clock_start():
    """SPEC 13a: one time base per session. Found by an instructor: Ben's session said it
    began at 203.1 s, the time Ana's had reached, while his faults were at 17-44 s; one session
    began at 165.8 and ended at 151.1."""
    A, B = "20261129T050000Z", "20261129T051000Z"
    r = Response(R)
    for t in ticks(0.0, 203.1):
        clock(r, t, session=A)
    # the clock's word that B opened comes before B's first tick (and a late sample of A's)
    ev(r, 203.1, "session", "control/session", actor="instructor", session=B, source="clock",
       params={"session": B, "trainee": "Ben", "started_wall": 1795928400.5})
    r.value(["battery", "state"], {"t_s": 203.2, "soc": 0.5})
    for t in ticks(0.0, 44.0):
        clock(r, t, epoch=1, session=B)
    inject(r, 17.0, "load/imu/open", session=B)
    a, b = r.sessions()
    assert (a.session, a.start_t_s, a.end_t_s) == (A, 0.0, pytest.approx(203.0))
    assert (b.session, b.trainee, b.start_t_s, b.started_wall) == (B, "Ben", 0.0, 1795928400.5)
    assert b.end_t_s == pytest.approx(43.9) and b.start_t_s <= b.faults[0].injected_t_s <= b.end_t_s


def test_a_fault_injected_before_the_recording_began_says_so():
    """SPEC 13a: a recording begun after a fault says so. Found by an instructor: a recording
    started 16 s after a short gave its times as if it had seen them all."""
    A = "20261129T050000Z"
    r = Response(R)
    inject(r, 14.0, "load/imu/open", session=A)  # the journal's history, heard first
    for t in ticks(30.0, 40.0):
        clock(r, t, session=A)
    inject(r, 35.0, "battery/heating", {"heat_w": 30}, session=A)
    early, late = only(r).faults
    assert early.note == ("injected at 14.0 s, before the recording began (30.0 s): what came between "
                          "is not in it")
    assert late.note == ""
