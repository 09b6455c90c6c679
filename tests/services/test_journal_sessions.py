"""The journal's sessions (services/faults/sessions.py), from events given by hand: each
session's trainee and start from the clock's event that opens it (the rule the tools share,
common.events.session_opened), its end from the one that closes it."""

from __future__ import annotations

from typing import Any

from common.messages import Event
from services.faults.sessions import SessionIndex


def ev(t_s: float, session: str, kind: str = "fault_injected", source: str = "loads",
       params: dict[str, Any] | None = None) -> Event:
    return Event(t_s=t_s, severity="info", source=source, kind=kind,  # type: ignore[arg-type]
                 key="lunaris/mapp-1/x", message="m", params=params, session=session)


def opens(t_s: float, sid: str, trainee: str) -> Event:
    return ev(t_s, sid, "session", "clock", {"session": sid, "trainee": trainee,
                                             "from_snapshot": None, "started_wall": 1.8e9,
                                             "start_t_s": t_s})


def closes(t_s: float, sid: str, trainee: str) -> Event:
    return ev(t_s, sid, "session", "clock", {"session": sid, "trainee": trainee, "end_t_s": t_s})


def test_each_session_has_its_trainee_start_and_end_from_the_clock_events() -> None:
    index = SessionIndex()
    lines = [opens(0.0, "20261125-100000", "Ana"), ev(3.0, "20261125-100000"),
             closes(35.0, "20261125-100000", "Ana"), opens(0.0, "20261125-100001", "Ben"),
             ev(1.0, "20261125-100001")]
    assert [index.note(e) for e in lines] == ["20261125-100000"] * 3 + ["20261125-100001"] * 2
    ana, ben = index.infos()
    assert (ana.trainee, ana.start_t_s, ana.end_t_s, ana.events) == ("Ana", 0.0, 35.0, 3)
    assert (ben.trainee, ben.start_t_s, ben.end_t_s, ben.events) == ("Ben", 0.0, None, 2)
    assert ben.started_wall == 1.8e9 and ben.from_snapshot is None


def test_a_session_event_of_another_source_or_session_names_no_trainee() -> None:
    index = SessionIndex()
    forged = opens(0.0, "20261125-100000", "Mallory")
    index.note(Event(**{**{f: getattr(forged, f) for f in forged.__struct_fields__},
                        "source": "loads"}))  # not the clock's
    index.note(ev(1.0, "20261125-100000", "session", "clock",
                  {"session": "20261125-090000", "trainee": "Eve", "started_wall": 1.0}))
    (only,) = index.infos()
    assert only.trainee == ""
