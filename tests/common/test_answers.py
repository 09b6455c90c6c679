"""The one waiting for a write's answer (common/answers.py), without Zenoh: which event
answers which write, each event taken once, the first answer wins, a deadline passes."""

from __future__ import annotations

import pytest

from common.answers import Accepted, Awaiting, NotApplied, Pending, Rejected
from common.messages import BadInput, Event
from common.writes import plan_write, stand_in

RAIL = plan_write("mapp-1", "cmd/rail/5V_CH2", b'{"on": false}')


def event(kind: str, source: str = "power", key: str = RAIL.key, seq: int = 1,
          message: str = "rail 5V_CH2: on=false; the rail is now off") -> Event:
    return Event(t_s=1.0, severity="info", source=source, kind=kind, key=key, message=message,
                 source_id="z1", seq=seq, actor="crew")


def test_the_owners_accepting_event_answers_once_and_calls_back():
    awaiting, got = Awaiting(), []
    p = awaiting.add(Pending(RAIL, deadline=10.0, on_answer=got.append))
    assert awaiting.hear("mapp-1", ["event", "power"], event("input")) is None  # not its kind
    assert awaiting.hear("mapp-1", ["event", "power"], event("command", key="lunaris/mapp-1/cmd/rail/12V",
                                                             seq=2)) is None  # another key
    assert awaiting.hear("mapp-1", ["event", "power"], event("command", seq=3)) is p
    assert isinstance(p.answer, Accepted) and p.done.is_set() and got == [p.answer]
    assert p.answer.message == "rail 5V_CH2: on=false; the rail is now off"
    assert len(awaiting) == 0


def test_a_rejection_by_anyone_answers_in_words_and_a_forged_source_does_not():
    awaiting = Awaiting()
    p = awaiting.add(Pending(RAIL, deadline=10.0))
    # on the power service's own key, an event that says it comes from the battery: no answer
    assert awaiting.hear("mapp-1", ["event", "power"], event("rejected", source="battery")) is None
    assert awaiting.hear("mapp-1", ["event", "faults"], event(
        "rejected", source="faults", seq=4, message="rejected: rover mapp-1 has no rail 'x'")) is p
    assert isinstance(p.answer, Rejected) and p.answer.message == "rover mapp-1 has no rail 'x'"


def test_an_event_heard_twice_answers_one_write_and_the_first_answer_wins():
    awaiting = Awaiting()
    first, second = (awaiting.add(Pending(RAIL, deadline=10.0)) for _ in range(2))
    ev = event("command", seq=7)
    assert awaiting.hear("mapp-1", ["event", "power"], ev) is first
    assert awaiting.hear("mapp-1", ["event"], ev) is None  # the journal's copy of the same event
    assert second.answer is None
    late = NotApplied(RAIL, "not applied: no answer", False, True)
    assert not awaiting.settle(first, late) and isinstance(first.answer, Accepted)


def test_a_write_past_its_deadline_is_no_longer_waited_for():
    awaiting = Awaiting()
    soon, later = awaiting.add(Pending(RAIL, deadline=1.0)), awaiting.add(Pending(RAIL, deadline=5.0))
    assert awaiting.overdue(now=2.0) == [soon]
    assert awaiting.withdraw(soon) is None and len(awaiting) == 1
    assert awaiting.hear("mapp-1", ["event", "power"], event("command", seq=9)) is later


def test_a_stand_in_for_the_crew_makes_only_what_the_crew_makes():
    """The crew's rail commands and its stop (a delete of the traverse) are the crew's when the
    instructor stands in; a traverse sent, an input or a fault is refused in words."""
    rail = plan_write("mapp-1", "cmd/rail/5V_CH2", b'{"on": false}')
    stop = plan_write("mapp-1", "input/drive/traverse", None)
    assert (stand_in(rail).actor, stand_in(stop).actor, rail.actor) == ("crew", "crew", None)
    route = plan_write("mapp-1", "input/drive/traverse", b'{"waypoints": [{"x_m": 1, "y_m": 1, "z_m": 0}]}')
    sun = plan_write("mapp-1", "input/sun_angle", b"30")
    heat = plan_write("mapp-1", "fault/battery/heating", b"1")
    for write, words in ((route, "does not send it a traverse"),
                         (sun, "send input/sun_angle as the instructor"),
                         (heat, "cannot write fault/battery/heating")):
        with pytest.raises(BadInput, match=words):
            stand_in(write)
