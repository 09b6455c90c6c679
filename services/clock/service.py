"""Clock service: publishes ``lunaris/<rover>/clock`` ticks; ``clock/control`` pauses and scales.

Longer than 450 lines: the time that never goes back, the epochs and the trainee sessions
are one clock's.

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

A node (:class:`ClockNode`): ``clock/control`` read, the session controls heard (no key
family: read as they come), ``clock`` published; the state of each rover (:class:`Ticking`)
its clock model and what the service remembers of a lost time and of a restore being checked.
Its timers are one per tick rate of the rovers served, made at start.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
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
from common.node import Hears, Node, PerRover, Publishes, Reads
from common.runtime import Sample
from common.session import NO_PART, RESTORE, parse_control
from services.clock.model import ClockModel, Tick

__all__ = ["NODE", "ClockNode", "SavedClock", "Ticking"]

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


class Found(NamedTuple):
    """Where the twin was, as a clock that lost its time finds it: (epoch, t_s), the session
    then ("" when the source did not say) and who said."""

    at: tuple[int, float]
    session: str
    source: str


@dataclass
class Ticking(PerRover):
    """One rover's clock and what the service remembers of it."""

    model: ClockModel
    asking_until: float | None = None  # until when a clock that lost its time asks the twin
    holding_until: float | None = None  # ... and until when its ticks wait for a time found
    checking: str | None = None  # the snapshot whose parts are being checked for a restore
    epoch_out: int | None = None  # the epoch of the last tick published


class ClockNode(Node[Ticking]):
    """The clock of every rover served: its ticks, its time that never goes back, the epochs
    and trainee sessions it begins."""

    name = "clock"
    makes_time = True
    reads = (Reads("clock/control", ClockControl, "on_control", kind="command", deletes="reject"),)
    # The session controls are no key family (a control carries no data of the twin's):
    # read as they come, the payload (a session's trainee) by the callback.
    hears = (Hears("control/reset", "on_session"), Hears("control/restore/*", "on_session"),
             Hears("control/session", "on_session"))
    publishes = (Publishes("clock", Clock),)
    persist_every_s = None  # saved at every tick (see save)

    def __init__(self, rovers: list[Rover], seed: int | None = None):
        self.flushed = 0.0  # monotonic time of the last save flushed to the disk
        super().__init__(rovers, seed)

    def rover_state(self, rover: Rover) -> Ticking:
        return Ticking(rover.id, ClockModel(rover.tick_hz))

    def publish_tick(self, st: Ticking, tick: Tick) -> None:
        """A tick; the first of an epoch (a reset, a restore, a trainee's session) goes at the
        writes' priority: a write sent by whoever has seen it cannot overtake it on the way
        to a service (telemetry goes behind the writes), and be applied in the epoch that
        ended and undone by its reset (a fault of Ben's session, sent once it had begun,
        injected in Ana's and cleared with her session)."""
        self.rt.t_s[st.id], self.rt.epoch[st.id] = tick.t_s, tick.epoch
        msg = Clock(**tick._asdict())
        if tick.epoch != st.epoch_out:
            st.epoch_out = tick.epoch
            self.rt.publish_ahead(keys.clock(st.id), msg)
        self.publish(keys.clock(st.id), msg)

    def save(self) -> None:
        """Every tick: whole after a kill; flushed once a second (a power cut loses at most
        that), as an fsync per tick (2 files, 0.7 ms each here) would cost a slow disk more
        than a tick."""
        now = time.monotonic()
        durable = now - self.flushed >= DURABLE_EVERY_S
        if durable:
            self.flushed = now
        self.rt.keeper.persist(durable)
        self.rt.save_time(durable)  # a second copy of the time, should the state be damaged

    def tick(self, group: tuple[str, ...]) -> None:
        """Tick every rover of a tick rate: saved before it is published, so that a restart
        never goes on from a time older than one already sent."""
        rt = self.rt
        ticks = [(st, st.model.tick()) for st in map(self.rovers.__getitem__, group)
                 if st.holding_until is None]
        for st, t in ticks:
            rt.t_s[st.id], rt.epoch[st.id] = t.t_s, t.epoch
        self.save()
        for st, t in ticks:
            self.publish_tick(st, t)

    def on_control(self, st: Ticking, ctl: ClockControl, s: Sample) -> None:
        if ctl.time_scale is None and ctl.paused is None:
            raise BadInput("give time_scale (> 0) or paused (true or false)")
        clock = st.model
        if ctl.time_scale is not None:
            clock.set_scale(ctl.time_scale)
        if ctl.paused is not None:
            clock.paused = ctl.paused
        self.rt.event(st.id, "info", "clock", s.key,
                      f"clock {'paused' if clock.paused else 'running'} at x{clock.time_scale:g}")

    # -- time that never goes back -------------------------------------------------------------

    def reached(self, st: Ticking) -> Found | None:
        """The latest (epoch, t_s) of a rover this clock can find, its session, and where it
        found them."""
        rt, rover = self.rt, st.id
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

    def resume(self, st: Ticking, found: Found) -> None:
        clock, rt = st.model, self.rt
        clock.epoch, clock.t_s = found.at
        rt.epoch[st.id], rt.t_s[st.id] = found.at
        if found.session:
            clock.resume_session(found.session, found.at[0])
            rt.session_id[st.id] = found.session

    def recover(self, st: Ticking) -> str:
        """A damaged state: the time is the latest this clock can find, never 0 again."""
        st.model = ClockModel(st.model.tick_hz)
        found = self.reached(st)
        if found is None:
            now = time.monotonic()
            st.holding_until, st.asking_until = now + HOLD_FOR_S, now + ASK_FOR_S
            return (f"no time found (no other service is up): its ticks wait up to "
                    f"{HOLD_FOR_S:g} s for one to say where the twin was, then start at 0")
        self.resume(st, found)
        (epoch, t_s), source = found.at, found.source
        return (f"time resumed at t={t_s:.1f} s in epoch {epoch}{_in(found.session)}, from "
                f"{source}, running at x1 (its speed was lost with its state)")

    def ask_again(self) -> None:
        """A clock that lost its time and found none: a service that came back knows it."""
        now = time.monotonic()
        for st in self.rovers.values():
            if st.asking_until is None:
                continue
            rover, clock = st.id, st.model
            found = self.reached(st)
            if found is not None and (st.holding_until is not None
                                      or found.at > (clock.epoch, clock.t_s)):
                st.asking_until = st.holding_until = None
                if found.at < (clock.epoch, clock.t_s):
                    found = Found((clock.epoch, clock.t_s), found.session, "its own")
                self.resume(st, found)
                (epoch, t_s) = found.at
                self.rt.event(rover, "warning", "clock", keys.clock(rover),
                              f"clock of {rover}: time resumed at t={t_s:.1f} s in epoch {epoch}"
                              f"{_in(found.session)}, from {found.source}, running at x1 (its "
                              "own state was lost)")
                self.first_session(st)
            elif now >= st.asking_until:
                st.asking_until = None
        for st in self.rovers.values():
            if st.holding_until is not None and now >= st.holding_until:
                st.holding_until = None
                self.rt.event(st.id, "critical", "clock", keys.clock(st.id),
                              f"clock of {st.id}: its state was lost and no service said where "
                              f"the twin was within {HOLD_FOR_S:g} s: time starts at 0")
                self.first_session(st)

    # -- epochs: reset, and restores checked part by part ------------------------------------

    def on_session(self, s: Sample) -> None:
        """The clock begins the new epoch of a reset, a restore or a trainee's session; the
        others follow it."""
        control = parse_control(s.parts)
        if control is None or s.deleted or control[0] in ("snapshot", "mark"):
            return  # a snapshot is saved by every service itself; bad keys: the faults service
        st, rt = self.rovers[s.rover], self.rt
        action, name = control
        actor = rt.actor(s)
        if action == "reset":
            rt.keeper.reset(st.id)  # the clock's reset begins the new epoch
            self.begin(st)
            return
        trainee: str | None = None
        if action == "session":
            start = decode_input(s.payload, SessionStart)  # a bad name: refused in its words
            trainee, name = start.trainee, start.from_snapshot or ""
        if st.checking is not None:  # a restore or a session waits for it: one at a time
            raise BadInput(f"snapshot {st.checking!r} is being checked for a restore: "
                           "send it again in a moment")
        if trainee is not None and not name:
            self.new_session(st, s.key, trainee, None, [], actor)
            return
        st.checking = name
        check = PartsCheck(self, st, s.key, name, trainee, actor)
        rt.zenoh_session.get(f"{keys.snapshots_of(st.id, '*')}?check={name}",
                             zenoh.handlers.Callback(check.on_reply, check.on_done),
                             consolidation=zenoh.ConsolidationMode.NONE, timeout=CHECK_TIMEOUT_S)

    def decide(self, st: Ticking, key: str, name: str, answers: list[tuple[str, str | None]],
               trainee: str | None = None, actor: str | None = None) -> None:
        """Every service has checked its part (or not answered in time): all or nothing.
        ``trainee``: the restore begins that trainee's session (else it is a restore within
        the running one)."""
        st.checking = None
        rt, rover = self.rt, st.id
        keeper = rt.keeper
        held = sorted(svc for svc, problem in answers if problem is None)
        damaged = sorted((svc, p) for svc, p in answers if p not in (None, NO_PART) and svc != "?")
        missing = sorted(svc for svc, p in answers if p == NO_PART)
        silent = [p or "" for svc, p in answers if svc == "?"]  # a timeout: who is not known
        # a trainee's session that cannot begin: said as such, and the running one goes on
        head = "" if trainee is None else f"the session of {trainee!r} not begun: "
        tail = "" if trainee is None else f"; {_going_on(st.model)}"
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
            self.new_session(st, key, trainee, name, held, actor)
            return
        if not keeper.restore(rover, name):  # checked a moment ago: changed since
            rt.event(rover, "critical", "rejected", key,
                     f"rejected: snapshot {name!r} not restored: the clock's part changed as it "
                     "was read; nothing changed", actor=actor)
            return
        st.model.new_epoch(RESTORE + name)
        self.begin(st)
        rt.event(rover, "info", "session", key, f"snapshot {name!r} restored (every part "
                 f"checked: {', '.join(held)})", {"services": held}, actor=actor)

    # -- trainee sessions ----------------------------------------------------------------------

    def new_session(self, st: Ticking, key: str, trainee: str, snapshot: str | None,
                    held: list[str], actor: str | None) -> None:
        """End the running session and begin ``trainee``'s: a reset, or the restore of
        ``snapshot`` (every part checked already), in a new epoch whose ticks carry the new
        session's id; answered with the ``session`` event that opens it in the journal."""
        clock, rt, rover = st.model, self.rt, st.id
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
                         f"changed; {_going_on(clock)}", actor=actor)
                return
            clock.new_epoch(RESTORE + snapshot)
            how = f"snapshot {snapshot!r} restored (every part checked: {', '.join(held)})"
        self.announce(st, key, trainee, snapshot, how, actor, tick=True)

    def announce(self, st: Ticking, key: str, trainee: str, snapshot: str | None, how: str,
                 actor: str | None, tick: bool = False) -> None:
        """Begin the clock's record of a new session and say it; ``tick``: its first tick
        goes out first (the writer told of the new session writes again in it: the services
        have its tick before they have that write)."""
        clock, rt = st.model, self.rt
        wall = time.time()
        sid = clock.begin_session(trainee, wall)
        rt.enter_session(st.id, sid)
        rt.t_s[st.id] = clock.t_s
        if tick:
            self.begin(st)
        params: dict[str, Any] = {"session": sid, "trainee": trainee, "from_snapshot": snapshot,
                                  "started_wall": wall, "start_t_s": clock.t_s}
        rt.event(st.id, "info", "session", key, f"session {sid} {_who(trainee)} begins: {how}",
                 params, actor=actor)

    def first_session(self, st: Ticking) -> None:
        """A twin that never got a control/session is in a session all the same."""
        if st.model.session or st.holding_until is not None:
            return
        self.announce(st, keys.control_session(st.id), "", None,
                      "the twin's first session (lunaris session start names a trainee)", "twin")
        self.save()

    def begin(self, st: Ticking) -> None:
        clock, rt = st.model, self.rt
        rt.keeper.epoch[st.id] = clock.epoch
        mark = clock.mark()
        rt.t_s[st.id], rt.epoch[st.id] = mark.t_s, mark.epoch
        self.save()
        self.publish_tick(st, mark)

    # -- state ---------------------------------------------------------------------------------

    def get_state(self, st: Ticking) -> dict[str, Any]:
        return st.model.state()

    def set_state(self, st: Ticking, state: dict[str, Any]) -> None:
        st.model.set_state(state)
        self.rt.t_s[st.id], self.rt.epoch[st.id] = st.model.t_s, st.model.epoch

    def reset(self, st: Ticking) -> None:
        st.model.reset()

    def check_state(self, st: Ticking, state: dict[str, Any]) -> None:
        msgspec.convert(state, SavedClock)

    def start(self) -> None:
        rt = self.rt
        for st in self.rovers.values():
            if st.id not in rt.keeper.resumed and st.id not in rt.keeper.damaged:
                found = self.reached(st)  # no state of its own (a new state folder): the twin's
                if found is not None and (found.at > (0, 0.0) or found.session):
                    self.resume(st, found)
            rt.session_id[st.id] = st.model.session
            self.first_session(st)
        # Timers made here, not in a table: one per tick rate of the rovers served, then the
        # asking of a clock that lost its time (after the ticks: both due, a tick goes first).
        groups: dict[float, list[str]] = {}
        for st in self.rovers.values():
            groups.setdefault(st.model.period_s, []).append(st.id)
        for period_s, group in groups.items():
            # A clock that falls behind skips ahead rather than bursting (see Runtime.every).
            rt.every(period_s, partial(self.tick, tuple(group)))
        rt.every(ASK_S, self.ask_again)


class PartsCheck:
    """A restore's check of the snapshot's parts: the services' answers gathered on Zenoh's
    thread, handed to :meth:`ClockNode.decide` on the worker once the get is over."""

    def __init__(self, node: ClockNode, st: Ticking, key: str, name: str, trainee: str | None,
                 actor: str):
        self.node, self.st, self.key, self.name = node, st, key, name
        self.trainee, self.actor = trainee, actor
        self.answers: list[tuple[str, str | None]] = []  # (service, None: intact | NO_PART | damage)

    def on_reply(self, reply: zenoh.Reply) -> None:
        self.answers.append(_answer(reply))

    def on_done(self) -> None:
        self.node.rt.call_soon(self.node.decide, self.st, self.key, self.name, self.answers,
                               self.trainee, self.actor)


NODE = ClockNode


def _going_on(clock: ClockModel) -> str:
    return (f"the session {clock.session} {_who(clock.trainee)} goes on" if clock.session
            else "the running session goes on")


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
