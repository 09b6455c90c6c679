"""Armed faults over real processes (SPEC 13b): armed, warned, fired as an instructor's
injection, cancelled, kept across a restart of the faults service, ended with their session.

The clock runs at x10 so that a fault armed 20 s of sim time ahead fires within seconds;
every wait is on an event or a value, never a fixed sleep.
"""

from __future__ import annotations

import msgspec
import pytest

from common import keys
from lunaris.processes import stop_processes
from tests.harness import Probe, wait_for

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
SCALE = 10.0


@pytest.fixture(scope="module")
def armed_twin(mapp_twin):
    p, t = mapp_twin
    p.put(keys.clock_control(R), {"time_scale": SCALE})
    p.wait_value(keys.clock(R), lambda c: c["time_scale"] == SCALE)
    yield p, t


def armed_key(component: str, kind: str) -> str:
    return keys.faults_armed_of(R, component, kind)


def answer(p: Probe, key: str, kinds: tuple[str, ...], since: int) -> dict:
    """The first event on ``key`` of one of ``kinds`` after the first ``since`` events seen."""
    return p.wait_event(R, lambda e: e["key"] == key and e["kind"] in kinds
                        and p.events(R).index(e) >= since, timeout_s=30)


def arm(p: Probe, component: str, kind: str, body: dict) -> dict:
    key = armed_key(component, kind)
    since = len(p.events(R))
    p.put(key, msgspec.json.encode(body))
    ev = answer(p, key, ("fault_armed", "rejected"), since)
    assert ev["kind"] == "fault_armed", ev
    return ev


def kinds_on(p: Probe, key: str) -> list[str]:
    return [e["kind"] for e in p.events(R) if e["key"] == key]


def test_a_fault_armed_in_s_warns_then_fires_as_the_instructors_injection(armed_twin):
    p, _ = armed_twin
    key, fault = armed_key("solar/left", "dust"), keys.fault(R, "solar/left", "dust")
    armed = arm(p, "solar/left", "dust", {"value": 0.5, "in_s": 20, "warn_s": 8})
    assert armed["actor"] == "instructor" and armed["params"]["due_t_s"] == pytest.approx(
        armed["t_s"] + 20)
    (listed,) = p.get_json(keys.faults_armed(R))
    assert [(a["fault"], a["value"], a["in_s"]) for a in listed] == [("solar/left/dust", 0.5, 20.0)]
    warned = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_warned", timeout_s=30)
    fired = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_fired", timeout_s=30)
    injected = p.wait_event(R, lambda e: e["key"] == fault and e["kind"] == "fault_injected")
    due = armed["params"]["due_t_s"]
    assert due - 8 <= warned["t_s"] < due and fired["t_s"] >= due
    assert warned["severity"] == "warning" and "fires in 8 s" in warned["message"]
    assert injected["actor"] == "instructor" and injected["params"]["fraction"] == 0.5
    events = p.events(R)
    assert events.index(armed) < events.index(warned) < events.index(fired) < events.index(injected)
    p.wait_value(keys.solar_power(R, "left"), lambda v: v["power_w"] < 15)  # its effect
    assert p.get_json(keys.faults_armed(R)) == [[]]
    p.delete(fault)
    p.wait_event(R, lambda e: e["key"] == fault and e["kind"] == "fault_cleared")


def test_a_conditional_fault_warns_when_its_condition_holds_and_fires_warn_s_later(armed_twin):
    p, _ = armed_twin
    key = armed_key("radio/lander", "failure")
    soc = p.value(keys.battery_state(R))["soc"]
    below = round(soc - 0.0003, 6)  # a few seconds of sim time of MAPP's drain below now
    arm(p, "radio/lander", "failure", {"when": f"battery.soc < {below}", "warn_s": 5})
    warned = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_warned", timeout_s=60)
    assert p.value(keys.battery_state(R))["soc"] < below
    assert f"battery.soc < {below} holds" in warned["message"]
    fired = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_fired", timeout_s=30)
    # due warn_s after it held, fired at a tick from then (the exact tick: the unit tests; here
    # a busy machine's clock may step more than 1 s of sim time at once)
    assert warned["params"]["due_t_s"] == pytest.approx(warned["t_s"] + 5)
    assert fired["t_s"] >= warned["params"]["due_t_s"]
    fault = keys.fault(R, "radio/lander", "failure")
    p.wait_event(R, lambda e: e["key"] == fault and e["kind"] == "fault_injected")
    p.delete(fault)
    p.wait_event(R, lambda e: e["key"] == fault and e["kind"] == "fault_cleared")


def test_a_fault_cancelled_during_its_warning_never_fires(armed_twin):
    p, _ = armed_twin
    key = armed_key("battery", "heating")
    armed = arm(p, "battery", "heating", {"value": 30, "in_s": 40, "warn_s": 35})
    p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_warned", timeout_s=30)
    since = len(p.events(R))
    p.delete(key)
    cancelled = answer(p, key, ("fault_cancelled", "rejected"), since)
    assert cancelled["kind"] == "fault_cancelled" and cancelled["actor"] == "instructor"
    due = armed["params"]["due_t_s"]
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > due + 5)  # well past when it was due
    assert "fault_fired" not in kinds_on(p, key)
    assert not [e for e in p.events(R) if e["key"] == keys.fault(R, "battery", "heating")]
    journal = {e["kind"] for e in p.get_json(keys.faults_journal(R))[0]}
    assert {"fault_armed", "fault_warned", "fault_cancelled"} <= journal  # (fired: the test above)


def test_a_bad_arming_is_rejected_in_words(armed_twin):
    p, _ = armed_twin
    for component, kind, body, said in [
            ("battery", "heating", {"value": 30}, "exactly one of at_t_s"),
            ("battery", "heating", {"value": 30, "when": "battery.soc < lots"}, "is a number"),
            ("load/ghost", "open", {"in_s": 5}, "has no load 'ghost'"),
            ("battery", "melt", {"in_s": 5}, "unknown battery fault kind")]:
        key = armed_key(component, kind)
        since = len(p.events(R))
        p.put(key, msgspec.json.encode(body))
        ev = answer(p, key, ("fault_armed", "rejected"), since)
        assert ev["kind"] == "rejected" and said in ev["message"], ev
    since = len(p.events(R))
    p.delete(armed_key("umbilical", "disconnect"))
    assert "nothing to cancel" in answer(p, armed_key("umbilical", "disconnect"), ("rejected",),
                                         since)["message"]
    assert p.get_json(keys.faults_armed(R)) == [[]]


def test_armed_faults_outlive_a_restart_and_end_with_their_session(armed_twin):
    p, t = armed_twin
    key, later = armed_key("umbilical", "disconnect"), armed_key("solar/right", "disconnect")
    armed = arm(p, "umbilical", "disconnect", {"in_s": 80, "warn_s": 5})  # 8 s of wall time
    arm(p, "solar/right", "disconnect", {"in_s": 100000})
    stop_processes([t.procs["faults"]])
    t.start("faults")
    p.wait_services(R, ("faults",))
    (listed,) = wait_for(lambda: p.get_json(keys.faults_armed(R)) or None, 10, "the armed list")
    assert {a["key"] for a in listed} == {key, later}
    fired = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_fired", timeout_s=30)
    assert fired["t_s"] >= armed["params"]["due_t_s"]
    since = len(p.events(R))
    p.put(keys.control_session(R), {"trainee": "next"})
    ended = answer(p, later, ("fault_cancelled",), since)
    assert "session ended" in ended["params"]["reason"] and ended["actor"] == "twin"
    assert ended["session"] == armed["session"]  # journalled in the session it ended with
    assert p.get_json(keys.faults_armed(R)) == [[]]
