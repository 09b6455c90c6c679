"""Clock service: publishes ``lunaris/<rover>/clock`` ticks; ``clock/control`` pauses and scales.

Its time never goes back within an epoch. It is saved after every tick (a restarted clock
goes on from its last tick); a saved state that is missing or damaged is not a reason to
start again at 0 in the same epoch: the clock takes the latest time it can find, its own
saved time (``clock-time.json``) or the time the other services report with their faults
in effect (``faults/active/<service>``, which carries the epoch). A clock whose state is
damaged and that finds no time at all (every other service down too) holds its ticks, and
keeps asking, for up to ``HOLD_FOR_S``: the services that come back tell it where the twin
was; none in that time, it starts at 0 and says so.

It begins the epochs of the session: ``control/reset`` at once, ``control/restore/<name>``
once every service has checked its part of the snapshot (``snapshots/<service>?check=``):
all parts intact, the restore goes ahead; any part damaged or missing, it is refused with
the reason and nothing changes. The clock answers a restore (a ``session`` event, or a
``rejected`` one).

It begins the trainee sessions (SPEC §12c): ``control/session`` ``{"trainee",
"from_snapshot"?}`` ends the running session and begins a new one with a new epoch, a reset
(or the snapshot's restore, checked part by part as any restore: all or nothing), and every
tick from there carries the new session's id (:func:`services.clock.model.session_id`). The
session that ends is closed by a ``session`` event of its own (key ``sessions``, ``params``:
``session``, ``trainee``, ``end_t_s``); the clock answers the write with the ``session`` event
that opens the new one (``params``: ``session``, ``trainee``, ``from_snapshot``,
``started_wall``, ``start_t_s``; nothing of the previous session), or refuses it in words (a
bad name, an unknown or damaged snapshot: the running session goes on). A twin that never got a
``control/session`` is in a first session all the same (trainee ``""``), begun (and said in
such an event) when its clock first starts. The session is kept with the clock's state; a
clock whose state is lost learns it back with the time, from the services
(``faults/active/<service>`` carries it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Annotated, Any, NamedTuple

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.messages import (
    TRAINEE_MAX,
    ActiveFaults,
    BadInput,
    Clock,
    ClockControl,
    SessionStart,
    decode,
    decode_input,
)
from common.runtime import Runtime, Sample
from common.session import NO_PART, RESTORE, parse_control
from services.clock.model import ClockModel, Tick

__all__ = ["serve"]

CHECK_TIMEOUT_S = 2.0  # how long a restore waits for the services' checks of their parts
ASK_S = 0.5  # how often a clock that lost its time and found none asks the twin again
HOLD_FOR_S = 10.0  # ... holding its ticks meanwhile, for at most this long
ASK_FOR_S = 60.0  # ... and asking for this long (a later time found: it goes on from there)
DURABLE_EVERY_S = 1.0  # saved at every tick, flushed to the disk (fsync) this often


class SavedClock(msgspec.Struct):
    """What the clock saves: checked, types and ranges, when it is read back."""

    t_s: Annotated[float, msgspec.Meta(ge=0)]
    seq: Annotated[int, msgspec.Meta(ge=0)]
    epoch: Annotated[int, msgspec.Meta(ge=0)]
    time_scale: Annotated[float, msgspec.Meta(gt=0)] = 1.0
    paused: bool = False
    cause: str = ""
    session: Annotated[str, msgspec.Meta(max_length=32)] = ""
    session_epoch: Annotated[int, msgspec.Meta(ge=-1)] = -1
    trainee: Annotated[str, msgspec.Meta(max_length=TRAINEE_MAX)] = ""
    session_wall: Annotated[float, msgspec.Meta(ge=0)] = 0.0


def check_state(rover: str, state: dict[str, Any]) -> None:
    msgspec.convert(state, SavedClock)


class Found(NamedTuple):
    """Where the twin was, as a clock that lost its time finds it: (epoch, t_s), the session
    then ("" when the source did not say) and who said."""

    at: tuple[int, float]
    session: str
    source: str


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    rt.makes_time()
    clocks = {r.id: ClockModel(r.tick_hz) for r in rovers}
    asking: dict[str, float] = {}  # rover -> until when the clock asks the twin for its time
    holding: dict[str, float] = {}  # rover -> until when its ticks wait for a time found

    def publish(rover: str, tick: Tick) -> None:
        rt.t_s[rover], rt.epoch[rover] = tick.t_s, tick.epoch
        rt.publish(keys.clock(rover), Clock(**tick._asdict()))

    flushed = 0.0  # monotonic time of the last save flushed to the disk

    def save() -> None:
        """Every tick: whole after a kill; flushed once a second (a power cut loses at most
        that), as an fsync per tick (2 files, 0.7 ms each here) would cost a slow disk more
        than a tick."""
        nonlocal flushed
        now = time.monotonic()
        durable = now - flushed >= DURABLE_EVERY_S
        if durable:
            flushed = now
        rt.keeper.persist(durable)
        rt.save_time(durable)  # a second copy of the time, should the state be damaged

    def ticker(group: list[str]) -> Callable[[], None]:
        """Tick every rover of a tick rate: saved before it is published, so that a restart
        never goes on from a time older than one already sent."""
        def tick() -> None:
            ticks = [(rover, clocks[rover].tick()) for rover in group if rover not in holding]
            for rover, t in ticks:
                rt.t_s[rover], rt.epoch[rover] = t.t_s, t.epoch
            save()
            for rover, t in ticks:
                publish(rover, t)
        return tick

    def on_control(s: Sample) -> None:
        ctl = decode_input(s.payload, ClockControl)
        if ctl.time_scale is None and ctl.paused is None:
            raise BadInput("give time_scale (> 0) or paused (true or false)")
        clock = clocks[s.rover]
        if ctl.time_scale is not None:
            clock.set_scale(ctl.time_scale)
        if ctl.paused is not None:
            clock.paused = ctl.paused
        rt.event(s.rover, "info", "clock", s.key,
                 f"clock {'paused' if clock.paused else 'running'} at x{clock.time_scale:g}")

    # -- time that never goes back -------------------------------------------------------------

    def reached(rover: str) -> Found | None:
        """The latest (epoch, t_s) of ``rover`` this clock can find, its session, and where
        it found them."""
        found: list[Found] = []
        saved = rt.saved_time(rover)
        if saved is not None:
            found.append(Found(saved, rt.saved_session(rover), "its saved time"))
        try:
            replies = rt.zenoh_session.get(keys.faults_active(rover, "*"), timeout=0.5)
            for reply in replies:
                if reply.ok is not None:
                    answer = decode(reply.ok.payload.to_bytes(), ActiveFaults)
                    found.append(Found((answer.epoch, answer.t_s), answer.session,
                                       f"the {answer.service} service"))
        except (zenoh.ZError, msgspec.DecodeError, msgspec.ValidationError):
            pass
        if not found:
            return None
        found.sort(key=lambda f: f.at)
        best = found[-1]
        session = best.session or next((f.session for f in reversed(found) if f.session), "")
        return best._replace(session=session)

    def resume(rover: str, found: Found) -> None:
        clock = clocks[rover]
        clock.epoch, clock.t_s = found.at
        rt.epoch[rover], rt.t_s[rover] = found.at
        if found.session:
            clock.resume_session(found.session, found.at[0])
            rt.session_id[rover] = found.session

    def recover(rover: str) -> str:
        """A damaged state: the time is the latest this clock can find, never 0 again."""
        clocks[rover] = ClockModel(clocks[rover].tick_hz)
        found = reached(rover)
        if found is None:
            now = time.monotonic()
            holding[rover], asking[rover] = now + HOLD_FOR_S, now + ASK_FOR_S
            return (f"no time found (no other service is up): its ticks wait up to "
                    f"{HOLD_FOR_S:g} s for one to say where the twin was, then start at 0")
        resume(rover, found)
        (epoch, t_s), source = found.at, found.source
        return (f"time resumed at t={t_s:.1f} s in epoch {epoch}{_in(found.session)}, from "
                f"{source}, running at x1 (its speed was lost with its state)")

    def ask_again() -> None:
        """A clock that lost its time and found none: a service that came back knows it."""
        now = time.monotonic()
        for rover, until in list(asking.items()):
            found = reached(rover)
            clock = clocks[rover]
            if found is not None and (rover in holding or found.at > (clock.epoch, clock.t_s)):
                del asking[rover]
                holding.pop(rover, None)
                if found.at < (clock.epoch, clock.t_s):
                    found = Found((clock.epoch, clock.t_s), found.session, "its own")
                resume(rover, found)
                (epoch, t_s) = found.at
                rt.event(rover, "warning", "clock", keys.clock(rover),
                         f"clock of {rover}: time resumed at t={t_s:.1f} s in epoch {epoch}"
                         f"{_in(found.session)}, from {found.source}, running at x1 (its own "
                         "state was lost)")
                first_session(rover)
            elif now >= until:
                del asking[rover]
        for rover, until in list(holding.items()):
            if now >= until:
                del holding[rover]
                rt.event(rover, "critical", "clock", keys.clock(rover),
                         f"clock of {rover}: its state was lost and no service said where the "
                         f"twin was within {HOLD_FOR_S:g} s: time starts at 0")
                first_session(rover)

    # -- epochs: reset, and restores checked part by part ------------------------------------

    checking: dict[str, str] = {}  # rover -> the snapshot whose parts are being checked

    def on_session(s: Sample) -> None:
        """The clock begins the new epoch of a reset, a restore or a trainee's session; the
        others follow it."""
        control = parse_control(s.parts)
        if control is None or s.deleted or control[0] in ("snapshot", "mark"):
            return  # a snapshot is saved by every service itself; bad keys: the faults service
        action, name = control
        actor = rt.actor(s)
        if action == "reset":
            rt.keeper.reset(s.rover)  # the clock's reset begins the new epoch
            begin(s.rover)
            return
        trainee: str | None = None
        if action == "session":
            start = decode_input(s.payload, SessionStart)  # a bad name: refused in its words
            trainee, name = start.trainee, start.from_snapshot or ""
        if s.rover in checking:  # a restore or a session waits for it: one at a time
            raise BadInput(f"snapshot {checking[s.rover]!r} is being checked for a restore: "
                           "send it again in a moment")
        if trainee is not None and not name:
            new_session(s.rover, s.key, trainee, None, [], actor)
            return
        checking[s.rover] = name
        answers: list[tuple[str, str | None]] = []  # (service, None: intact | NO_PART | damage)

        def on_reply(reply: zenoh.Reply) -> None:
            answers.append(_answer(reply))

        def on_done() -> None:
            rt.call_soon(decide, s.rover, s.key, name, answers, trainee, actor)

        rt.zenoh_session.get(f"{keys.snapshots_of(s.rover, '*')}?check={name}",
                             zenoh.handlers.Callback(on_reply, on_done),
                             consolidation=zenoh.ConsolidationMode.NONE, timeout=CHECK_TIMEOUT_S)

    def decide(rover: str, key: str, name: str, answers: list[tuple[str, str | None]],
               trainee: str | None = None, actor: str | None = None) -> None:
        """Every service has checked its part (or not answered in time): all or nothing.
        ``trainee``: the restore begins that trainee's session (else it is a restore within
        the running one)."""
        del checking[rover]
        keeper = rt.keeper
        held = sorted(svc for svc, problem in answers if problem is None)
        damaged = sorted((svc, p) for svc, p in answers if p not in (None, NO_PART) and svc != "?")
        missing = sorted(svc for svc, p in answers if p == NO_PART)
        silent = [p or "" for svc, p in answers if svc == "?"]  # a timeout: who is not known
        # a trainee's session that cannot begin: said as such, and the running one goes on
        head = "" if trainee is None else f"the session of {trainee!r} not begun: "
        tail = "" if trainee is None else f"; {going_on(rover)}"
        if not held and not damaged and not silent:
            known = keeper.names(rover)
            rt.event(rover, "warning", "rejected", key,
                     f"rejected: {head}no snapshot {name!r} of {rover} (snapshots: "
                     f"{', '.join(known) or 'none'}){tail}", actor=actor)
            return
        if damaged or missing or silent:
            why = [f"the {svc} part is damaged ({problem})" for svc, problem in damaged]
            why += [f"the {svc} service holds no part of it" for svc in missing]
            why += [f"a service did not check its part within {CHECK_TIMEOUT_S:g} s ({problem})"
                    for problem in silent]
            rt.event(rover, "critical", "rejected", key,
                     f"rejected: {head}snapshot {name!r} not restored: {'; '.join(why)}. Nothing "
                     f"changed (restored only when every part is intact){tail}",
                     {"damaged": [svc for svc, _ in damaged], "missing": missing,
                      "intact": held}, actor=actor)
            return
        if trainee is not None:
            new_session(rover, key, trainee, name, held, actor)
            return
        if not keeper.restore(rover, name):  # checked a moment ago: changed since
            rt.event(rover, "critical", "rejected", key,
                     f"rejected: snapshot {name!r} not restored: the clock's part changed as it "
                     "was read; nothing changed", actor=actor)
            return
        clocks[rover].new_epoch(RESTORE + name)
        begin(rover)
        rt.event(rover, "info", "session", key, f"snapshot {name!r} restored (every part "
                 f"checked: {', '.join(held)})", {"services": held}, actor=actor)

    # -- trainee sessions ----------------------------------------------------------------------

    def going_on(rover: str) -> str:
        clock = clocks[rover]
        return (f"the session {clock.session} {_who(clock.trainee)} goes on" if clock.session
                else "the running session goes on")

    def new_session(rover: str, key: str, trainee: str, snapshot: str | None, held: list[str],
                    actor: str | None) -> None:
        """End the running session and begin ``trainee``'s: a reset, or the restore of
        ``snapshot`` (every part checked already), in a new epoch whose ticks carry the new
        session's id; answered with the ``session`` event that opens it in the journal."""
        clock = clocks[rover]
        if clock.session:  # closed in its own words, in its own segment of the journal
            rt.event(rover, "info", "session", keys.sessions(rover),
                     f"session {clock.session} {_who(clock.trainee)} ends at t={clock.t_s:.1f} s: "
                     "the next trainee's session begins",
                     {"session": clock.session, "trainee": clock.trainee, "end_t_s": clock.t_s},
                     actor=actor)
        if snapshot is None:
            rt.keeper.reset(rover)  # a new epoch, t = 0
            how = "the twin back to its rover file"
        else:
            if not rt.keeper.restore(rover, snapshot):  # checked a moment ago: changed since
                rt.event(rover, "critical", "rejected", key,
                         f"rejected: the session of {trainee!r} not begun: snapshot {snapshot!r} "
                         f"not restored: the clock's part changed as it was read; nothing "
                         f"changed; {going_on(rover)}", actor=actor)
                return
            clock.new_epoch(RESTORE + snapshot)
            how = f"snapshot {snapshot!r} restored (every part checked: {', '.join(held)})"
        announce(rover, key, trainee, snapshot, how, actor, tick=True)

    def announce(rover: str, key: str, trainee: str, snapshot: str | None, how: str,
                 actor: str | None, tick: bool = False) -> None:
        """Begin the clock's record of a new session and say it; ``tick``: its first tick
        goes out first (the writer told of the new session writes again in it: the services
        have its tick before they have that write)."""
        clock = clocks[rover]
        wall = time.time()
        sid = clock.begin_session(trainee, wall)
        rt.enter_session(rover, sid)
        rt.t_s[rover] = clock.t_s
        if tick:
            begin(rover)
        params: dict[str, Any] = {"session": sid, "trainee": trainee, "from_snapshot": snapshot,
                                  "started_wall": wall, "start_t_s": clock.t_s}
        rt.event(rover, "info", "session", key, f"session {sid} {_who(trainee)} begins: {how}",
                 params, actor=actor)

    def first_session(rover: str) -> None:
        """A twin that never got a control/session is in a session all the same."""
        if clocks[rover].session or rover in holding:
            return
        announce(rover, keys.control_session(rover), "", None,
                 "the twin's first session (lunaris session start names a trainee)", "twin")
        save()

    def begin(rover: str) -> None:
        clock = clocks[rover]
        rt.keeper.epoch[rover] = clock.epoch
        mark = clock.mark()
        rt.t_s[rover], rt.epoch[rover] = mark.t_s, mark.epoch
        save()
        publish(rover, mark)

    def set_state(rover: str, state: dict[str, Any]) -> None:
        clocks[rover].set_state(state)
        rt.t_s[rover], rt.epoch[rover] = clocks[rover].t_s, clocks[rover].epoch

    rt.subscribe(keys.clock_control("*"), on_control)
    rt.subscribe(keys.control_reset("*"), on_session)
    rt.subscribe(keys.control_restore("*", "*"), on_session)
    rt.subscribe(keys.control_session("*"), on_session)
    rt.own_state(lambda rover: clocks[rover].state(), set_state,
                 lambda rover: clocks[rover].reset(), persist_every_s=None, check=check_state,
                 damaged=recover)
    for rover in clocks:
        if rover not in rt.keeper.resumed and rover not in rt.keeper.damaged:
            found = reached(rover)  # no state of its own (a new state folder): the twin's
            if found is not None and (found.at > (0, 0.0) or found.session):
                resume(rover, found)
        rt.session_id[rover] = clocks[rover].session
        first_session(rover)
    groups: dict[float, list[str]] = {}  # the rovers of each tick period
    for rover_id, clock in clocks.items():
        groups.setdefault(clock.period_s, []).append(rover_id)
    for period_s, group in groups.items():
        # A clock that falls behind skips ahead rather than bursting (see Runtime.every).
        rt.every(period_s, ticker(group))
    rt.every(ASK_S, lambda: ask_again() if asking or holding else None)


def _who(trainee: str) -> str:
    """``of 'Ana'``, or ``with no trainee named`` (the twin's first session)."""
    return f"of {trainee!r}" if trainee else "with no trainee named"


def _in(session: str) -> str:
    return f" of session {session}" if session else ""


def _answer(reply: zenoh.Reply) -> tuple[str, str | None]:
    """(service, None | NO_PART | the damage) from a service's check of its part."""
    if reply.ok is not None:
        service = str(reply.ok.key_expr).rsplit("/", 1)[-1]
        try:
            infos = msgspec.json.decode(reply.ok.payload.to_bytes())
        except msgspec.DecodeError:
            return service, "its answer is not JSON"
        return service, None if infos else NO_PART
    raw = reply.err.payload.to_bytes() if reply.err is not None else b""
    try:
        err = msgspec.json.decode(raw)
        return str(err["service"]), str(err["problem"])
    except (msgspec.DecodeError, KeyError, TypeError):
        return "?", raw.decode("utf-8", "replace") or "no answer"
