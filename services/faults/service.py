"""Faults service: the session's journal, ``get lunaris/<rover>/faults``, and the gatekeeper.

Longer than 450 lines: one service's journal, queries, gatekeeper and session controls; its
armed faults are :mod:`services.faults.arming`'s.

- **The journal**: every event of the rover, kept on disk for the whole training day (a flood
  of rejections is summarised, and the summary says so), in one segment per trainee session
  (SPEC §12c: each event says its ``session``), answered to
  ``get lunaris/<rover>/faults/journal``: the running session's events, ``?session=<id>``
  another's (``?session=all``: every session's), ``?last=N`` the latest N of them (N a whole
  number up to ``LAST_MAX``: anything else refused in words).
  ``get lunaris/<rover>/sessions`` lists the sessions (``id, trainee, start_t_s, end_t_s,
  started_wall``, oldest first). Each service
  publishes its events on its own key, ``lunaris/<rover>/event/<service>`` (which the access
  control lets only that service write); an event whose ``source`` is not that service is
  refused and said in a ``critical`` event. Each event journalled goes out again, unchanged,
  on ``lunaris/<rover>/event``: the journal's stream (complete, authenticated, floods
  summarised), which this service's own events join the same way.
- **The faults in effect**: ``get lunaris/<rover>/faults`` is answered by asking each owning
  service for its own record (``lunaris/<rover>/faults/active/<service>``, see
  ``common.fault_book``) at the time of the query and merging the answers. An owner the rover
  file implies that does not answer (stopped, or behind a cut link) is named in an error
  reply beside the list, never left out silently (SPEC §12f). A fault whose
  effect is on the telemetry is therefore in the answer: its owner applied it, and recorded
  it, before publishing the effect. Nothing is kept here that could go stale.
- **The gatekeeper** for what no other service owns: an instructor key for a rover no
  service serves, a fault on an unknown component, an input or command the twin does not
  have (a traverse for a rover without a ``drive`` section), a write whose key holds a
  wildcard (``lunaris/**``: every service drops it, see ``Runtime.on_wildcard``). Each is
  rejected with an event, like every other bad input, once.
- **Session controls** (``control/reset``, ``control/snapshot/<name>``,
  ``control/restore/<name>``): every service acts on its own state (``common.session``);
  this one answers a reset or a snapshot with the one ``session`` event that marks it in the
  journal, refuses a malformed control, and answers ``get lunaris/<rover>/snapshots`` from
  what the services hold. A restore is the clock's to answer: it checks every part first
  (all or nothing, see ``common.session``).
  A scenario's progress (``control/scenario``) is journalled as ``scenario`` events.
  A trainee's session (``control/session``) is the clock's to answer, as a restore is.
- **Armed faults** (SPEC 13b): ``faults/armed/<component>/<kind>`` arms a fault for a time or
  a condition, ``get lunaris/<rover>/faults/armed`` lists them (:mod:`services.faults.arming`).
- **Marks**: ``control/mark`` ``{"text"}`` is answered with a ``mark`` event (by whoever wrote
  it: its ``actor``), an instructor's note on the timeline.
- **A full disk** (SPEC 13e) never stops the service: the journal holds its events in memory
  and writes them when space returns (:mod:`services.faults.journal`); the instructor is told
  at once, and again when it is written again, in ``disk_full`` events, and warned before,
  while the state folder has less than ``LOW_SPACE_BYTES`` free (:mod:`services.faults.disk`);
  a mark answered meanwhile says "not recorded: the disk is full".

A node (:class:`FaultsNode`) whose ports are heard, not read: every service's events and the
gatekeeper's keys are no key family (:class:`common.node.Hears`); it publishes the journal's
stream (``event``, the last ``EVENT_CACHE`` events cached). The journal of each rover is in
its :class:`Desk`; the queries (no key family either) are declared at start.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from functools import partial

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.faults import check_component
from common.messages import (
    SESSION_ID,
    ActiveFault,
    ActiveFaults,
    ArmFault,
    BadInput,
    Clock,
    Event,
    ScenarioMark,
    SnapshotInfo,
    TimelineMark,
    decode,
    decode_input,
)
from common.node import Every, Hears, Node, PerRover, Publishes, Reads
from common.reasons import shown
from common.runtime import EVENT_CACHE, Runtime, Sample
from common.session import parse_control
from common.writes import fault_owners
from services.faults.arming import Arms
from services.faults.disk import LowSpace, journal_said
from services.faults.journal import Journal

__all__ = ["NODE", "Desk", "FaultsNode"]

GATHER_TIMEOUT_S = 2.0  # how long a `get faults` waits for the owners' answers
LAST_MAX = 1_000_000  # ?last= of the journal query: at most this many events
# The heads of the keys that instructors, scenarios and dashboards write.
WRITABLE = ("fault/**", "input/**", "cmd/**", "clock/control/**", "control/**")
CONTROLS = ("control/session, control/mark, control/reset, control/snapshot/<name>, "
            "control/restore/<name>")
SESSION_MESSAGES = {
    "reset": "session reset: every service back to the rover file's initial conditions, "
             "injected faults cleared, the clock at 0",
    "snapshot": "snapshot {name!r} saved",
}


@dataclass
class Desk(PerRover):
    """What the faults service keeps of one rover: its journal and what its rover file says."""

    drives: bool  # it has a drive section (a traverse is an input it has)
    owners: set[str]  # the services that own the faults of its components
    # the journal in memory until attach opens the one in the state folder (the runtime's)
    journal: Journal = field(default_factory=Journal)
    unopened: bool = False  # a new journal: its first line waits for the session of a tick


class FaultsNode(Node[Desk]):
    """The journal, the faults in effect gathered, the gatekeeper and the session controls of
    every rover served."""

    name = "faults"
    keeps_state = False  # the journal is its own file (services.faults.journal)
    # Every service's events (event/<service>: no key family, the access control's), and the
    # gatekeeper's every write and one-chunk key, of any rover (a rover nobody serves included)
    hears = (
        Hears("event/*", "on_event", history=True),
        *(Hears(head, "on_instructor_key", any_rover=True, writes="gate") for head in WRITABLE),
        Hears("*", "on_one_chunk", any_rover=True, telemetry=True, writes="gate"),
    )
    reads = (Reads("faults/armed/**", ArmFault, "on_arm", kind="command"),)
    publishes = (Publishes("event", Event, reliable=True, cache=EVENT_CACHE),)
    timers = (Every(1.0, "end_floods"),)

    def __init__(self, rovers: list[Rover], seed: int | None = None):
        self.live_rovers: set[str] = set()  # rovers some service serves (their tokens)
        self.space: LowSpace | None = None  # the state folder's free space, watched
        super().__init__(rovers, seed)

    def rover_state(self, rover: Rover) -> Desk:
        return Desk(rover.id, rover.drive is not None, fault_owners(rover))

    def attach(self, rt: Runtime) -> None:
        # The journals are the state folder's, the runtime's; the services' liveliness tokens
        # are no port of the table (heard on Zenoh's thread, with the tokens up already).
        folder = rt.store.dir
        self.space = LowSpace(folder) if folder is not None else None
        for desk in self.rovers.values():
            desk.journal = Journal(folder / f"faults-journal-{desk.id}.jsonl" if folder else None,
                                   rover=desk.id)
        rt.keep(rt.zenoh_session.liveliness().declare_subscriber(
            keys.service("*", "*"), self.on_token, history=True))
        rt.record_own_events(self.journal_own)
        self.arms = Arms(rt, self.configs)
        super().attach(rt)

    def on_token(self, s: zenoh.Sample) -> None:
        rover, _ = keys.split(str(s.key_expr))
        if s.kind == zenoh.SampleKind.PUT:
            self.live_rovers.add(rover)

    # -- the journal -------------------------------------------------------------------------

    def on_event(self, s: Sample) -> None:
        """An event a service published on its own key: journalled and relayed on the rover's
        ``event`` key if its ``source`` is that service, refused (and said) if not."""
        rt = self.rt
        ev = decode(s.payload, Event)
        if len(s.parts) != 2 or ev.source != s.parts[1]:
            rt.event(s.rover, "critical", "rejected", s.key,
                     f"forged event refused: published on {s.key}, the key of the "
                     f"{s.parts[-1]} service, it claims to come from {shown(ev.source)} "
                     f"({ev.kind}: {shown(ev.message)}); not journalled")
            return
        was = self.rovers[s.rover].journal.disk_error
        self.relay(s.rover, self.rovers[s.rover].journal.record(ev, time.monotonic()))
        self.said_disk(s.rover, was)
        if ev.source == "clock" and ev.kind == "session" and ev.session > rt.session_id[s.rover] \
                and "started_wall" in (ev.params or {}):
            # the clock's word that a session begins: a write answered here after it is in
            # that session, whether its first tick has come or not (ids grow: a session's
            # event replayed from a cache never takes this service back)
            rt.enter_session(s.rover, ev.session)

    def journal_own(self, rover: str, ev: Event) -> Event:
        """This service's own event (a mark, a session control, a rejection), journalled and
        relayed before it is published on ``event/faults``: heard back, it is known already.
        What to publish: ``ev``, or, held while the disk is full, ``ev`` saying it is not
        recorded (an answer to a write: "not recorded: the disk is full ...")."""
        journal = self.rovers[rover].journal
        was = journal.disk_error
        written = journal.record(ev, time.monotonic())
        self.relay(rover, written)
        self.said_disk(rover, was)
        return next((w for w in written if w.source_id == ev.source_id and w.seq == ev.seq), ev)

    def relay(self, rover: str, written: list[Event]) -> None:
        """What the journal wrote, unchanged, on ``lunaris/<rover>/event``: the journal's
        stream (complete, authenticated, floods summarised)."""
        for ev in written:
            self.publish(keys.event(rover), ev)

    def said_disk(self, rover: str, was: str | None) -> None:
        """Tell the instructor, at once, that the journal's disk refuses it, and that it takes
        it again (:func:`services.faults.disk.journal_said`)."""
        said = journal_said(rover, self.rovers[rover].journal, was)
        if said is not None:
            self.rt.event(rover, said.severity, "disk_full", keys.faults_journal(rover),
                          said.message, said.params)

    def end_floods(self, force: bool = False) -> None:
        """What the disk refused written if it takes it now, summaries of the floods that have
        ended (all of them, ``force``), the events that never came back counted; the free
        space of the state folder looked at."""
        for rover, desk in self.rovers.items():
            was = desk.journal.disk_error
            self.relay(rover, desk.journal.tick(time.monotonic(), flood_over=force))
            self.said_disk(rover, was)
        said = self.space.look() if self.space is not None else None
        if said is not None:
            for rover in sorted(self.rovers):
                self.rt.event(rover, said.severity, "disk_full", keys.faults_journal(rover),
                              said.message, said.params)

    def on_tick(self, desk: Desk, tick: Clock) -> None:
        if desk.unopened:
            self.open_journal(desk)
        self.arms.on_tick(desk.id, tick)

    def on_arm(self, desk: Desk, msg: ArmFault | None, s: Sample) -> None:
        self.arms.on_arm(desk.id, msg, s)

    def open_journal(self, desk: Desk) -> None:
        """A new journal's first line, in the session the clock's ticks say (once one has come)."""
        if desk.unopened and self.rt.session_id.get(desk.id):
            desk.unopened = False
            self.rt.event(desk.id, "info", "session", keys.faults_journal(desk.id),
                          f"journal opened: the journal of {desk.id} begins in session "
                          f"{self.rt.session_id[desk.id]}")

    # -- the gatekeeper and the session controls ------------------------------------------------

    def on_instructor_key(self, s: Sample) -> None:
        rt = self.rt
        if s.rover not in rt.rovers and s.rover not in self.live_rovers:
            raise BadInput(f"unknown rover {s.rover!r}: no Lunaris service serves it")
        if s.rover not in rt.rovers:
            return  # another faults service journals that rover
        if s.parts[0] == "fault":
            check_component(s.parts[1:])  # the owner of a known component answers the rest
            return
        if s.parts[0] == "control":  # answered here alone (the others follow: common.session)
            refusal = rt.refusal(s)
            if refusal is not None:
                raise BadInput(refusal)
            self.on_control(s)
            return
        family = keys.family_of(s.parts)
        if family is None or family.direction != "in":
            writable = ", ".join(f.name for f in keys.families("in"))
            raise BadInput(f"no such input or command {'/'.join(s.parts)!r} (the twin reads: "
                           f"{writable}, fault/...)")
        if family.owner == "drive" and not self.rovers[s.rover].drives:
            raise BadInput(f"rover {s.rover} has no drive section in its rover file: it does not "
                           "drive, so it cannot follow a traverse")

    def on_one_chunk(self, s: Sample) -> None:
        if s.parts[0] in ("clock", "event") or any(h.startswith(s.parts[0] + "/") for h in WRITABLE):
            return  # telemetry (its writer is the router's to check), or answered above
        self.on_instructor_key(s)

    def on_wildcard(self, s: Sample) -> None:
        """A write on a key naming many (``lunaris/**``): no service took it; refused once, in
        words, for each rover served here that it reaches."""
        verb = "delete" if s.deleted else "put"
        expr = zenoh.KeyExpr(s.key)
        for rover in sorted(self.rt.rovers):
            if zenoh.KeyExpr(keys.under(rover)).intersects(expr):
                self.rt.reject(rover, s.key, f"a {verb} on {s.key} names many keys (it holds a "
                               "wildcard: *, ** or $*); a write names exactly one key. Nothing "
                               "changed")

    def on_control(self, s: Sample) -> None:
        rt = self.rt
        if s.parts == ["control", "scenario"]:  # a scenario's progress, for the journal
            if s.deleted:
                raise BadInput("a scenario mark is a put")
            mark = decode_input(s.payload, ScenarioMark)
            params = {"scenario": mark.scenario, "what": mark.what, "step": mark.step}
            if mark.expectation is not None:  # an expectation scored (SPEC 12d)
                params["expectation"] = msgspec.to_builtins(mark.expectation)
            rt.event(s.rover, "info", "scenario", s.key, f"scenario {mark.scenario!r}: {mark.message}",
                     params)
            return
        control = parse_control(s.parts)
        if control is None:
            raise BadInput(f"no such control {'/'.join(s.parts)!r} ({CONTROLS}; a name is "
                           "letters, digits, '_', '-' and '.', at most 64)")
        if s.deleted:
            raise BadInput(f"a {'mark' if control[0] == 'mark' else 'session control'} is a put, "
                           "not a delete")
        action, name = control
        if action in ("restore", "session"):
            return  # the clock checks every part, then begins it or refuses: it answers
        if action == "mark":
            note = decode_input(s.payload, TimelineMark)
            rt.event(s.rover, "info", "mark", s.key, f"mark: {note.text}", {"text": note.text})
            return
        rt.event(s.rover, "info", "session", s.key, SESSION_MESSAGES[action].format(name=name))

    # -- the queries -------------------------------------------------------------------------

    def gather_snapshots(self, rover: str) -> list[SnapshotInfo]:
        merged: dict[str, SnapshotInfo] = {}
        for reply in self.rt.zenoh_session.get(keys.snapshots_of(rover, "*"),
                                               timeout=GATHER_TIMEOUT_S,
                                               consolidation=zenoh.ConsolidationMode.NONE):
            if reply.ok is None:
                continue
            for info in msgspec.json.decode(reply.ok.payload.to_bytes(), type=list[SnapshotInfo]):
                known = merged.setdefault(info.name, SnapshotInfo(info.name, info.t_s,
                                                                  info.saved_at, []))
                known.services.extend(info.services)
        return [merged[n] for n in sorted(merged)]

    def on_snapshots_query(self, q: zenoh.Query) -> None:
        with q:
            for rover in sorted(self.rovers):
                key = keys.snapshots(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    q.reply(key, msgspec.json.encode(self.gather_snapshots(rover)),
                            encoding=zenoh.Encoding.APPLICATION_JSON)

    def running(self, desk: Desk) -> str:
        """The session running: as the ticks say, or the journal's latest."""
        return self.rt.session_id.get(desk.id) or desk.journal.sessions.running

    def on_journal_query(self, q: zenoh.Query) -> None:
        with q:
            last = q.parameters.get("last")
            if last is not None and not (last.isascii() and last.isdigit() and len(last) <= 7
                                         and int(last) <= LAST_MAX):
                q.reply_err(f"last={shown(last)}: give a whole number of events, 0 to {LAST_MAX:,}")
                return
            asked = q.parameters.get("session")
            if asked is not None and asked != "all" and not SESSION_ID.match(asked):
                q.reply_err(f"session={shown(asked)}: give a session's id (YYYYMMDD-HHMMSS, as "
                            "get sessions lists them) or all")
                return
            for rover, desk in self.rovers.items():
                key, journal = keys.faults_journal(rover), desk.journal
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    session = self.running(desk) if asked is None else asked
                    if session not in ("all", self.running(desk)) \
                            and not journal.sessions.known(session):
                        ids = ", ".join(journal.sessions.ids()) or "none"
                        q.reply_err(f"no session {session} of {rover} in its journal (sessions: {ids})")
                        continue
                    lines = journal.lines(None if session == "all" else session)
                    if last is not None:
                        lines = lines[-int(last):] if int(last) else []
                    # megabytes for a long session: never dropped behind a burst of events
                    q.reply(key, b"[" + b",".join(lines) + b"]",
                            encoding=zenoh.Encoding.APPLICATION_JSON,
                            congestion_control=zenoh.CongestionControl.BLOCK)

    def on_sessions_query(self, q: zenoh.Query) -> None:
        with q:
            for rover, desk in self.rovers.items():
                key = keys.sessions(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    q.reply(key, msgspec.json.encode(desk.journal.session_infos(self.running(desk))),
                            encoding=zenoh.Encoding.APPLICATION_JSON)

    def on_faults_query(self, q: zenoh.Query) -> None:
        # Answered on Zenoh's thread: the owners are asked at once, and the query is
        # finalised when their answers are in (or the timeout ends the gathering).
        wanted = [r for r in sorted(self.rovers)
                  if zenoh.KeyExpr(keys.faults(r)).intersects(q.key_expr)]
        if not wanted:
            q.drop()
            return
        gathering = Gathering(q, {r: self.rovers[r].owners for r in wanted})
        rover_chunk = wanted[0] if len(wanted) == 1 else "*"
        self.rt.zenoh_session.get(keys.faults_active(rover_chunk, "*"),
                                  zenoh.handlers.Callback(gathering.on_reply, gathering.on_done),
                                  consolidation=zenoh.ConsolidationMode.NONE,
                                  timeout=GATHER_TIMEOUT_S)

    def start(self) -> None:
        rt = self.rt
        for rover, desk in self.rovers.items():
            if desk.journal.damage:
                rt.state_damaged(rover, f"faults journal of {rover} damaged: {desk.journal.damage}",
                                 keys.faults_journal(rover))
        for desk in self.rovers.values():
            desk.unopened = desk.journal.count == 0
        for rover in sorted(self.rovers):
            self.open_journal(self.rovers[rover])
        rt.on_exit(partial(self.end_floods, force=True))
        # The queries are no port of the table: keys no family describes (their answers are
        # lists, not one Struct), each answered for every rover the query names at once;
        # `get faults` on Zenoh's thread, as it waits on the owners' answers.
        rt.keep(rt.zenoh_session.declare_queryable(keys.faults("*"), self.on_faults_query))
        rt.queryable(keys.faults_journal("*"), self.on_journal_query)
        rt.queryable(keys.snapshots("*"), self.on_snapshots_query)
        rt.queryable(keys.sessions("*"), self.on_sessions_query)
        rt.queryable(keys.faults_armed("*"), self.arms.on_query)
        self.arms.load()


class Gathering:
    """A ``get faults``: the owners' records of the faults in effect gathered on Zenoh's
    thread, the query answered once the get is over."""

    def __init__(self, q: zenoh.Query, owners: dict[str, set[str]]):
        self.q, self.owners = q, owners  # rover -> the services that must answer
        self.gathered: dict[str, list[ActiveFault]] = {r: [] for r in owners}
        self.answered: dict[str, set[str]] = {r: set() for r in owners}
        self.lock = threading.Lock()

    def on_reply(self, reply: zenoh.Reply) -> None:
        if reply.ok is None:
            return
        rover, _ = keys.split(str(reply.ok.key_expr))
        answer = decode(reply.ok.payload.to_bytes(), ActiveFaults)
        with self.lock:
            if rover in self.gathered:
                self.gathered[rover].extend(answer.faults)
                self.answered[rover].add(answer.service)

    def on_done(self) -> None:
        q = self.q
        with q:
            for rover, owners in self.owners.items():
                faults = sorted(self.gathered[rover], key=lambda f: (f.since_t_s, f.key))
                q.reply(keys.faults(rover), msgspec.json.encode(faults),
                        encoding=zenoh.Encoding.APPLICATION_JSON)
                for service in sorted(owners - self.answered[rover]):
                    q.reply_err(f"the {service} service of {rover} did not answer within "
                                f"{GATHER_TIMEOUT_S:g} s: its faults are not listed")


NODE = FaultsNode
