"""The client layer without a twin: the mirror fed by hand with a clock of the test's own, the
link judged from ticks, the one table of answers, writes checked before they are sent."""

from __future__ import annotations

import msgspec
import pytest

from common import keys
from common.messages import BadInput, Clock, Event, LoadPower
from common.writes import FAULT_OWNERS, answer_of, plan_write
from lunaris.client import EventWindow, Mirror, event_identity
from lunaris.client.link import LinkTracker
from lunaris.client.writer import _answers

R = "mapp-1"


class FakeClock:
    def __init__(self, t: float = 1_000_000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def tick(t_s: float) -> bytes:
    return msgspec.json.encode(Clock(t_s=t_s, dt_s=0.1, seq=int(t_s * 10), time_scale=1.0, paused=False))


def event(seq: int, source: str = "battery", kind: str = "fault_injected", source_id: str = "abc",
          key: str = "lunaris/mapp-1/fault/battery/heating") -> bytes:
    return msgspec.json.encode(Event(t_s=1.0, severity="info", source=source, kind=kind, key=key,
                                     message="m", source_id=source_id, seq=seq))


def load(power_w: float = 3.0) -> bytes:
    return msgspec.json.encode(LoadPower(t_s=1.0, power_w=power_w, rail="12V", on=True, faults=[]))


# -- events ------------------------------------------------------------------------------------


def test_an_event_is_named_by_its_publisher_and_count_and_taken_once_in_a_bounded_window():
    a = msgspec.json.decode(event(1), type=Event)
    assert event_identity(R, a) == ("abc", 1) == event_identity(R, msgspec.structs.asdict(a))
    old = msgspec.structs.replace(a, source_id="", seq=0)  # a publisher that does not number
    assert event_identity(R, old) == (R, 1.0, "battery", "fault_injected", a.key, "m")
    w = EventWindow(size=3)
    assert [w.first(i) for i in (1, 2, 1, 3, 4)] == [True, True, False, True, True]
    assert len(w) == 3 and w.first(1)  # 1 fell out of the window of 3


def test_the_mirror_takes_an_event_once_from_the_service_s_key_and_the_journal_s():
    m = Mirror(R, clock=FakeClock())
    assert m.feed(keys.event(R) + "/battery", event(1)) is not None
    assert m.feed(keys.event(R), event(1)) is None  # the journal's copy
    assert m.feed(keys.event(R), event(2)) is not None
    # on a service's own key, an event must be that service's (D1)
    assert m.feed(keys.event(R) + "/bridge", event(3, source="battery")) is None
    assert [ev.seq for _, ev, _ in m.events(R)] == [1, 2]


# -- values, bounds, forgetting ----------------------------------------------------------------


def test_values_are_decoded_by_their_family_and_a_bad_one_is_skipped():
    m = Mirror(R, families=["load/*/power"], clock=FakeClock())
    key = keys.load_power(R, "imu")
    assert m.feed(key, load(3.0)).kind == "value"
    assert m.value(key).power_w == 3.0
    assert m.feed(key, b'{"power_w": "lots"}') is None and m.value(key).power_w == 3.0
    assert m.feed(keys.battery_state(R), b"{}") is None  # a family it was not asked for


def test_history_keeps_one_point_per_interval_and_a_bounded_number():
    clock = FakeClock()
    m = Mirror(R, families=["load/*/power"], history={"load/*/power": 3}, history_every_s=1.0,
               clock=clock)
    key = keys.load_power(R, "imu")
    for i in range(20):
        clock.t += 0.25
        m.feed(key, load(float(i)))
    assert [v.value.power_w for v in m.history(key)] == [8.0, 12.0, 16.0]
    assert m.value(key).power_w == 19.0


def test_unknown_rovers_and_forged_names_are_bounded_and_forgotten():
    clock = FakeClock()
    m = Mirror("*", max_rovers=5, max_names=4, clock=clock)
    m.feed_token(keys.service(R, "clock"), True)
    for i in range(50):  # forged rover ids: room is made by forgetting the quietest stranger
        clock.t += 0.1
        m.feed(keys.load_power(f"x{i}", "imu"), load())
    assert m.stats()["rovers"] == 5 and R in m.rovers()
    for i in range(50):  # forged component names of a real rover
        m.feed(keys.load_power(R, f"n{i}"), load())
    assert len(m.latest(R)) == 4
    clock.t += 60.0  # strangers are forgotten after 30 s; a rover with live services is not
    gone = m.sweep()
    assert R not in gone and m.rovers() == [R] and len(gone) >= 4
    m.feed_token(keys.service(R, "clock"), False)
    clock.t += 601.0
    assert m.sweep() == [R] and m.stats() == {"rovers": 0, "keys": 0, "events": 0, "history": 0,
                                              "bytes": 0, "event_window": 0}


def test_a_sample_larger_than_any_telemetry_is_skipped():
    m = Mirror(R, families=["load/*/power"], clock=FakeClock())
    big = msgspec.json.encode(LoadPower(t_s=1.0, power_w=1.0, rail="x" * 40_000, on=True, faults=[]))
    assert m.feed(keys.load_power(R, "imu"), big) is None


# -- the link ------------------------------------------------------------------------------------


def test_the_link_is_lost_two_seconds_after_the_last_tick_and_comes_back_with_the_next():
    clock = FakeClock()
    m = Mirror(R, families=["clock"], clock=clock)
    assert m.link(R).state == "unknown"
    for i in range(10):
        clock.t += 0.1
        m.feed(keys.clock(R), tick(i / 10))
    assert m.link(R).state == "up"
    cut = clock.t
    clock.t += 1.9
    assert m.link(R).state == "up"
    clock.t += 0.2
    link = m.link(R)
    assert link.state == "lost" and link.since == cut and "no clock tick since" in link.reason
    clock.t += 10
    m.feed(keys.clock(R), tick(2.0))
    assert m.link(R).state == "up" and m.link(R).since == clock.t


def test_the_link_is_lost_at_once_when_the_clock_s_token_goes():
    clock = FakeClock()
    m = Mirror(R, families=["clock"], clock=clock)
    m.feed_token(keys.service(R, "clock"), True)
    m.feed(keys.clock(R), tick(0.0))
    m.feed_token(keys.service(R, "clock"), False)
    link = m.link(R)
    assert link.state == "lost" and "liveliness token went away" in link.reason
    m.feed_token(keys.service(R, "clock"), True)
    clock.t += 0.1
    m.feed(keys.clock(R), tick(0.1))
    assert m.link(R).state == "up"


def test_a_clock_seen_live_that_never_ticks_is_a_lost_link():
    t = LinkTracker()
    t.clock_token(True, 0.0)
    assert t.state(1.0).state == "unknown" and t.state(2.5).state == "lost"


def test_a_rover_asked_for_that_never_ticks_since_the_tool_connected_is_a_lost_link():
    """A tool started during a partition hears nothing of the rover: it says the link is lost
    (within the link's 2 s), not "waiting" until its own timeout."""
    clock = FakeClock()
    m = Mirror(R, families=["clock"], clock=clock)
    m.started_at, m.connected = clock.t, True  # what start() and the router's answer set
    clock.t += 1.5
    assert m.link(R).state == "unknown"
    clock.t += 1.0
    link = m.link(R)
    assert link.state == "lost" and "since this tool connected" in link.reason, link


def test_a_slow_clock_is_not_taken_for_a_cut():
    t = LinkTracker()
    for i in range(10):  # 0.2 Hz
        t.tick(i * 5.0)
    assert t.state(45.0 + 9.0).state == "up" and t.state(45.0 + 13.0).state == "lost"


# -- writes: checked, and the one table of answers ---------------------------------------------


@pytest.mark.parametrize("tail, delete, answer", [
    ("fault/battery/heating", False, ("fault_injected", "battery")),
    ("fault/battery/heating", True, ("fault_cleared", "battery")),
    ("fault/load/imu/short", False, ("fault_injected", "loads")),
    ("fault/rail/12V/fail", False, ("fault_injected", "power")),
    ("fault/umbilical/disconnect", False, ("fault_injected", "solar")),
    ("fault/radio/lander/degraded", True, ("fault_cleared", "radio")),
    ("cmd/rail/12V", False, ("command", "power")),
    ("clock/control", False, ("clock", "clock")),
    ("input/sun_angle", False, ("input", "solar")),
    ("input/solar/left/dust", True, ("input", "solar")),
    ("input/radio/lander/position", False, ("input", "radio")),
    ("input/umbilical", False, ("input", "solar")),
    ("input/drive/traverse", True, ("input", "drive")),
    ("control/reset", False, ("session", "faults")),
    ("control/snapshot/a", False, ("session", "faults")),
    ("control/scenario", False, ("scenario", "faults")),
])
def test_one_table_says_which_event_answers_a_write_and_who_sends_it(tail, delete, answer):
    assert answer_of(tail.split("/"), delete) == answer
    assert set(FAULT_OWNERS.values()) <= {f.owner for f in keys.FAMILIES}


@pytest.mark.parametrize("tail, payload, words", [
    ("fault/*/heating", b"3", "is a wildcard"),
    ("fault/battery/**", b"3", "is a wildcard"),
    ("input/$*", b"3", "is a wildcard"),
    ("input/sun$*", b"3", "is a wildcard"),
    ("@/input/sun_angle", b"3", "verbatim chunk"),
    ("input/sun angle", b"3", "holds characters no key of the twin has"),
    ("input/sun_angle", b"1" + b"0" * 5000, "has 5,001 digits: far too long for an input"),
    ("input/sun_angle", b'{"angle_deg": "\\ud800"}', "not valid Unicode"),
    ("input/sun_angle", b"500", "angle_deg must be at most 360"),
])
def test_a_write_that_cannot_be_valid_is_refused_in_words_before_it_is_sent(tail, payload, words):
    from lunaris.client import humane
    with pytest.raises(BadInput) as err:
        plan_write(R, tail, payload)
    assert words in humane(str(err.value))


def test_an_answer_is_the_owner_s_accepting_event_or_any_rejection_of_the_key():
    w = plan_write(R, "fault/battery/heating", b"5")
    ev = msgspec.json.decode(event(1), type=Event)
    assert _answers(w, ev)
    assert not _answers(w, msgspec.structs.replace(ev, source="bridge"))  # not its owner
    assert _answers(w, msgspec.structs.replace(ev, source="faults", kind="rejected"))
    assert not _answers(w, msgspec.structs.replace(ev, key=keys.fault(R, "battery", "other")))
    assert not _answers(w, msgspec.structs.replace(ev, kind="fault_cleared"))
