"""Trainee sessions without a twin (SPEC §12c): the session's id, the clock's record of it, the
journal's segments, the one table of answers, and the tools that start empty with each
session (the client's mirror, the console's stream, ``lunaris watch``'s frame)."""

from __future__ import annotations

import asyncio
import json

import msgspec
import pytest

from common import keys
from common.messages import BadInput, BatteryState, Clock, Event, SessionStart, TimelineMark, decode_input
from common.writes import answer_of, plan_write
from lunaris.client import Mirror, Session
from lunaris.console.live import Hub
from lunaris.watch import render, snapshot_of
from lunaris.watch_view import Connection
from services.clock.model import ClockModel, session_id
from services.faults.journal import Journal

pytestmark = [pytest.mark.unit, pytest.mark.timeout(30)]

R = "mapp-1"
S1, S2, S3 = "20250114-195312", "20250114-195500", "20250114-200000"


class FakeClock:
    def __init__(self, t: float = 1_000_000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def tick(t_s: float, session: str, epoch: int = 1) -> bytes:
    return msgspec.json.encode(Clock(t_s=t_s, dt_s=0.1, seq=int(t_s * 10) + 1, time_scale=1.0,
                                     paused=False, epoch=epoch, cause="reset", session=session))


def ev(seq: int, session: str, kind: str = "fault_injected", source: str = "battery",
       t_s: float = 1.0, message: str = "m", params: dict | None = None) -> Event:
    return Event(t_s=t_s, severity="info", source=source, kind=kind,
                 key=keys.fault(R, "battery", "heating"), message=message, params=params,
                 source_id=f"id-{source}", seq=seq, session=session)


def opening(seq: int, session: str, trainee: str, start_t_s: float = 0.0) -> Event:
    """The clock's event that opens a session."""
    params: dict = {"session": session, "trainee": trainee, "from_snapshot": None,
                    "started_wall": 1.7e9 + seq, "start_t_s": start_t_s}
    return ev(seq, session, "session", "clock", start_t_s, f"session {session} begins", params)


def closing(seq: int, session: str, end_t_s: float) -> Event:
    """The clock's event that closes a session."""
    return ev(seq, session, "session", "clock", end_t_s, f"session {session} ends",
              {"session": session, "trainee": "", "end_t_s": end_t_s})


def battery(soc: float) -> bytes:
    return msgspec.json.encode(BatteryState(
        t_s=1.0, energy_j=1.0, capacity_j=2.0, soc=soc, ocv_v=28.0, voltage_v=28.0, current_a=1.0,
        power_w=28.0, temperature_c=20.0, operational=True, fault_code=0, faults=[],
        time_to_empty_s=None))


# -- the id, and the clock's record of the session ------------------------------------------------


def test_a_session_id_is_its_utc_second_and_always_later_than_the_previous_one():
    assert session_id(1736884392.7) == "20250114-195312"
    # within the second of the one before, or behind it: counted, never a second ahead (issue 32)
    assert session_id(1736884392.7, after="20250114-195312") == "20250114-195312.001"
    assert session_id(1736884392.7, after="20250114-195359") == "20250114-195359.001"
    assert session_id(1736884400.0, after="20250114-195312") == "20250114-195320"
    assert session_id(1736884392.0, after="not an id") == "20250114-195312"


def test_the_clock_keeps_its_session_through_resets_and_restores_of_earlier_snapshots():
    clock = ClockModel(10.0)
    clock.begin_session("", 1736884392.0)
    saved_in_first = clock.state()  # a snapshot of the first session
    clock.reset()
    second = clock.begin_session("Ana", 1736884500.0)
    assert second == "20250114-195500" and clock.session_epoch == clock.epoch == 1
    clock.reset()  # a reset within the session keeps it
    assert clock.session == second and clock.trainee == "Ana"
    clock.set_state(saved_in_first)  # a restore of the first session's snapshot
    assert (clock.session, clock.trainee) == (second, "Ana")
    restarted = ClockModel(10.0)  # a restart reads its own state back: the session with it
    restarted.set_state(clock.state())
    assert (restarted.session, restarted.trainee, restarted.tick().session) == (second, "Ana", second)


# -- what a write on control/session or control/mark is, before it is sent -------------------------


def test_the_clock_answers_a_session_and_a_restore_the_faults_service_a_mark():
    assert answer_of(["control", "session"], False) == ("session", "clock")
    assert answer_of(["control", "restore", "x"], False) == ("session", "clock")
    assert answer_of(["control", "mark"], False) == ("mark", "faults")
    assert answer_of(["control", "reset"], False) == ("session", "faults")
    w = plan_write(R, "control/session", b'{"trainee": "Ana Lopez", "from_snapshot": "before-storm"}')
    assert json.loads(w.payload) == {"trainee": "Ana Lopez", "from_snapshot": "before-storm"}
    assert json.loads(plan_write(R, "control/mark", b'{"text": "crew saw it"}').payload) == {
        "text": "crew saw it"}


@pytest.mark.parametrize(("tail", "payload", "words"), [
    ("control/session", b'{"trainee": ""}', "give the trainee's name"),
    ("control/session", b'{"trainee": "   "}', "give the trainee's name"),
    ("control/session", b'{"trainee": "a/b"}', "this one has '/'"),
    ("control/session", b'{"trainee": " Ana"}', "without spaces before or after"),
    ("control/session", b'{"trainee": "' + b"x" * 65 + b'"}', "at most 64 characters"),
    ("control/session", b'{}', "trainee is missing"),
    ("control/session", b'{"trainee": "Ana", "from_snapshot": "a b"}', "names no snapshot"),
    ("control/session", None, "a put, not a delete"),
    ("control/mark", b'{"text": ""}', "text must not be empty"),
    ("control/mark", b'{"text": "two\\nlines"}', "one line"),
    ("control/mark", b'{"note": "x"}', "'note' is not a field"),
])
def test_a_bad_session_or_mark_is_refused_in_words(tail, payload, words):
    with pytest.raises(BadInput, match=words):
        plan_write(R, tail, payload)


def test_names_of_any_script_are_trainees():
    for name in ("Zoë Ångström", "crew-2", "O'Brien & Li", "Ана"):
        assert decode_input(json.dumps({"trainee": name}).encode(), SessionStart).trainee == name
    assert decode_input(b'{"text": "crew isolated the rail"}', TimelineMark).text


# -- the journal's segments -------------------------------------------------------------------------


def test_the_journal_lists_its_sessions_and_gives_each_its_own_events(tmp_path):
    path = tmp_path / "journal.jsonl"
    j = Journal(path, rover=R)
    j.record(ev(1, "", "session", "faults", message="journal opened"), 0.0)  # before any tick
    j.record(opening(1, S1, ""), 0.0)
    j.record(ev(2, S1, t_s=5.0), 0.0)
    j.record(closing(2, S1, 7.5), 0.0)
    j.record(opening(3, S2, "Ana"), 0.0)
    j.record(ev(3, S1, "fault_cleared", t_s=7.5), 0.0)  # the first session's clearing, late
    j.record(ev(4, S2, t_s=2.0), 0.0)
    j.record(ev(5, "", "mark", "faults", t_s=3.0), 0.0)  # no session said: the running one
    infos = j.session_infos()
    assert [(i.id, i.trainee, i.start_t_s, i.end_t_s, i.events) for i in infos] == [
        (S1, "", 0.0, 7.5, 5), (S2, "Ana", 0.0, None, 3)]
    assert infos[1].started_wall == 1.7e9 + 3

    def seqs(session: str | None) -> list[tuple[str, int]]:
        return [(e["source"], e["seq"]) for e in map(json.loads, j.lines(session))]
    assert seqs(S1) == [("faults", 1), ("clock", 1), ("battery", 2), ("clock", 2), ("battery", 3)]
    assert seqs(S2) == [("clock", 3), ("battery", 4), ("faults", 5)]
    assert len(seqs(None)) == 8
    # read back after a restart: the same sessions, the same segments
    again = Journal(path, rover=R)
    assert again.session_infos() == infos and [json.loads(x)["seq"] for x in again.lines(S2)] == [3, 4, 5]
    # a running session the journal has no event of yet (the tick said it first): listed last
    assert [(i.id, i.end_t_s) for i in j.session_infos(running=S3)][-2:] == [(S2, 3.0), (S3, None)]


# -- the tools start empty with each session --------------------------------------------------------


def test_the_mirror_drops_the_previous_session_s_history_and_events_when_a_new_one_ticks():
    clock = FakeClock()
    m = Mirror(R, families=["clock", "battery/state"], history={"battery/state": 10},
               history_every_s=1.0, clock=clock)
    told = []
    m.listen(lambda c: told.append(c) if c.kind == "session" else None)
    # replayed from the caches as the tool joins: an event of an older session, then the tick
    m.feed(keys.event_of(R, "battery"), msgspec.json.encode(ev(1, "20250101-000000")))
    m.feed(keys.clock(R), tick(1.0, S1))
    m.feed(keys.event_of(R, "clock"), msgspec.json.encode(opening(1, S1, "Ana")))
    assert m.session_of(R) == Session(S1, "Ana") and [e.seq for _, e, _ in m.events(R)] == [1]
    for i in range(3):
        clock.t += 1.0
        m.feed(keys.battery_state(R), battery(0.9 - i / 100))
    m.feed(keys.event_of(R, "battery"), msgspec.json.encode(ev(2, S1)))
    assert len(m.history(keys.battery_state(R))) == 3 and len(m.events(R)) == 2
    # the next trainee's: the clock's event comes before its first tick
    m.feed(keys.event_of(R, "clock"), msgspec.json.encode(opening(2, S2, "Ben")))
    assert [e.seq for _, e, _ in m.events(R)] == [1, 2]  # not read before the tick says so
    m.feed(keys.clock(R), tick(0.0, S2, epoch=2))
    assert m.session_of(R) == Session(S2, "Ben")
    assert m.history(keys.battery_state(R)) == []
    assert [(e.source, e.seq) for _, e, _ in m.events(R)] == [("clock", 2)]
    # a late event of the first trainee's session is not kept
    assert m.feed(keys.event_of(R, "battery"), msgspec.json.encode(ev(3, S1))) is None
    assert [(e.source, e.seq) for _, e, _ in m.events(R)] == [("clock", 2)]
    assert [c.value for c in told] == [Session(S1, None), Session(S1, "Ana"), Session(S2, "Ben")]


def test_watch_names_the_trainee_and_shows_the_session_s_events_only():
    m = Mirror(R, clock=FakeClock())
    m.feed(keys.clock(R), tick(1.0, S1))
    m.feed(keys.event_of(R, "clock"), msgspec.json.encode(opening(1, S1, "Ana")))
    m.feed(keys.event_of(R, "faults"), msgspec.json.encode(
        ev(1, S1, "mark", "faults", message="mark: ana's drill")))
    m.feed(keys.event_of(R, "clock"), msgspec.json.encode(opening(2, S2, "Ben")))
    m.feed(keys.clock(R), tick(0.0, S2, epoch=2))
    m.feed(keys.event_of(R, "faults"), msgspec.json.encode(
        ev(2, S2, "mark", "faults", message="mark: ben's drill")))
    from rich.console import Console
    for width in (80, 160):
        console = Console(width=width, record=True, color_system=None)
        console.print(render(snapshot_of(m), Connection("test"), R, 8, width=width, height=24))
        text = console.export_text()
        assert "Ben" in text and S2 in text and "ben's drill" in text
        assert "ana's drill" not in text and "Ana" not in text, text


def test_watch_lists_what_came_after_a_reset_within_a_session_as_the_latest():
    """A drill's reset within Ben's session starts the clock again: its events (at 30 s) are
    the latest, not the snapshot saved at 102 s before it (watch sorted by sim time alone)."""
    m = Mirror(R, clock=FakeClock())
    m.feed(keys.clock(R), tick(100.0, S1))
    for seq, kind, t, message in ((1, "mark", 102.6, "snapshot saved"),
                                  (2, "fault_injected", 101.0, "before the reset"),
                                  (3, "session", 102.9, "session reset")):
        e = ev(seq, S1, kind, "faults", t_s=t, message=message)
        if kind == "session":
            e = msgspec.structs.replace(e, key=keys.under(R, "control/reset"))
        m.feed(keys.event_of(R, "faults"), msgspec.json.encode(e))
    m.feed(keys.clock(R), tick(0.0, S1, epoch=2))
    m.feed(keys.event_of(R, "loads"), msgspec.json.encode(ev(1, S1, "fault_raised", "loads", t_s=30.1,
                                                             message="after the reset")))
    m.feed(keys.event_of(R, "faults"), msgspec.json.encode(ev(4, S1, "mark", "faults", t_s=30.0,
                                                              message="mark: the drill")))
    said = [e.message for _, e in snapshot_of(m).events]
    assert said == ["before the reset", "snapshot saved", "session reset", "mark: the drill",
                    "after the reset"], said


def test_the_console_sends_every_page_a_snapshot_empty_of_the_last_session():
    async def run() -> tuple[dict, dict]:
        hub = Hub(asyncio.get_running_loop(), flush_s=0.0, clock=FakeClock())
        hub.mirror.listen(hub._hand)
        hub.mirror.feed(keys.clock(R), tick(1.0, S1))
        hub.mirror.feed(keys.event_of(R, "clock"), msgspec.json.encode(opening(1, S1, "Ana")))
        hub.mirror.feed(keys.event_of(R, "battery"), msgspec.json.encode(ev(2, S1)))
        await asyncio.sleep(0.05)
        stream = hub.stream()
        first = json.loads((await anext(stream)).removeprefix(b"data: "))
        hub.mirror.feed(keys.clock(R), tick(0.0, S2, epoch=2))
        second = json.loads((await asyncio.wait_for(anext(stream), 5)).removeprefix(b"data: "))
        hub.stop()
        return first, second
    first, second = asyncio.run(run())
    assert first["type"] == "snapshot" and first["sessions"] == {R: {"id": S1, "trainee": "Ana"}}
    assert len(first["events"]) == 2
    assert second["type"] == "snapshot" and second["sessions"] == {R: {"id": S2, "trainee": None}}
    assert second["events"] == [] and second["history"] == {}
