"""Armed faults (SPEC 13b): the book on a manual clock, and the check of an arming.

Times are sim seconds derived by hand: armed at t=100 for ``in_s=30`` with ``warn_s=10`` is
due at 130 and warns at 120; a condition that first holds at t=7 with ``warn_s=5`` warns
at 7 and fires at 12.
"""

from __future__ import annotations

from unittest import mock

import msgspec
import pytest

from common.armed import parse_arm
from common.config import load_rover
from common.host import Sample
from common.messages import ArmFault, BadInput, Clock
from common.state_store import StateStore
from common.writes import answer_of, plan_write
from services.faults.armed import ArmedBook, arm
from services.faults.arming import Arms
from testbed.twin import static_rover

R = "mapp-1"
KEY = f"lunaris/{R}/faults/armed/battery/heating"


def _armed(body: dict, now: float = 100.0, key: str = KEY, epoch: int = 1, session: str = "s1"):
    parts = key.split("/")[4:]
    return arm(key, parse_arm(parts, msgspec.json.encode(body)), now, "instructor", epoch, session)


def _no_telemetry(parts: tuple[str, ...]) -> dict | None:
    return None


def test_a_timed_fault_warns_warn_s_before_and_fires_when_due() -> None:
    book = ArmedBook()
    book.arm(_armed({"value": 40, "in_s": 30, "warn_s": 10}))
    assert book.tick(119.9, _no_telemetry) == []
    steps = book.tick(120.0, _no_telemetry)  # 100 + 30 - 10
    assert [(w, a.fault) for w, a in steps] == [("warn", "battery/heating")]
    assert steps[0][1].warned_t_s == 120.0 and steps[0][1].due_t_s == 130.0
    assert book.tick(129.9, _no_telemetry) == []
    fired = book.tick(130.0, _no_telemetry)
    assert [w for w, _ in fired] == ["fire"]
    assert fired[0][1].payload == '{"heat_w":40.0}'  # the fault's put, as fault/... takes it
    assert len(book) == 0 and book.tick(140.0, _no_telemetry) == []


def test_at_t_s_is_a_sim_time_and_a_late_lead_warns_at_once() -> None:
    book = ArmedBook()
    book.arm(_armed({"at_t_s": 150, "warn_s": 20}, key=f"lunaris/{R}/faults/armed/umbilical/disconnect"))
    assert book.tick(129.0, _no_telemetry) == []
    assert [w for w, _ in book.tick(130.0, _no_telemetry)] == ["warn"]
    assert [w for w, _ in book.tick(150.0, _no_telemetry)] == ["fire"]
    late = ArmedBook()  # in 3 s with a 10 s warning: warned at the first tick, fired at 103
    late.arm(_armed({"value": 40, "in_s": 3}))
    assert [w for w, _ in late.tick(100.1, _no_telemetry)] == ["warn"]
    assert late.tick(102.9, _no_telemetry) == []
    assert [w for w, _ in late.tick(103.0, _no_telemetry)] == ["fire"]


def test_a_clock_that_jumps_past_the_time_warns_and_fires_in_one_tick() -> None:
    book = ArmedBook()
    book.arm(_armed({"value": 40, "in_s": 30}))
    assert [w for w, _ in book.tick(200.0, _no_telemetry)] == ["warn", "fire"]


def test_a_conditional_fault_warns_when_it_first_holds_and_fires_warn_s_later() -> None:
    soc = {"v": 0.95}

    def lookup(parts: tuple[str, ...]) -> dict | None:
        return {"soc": soc["v"]} if parts == ("battery", "state") else None

    book = ArmedBook()
    book.arm(_armed({"value": 40, "when": "battery.soc < 0.9", "warn_s": 5}, now=0.0))
    assert book.watched() == {("battery", "state")}
    assert book.tick(6.9, lookup) == []
    soc["v"] = 0.89
    steps = book.tick(7.0, lookup)
    assert [w for w, _ in steps] == ["warn"] and steps[0][1].due_t_s == 12.0
    assert book.watched() == set()  # warned: it no longer reads the battery
    soc["v"] = 0.95  # no longer holds: it fires all the same (a malfunction trigger)
    assert book.tick(11.9, lookup) == []
    assert [w for w, _ in book.tick(12.0, lookup)] == ["fire"]


def test_cancelled_during_its_warning_it_never_fires() -> None:
    book = ArmedBook()
    book.arm(_armed({"value": 40, "in_s": 30}))
    assert [w for w, _ in book.tick(120.0, _no_telemetry)] == ["warn"]
    gone = book.cancel(KEY)
    assert gone is not None and gone.warned_t_s == 120.0
    assert book.tick(130.0, _no_telemetry) == [] and book.cancel(KEY) is None


def test_arming_again_replaces_and_a_session_or_epoch_left_ends_them() -> None:
    book = ArmedBook()
    assert book.arm(_armed({"value": 40, "in_s": 30})) is None
    assert book.arm(_armed({"value": 80, "in_s": 60})) is not None
    assert [a.value for a in book.listed()] == [80]
    other = f"lunaris/{R}/faults/armed/umbilical/disconnect"
    book.arm(_armed({"in_s": 5}, key=other, epoch=2))
    assert [a.key for a in book.outside(2, "s1")] == [KEY]  # armed in epoch 1: reset since
    assert [a.key for a in book.outside(2, "s2")] == [other]  # a new session
    assert len(book) == 0


def test_the_book_saved_and_restored_goes_on_where_it_was() -> None:
    book = ArmedBook()
    book.arm(_armed({"value": 40, "in_s": 30}))
    book.tick(120.0, _no_telemetry)
    saved = msgspec.json.decode(msgspec.json.encode(book.saved()))
    again = ArmedBook()
    again.restore(saved)
    assert again.tick(125.0, _no_telemetry) == []  # warned already: not twice
    assert [w for w, _ in again.tick(130.0, _no_telemetry)] == ["fire"]
    with pytest.raises(ValueError, match="warn_s"):
        ArmedBook().restore([{**saved[0], "warn_s": "soon"}])


@pytest.mark.parametrize(("body", "match"), [
    ({"value": 40}, "exactly one of at_t_s .*got none"),
    ({"value": 40, "in_s": 5, "at_t_s": 9}, "got at_t_s, in_s"),
    ({"value": -1, "in_s": 5}, "value: heat_w must be at least 0"),
    ({"value": 40, "when": "battery.sox < 1"}, "unknown field 'sox' of battery"),
    ({"value": 40, "when": "rail.nope.state == off"}, "rover mapp-1 has no rail 'nope'"),
    ({"value": 40, "in_s": -5}, "in_s must be at least 0"),
    ({"value": 40, "in_s": 5, "warn": 3}, "'warn' is not a field"),
])
def test_a_bad_arming_is_refused_in_words(body: dict, match: str) -> None:
    rover = load_rover(static_rover("mapp.yaml"))
    with pytest.raises(BadInput, match=match):
        parse_arm(["battery", "heating"], msgspec.json.encode(body), rover)


def test_unknown_components_kinds_names_and_past_times_are_refused() -> None:
    rover = load_rover(static_rover("mapp.yaml"))
    with pytest.raises(BadInput, match="unknown component 'wheel'"):
        parse_arm(["wheel", "flat"], b'{"in_s": 5}', rover)
    with pytest.raises(BadInput, match="unknown battery fault kind 'melt'"):
        parse_arm(["battery", "melt"], b'{"in_s": 5}', rover)
    with pytest.raises(BadInput, match="has no load 'ghost'"):
        parse_arm(["load", "ghost", "open"], b'{"in_s": 5}', rover)
    with pytest.raises(BadInput, match="at_t_s=50 is past"):
        _armed({"value": 40, "at_t_s": 50}, now=100.0)


def test_the_tools_plan_an_arming_as_the_twin_checks_it() -> None:
    assert answer_of(["faults", "armed", "battery", "heating"], False) == ("fault_armed", "faults")
    assert answer_of(["faults", "armed", "battery", "heating"], True) == ("fault_cancelled", "faults")
    w = plan_write(R, "faults/armed/solar/left/dust", b'{"value": 0.6, "in_s": 20, "warn_s": 5}')
    assert msgspec.json.decode(w.payload)["value"] == 0.6
    with pytest.raises(BadInput, match="exactly one"):
        plan_write(R, "faults/armed/battery/heating", b'{"value": 40}')


# -- the faults service's side, on a manual clock (services.faults.arming) ----------------------


class _Runtime:
    """What :class:`~services.faults.arming.Arms` uses of a runtime: events kept, the state
    store in a folder, Zenoh a mock (a fired fault's put is read from it)."""

    def __init__(self, folder) -> None:
        self.t_s = {R: 0.0}
        self.events: list[dict] = []
        self.store = StateStore(folder, "faults")
        self.zenoh_session = mock.MagicMock()

    def event(self, rover, severity, kind, key, message, params=None, *, actor=None, t_s=None,
              session=None) -> None:
        self.events.append({"kind": kind, "key": key, "message": message, "params": params,
                            "actor": actor, "session": session, "t_s": self.t_s[rover]})

    def actor(self, sample: Sample) -> str:
        return "instructor"

    def save_state(self, what: str, data, durable: bool = True) -> bool:
        self.store.save(what, data, durable)
        return True

    def state_damaged(self, rover, message, key=None, params=None, severity="critical") -> None:
        self.event(rover, severity, "state_damaged", key or "", message)


def _tick(arms: Arms, rt: _Runtime, t_s: float, epoch: int = 1, session: str = "s1",
          cause: str = "") -> None:
    rt.t_s[R] = t_s
    arms.on_tick(R, Clock(t_s=t_s, dt_s=0.1, seq=int(t_s * 10), time_scale=1.0, paused=False,
                          epoch=epoch, cause=cause, session=session))


def _put(arms: Arms, tail: str, body: dict | None) -> None:
    key = f"lunaris/{R}/{tail}"
    payload = b"" if body is None else msgspec.json.encode(body)
    msg = None if body is None else msgspec.json.decode(payload, type=ArmFault)
    arms.on_arm(R, msg, Sample(key, R, tail.split("/"), payload, body is None))


def _service(folder) -> tuple[Arms, _Runtime]:
    rt = _Runtime(folder)
    arms = Arms(rt, {R: load_rover(static_rover("mapp.yaml"))})  # type: ignore[arg-type]
    return arms, rt


def test_the_service_arms_warns_fires_as_an_injection_and_keeps_them_on_disk(tmp_path) -> None:
    arms, rt = _service(tmp_path)
    with pytest.raises(BadInput, match="has not ticked yet"):
        _put(arms, "faults/armed/battery/heating", {"value": 40, "in_s": 30})
    _tick(arms, rt, 100.0)
    _put(arms, "faults/armed/battery/heating", {"value": 40, "in_s": 30})
    assert [e["kind"] for e in rt.events] == ["fault_armed"]
    assert "armed battery heating 40 at t=130.0 s, warning 10 s before" in rt.events[0]["message"]
    again, rt2 = _service(tmp_path)  # a restart: read back from the state folder
    again.load()
    _tick(again, rt2, 120.0)
    assert [e["kind"] for e in rt2.events] == ["fault_warned"]
    _tick(again, rt2, 130.0)
    assert [e["kind"] for e in rt2.events] == ["fault_warned", "fault_fired"]
    rt2.zenoh_session.put.assert_called_once()
    key, payload = rt2.zenoh_session.put.call_args.args
    assert (key, payload) == (f"lunaris/{R}/fault/battery/heating", b'{"heat_w":40.0}')
    assert rt2.zenoh_session.put.call_args.kwargs["attachment"] == b"actor=instructor"
    with pytest.raises(BadInput, match="nothing to cancel"):
        _put(again, "faults/armed/battery/heating", None)


@pytest.mark.parametrize(("epoch", "session", "cause", "why"), [
    (2, "s1", "reset", "the twin was reset"),
    (2, "s1", "restore:before-storm", "the twin was restored to snapshot 'before-storm'"),
    (2, "s2", "reset", "its session ended (session s2 began)"),
])
def test_a_reset_a_restore_or_a_new_session_cancels_them_with_the_reason(
        tmp_path, epoch: int, session: str, cause: str, why: str) -> None:
    arms, rt = _service(tmp_path)
    _tick(arms, rt, 10.0)
    _put(arms, "faults/armed/umbilical/disconnect", {"in_s": 30})
    _tick(arms, rt, 0.0, epoch=epoch, session=session, cause=cause)
    cancelled = rt.events[-1]
    assert cancelled["kind"] == "fault_cancelled" and cancelled["params"]["reason"] == why
    assert (cancelled["actor"], cancelled["session"]) == ("twin", "s1")  # journalled in its own
    _tick(arms, rt, 40.0, epoch=epoch, session=session)
    assert rt.zenoh_session.put.call_count == 0 and arms.rovers[R].book.listed() == []


def test_a_damaged_file_of_armed_faults_is_said_and_set_aside(tmp_path) -> None:
    (tmp_path / "faults-armed.json").write_text('{"mapp-1": [{"key": 3}]}')
    arms, rt = _service(tmp_path)
    arms.load()
    assert [e["kind"] for e in rt.events] == ["state_damaged"]
    assert "armed faults of mapp-1 damaged" in rt.events[0]["message"]
    assert not (tmp_path / "faults-armed.json").exists() and len(arms.rovers[R].book) == 0


def test_a_null_or_missing_warning_is_the_default_10_s() -> None:
    for body in ({"value": 40, "in_s": 30}, {"value": 40, "in_s": 30, "warn_s": None}):
        book = ArmedBook()
        book.arm(_armed(body))
        assert book.tick(119.9, _no_telemetry) == []
        assert [w for w, _ in book.tick(120.0, _no_telemetry)] == ["warn"]
