"""Faults service: the session's journal, ``get lunaris/<rover>/faults``, and the gatekeeper.

- **The journal**: every event of the rover, kept on disk for the whole training day (a flood
  of rejections is summarised, and the summary says so), in one segment per trainee session
  (SPEC §12c: each event says its ``session``), answered to
  ``get lunaris/<rover>/faults/journal``: the running session's events, ``?session=<id>``
  another's (``?session=all``: every session's), ``?last=N`` the latest N of them.
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
- **Marks**: ``control/mark`` ``{"text"}`` is answered with a ``mark`` event (by whoever wrote
  it: its ``actor``), an instructor's note on the timeline.
"""

from __future__ import annotations

import threading
import time

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.faults import check_component
from common.messages import (
    SESSION_ID,
    ActiveFault,
    ActiveFaults,
    BadInput,
    Event,
    ScenarioMark,
    SnapshotInfo,
    TimelineMark,
    decode,
    decode_input,
    encode,
)
from common.reasons import shown
from common.runtime import EVENT_CACHE, Runtime, Sample
from common.session import parse_control
from services.faults.journal import Journal

__all__ = ["fault_owners", "serve"]

GATHER_TIMEOUT_S = 2.0  # how long a `get faults` waits for the owners' answers
# The heads of the keys that instructors, scenarios and dashboards write.
WRITABLE = ("fault/**", "input/**", "cmd/**", "clock/control/**", "control/**")
CONTROLS = ("control/session, control/mark, control/reset, control/snapshot/<name>, "
            "control/restore/<name>")
SESSION_MESSAGES = {
    "reset": "session reset: every service back to the rover file's initial conditions, "
             "injected faults cleared, the clock at 0",
    "snapshot": "snapshot {name!r} saved",
}


def fault_owners(rover: Rover) -> set[str]:
    """The services that own the faults of a rover's components, as its file implies them."""
    owners = {"battery"}
    if rover.loads:
        owners.add("loads")
    if rover.rails:
        owners.add("power")
    if rover.solar.panels or rover.umbilical.power_w > 0 or rover.umbilical.connected:
        owners.add("solar")
    if rover.radios:
        owners.add("radio")
    return owners


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    folder = rt.store.dir
    journals = {r.id: Journal(folder / f"faults-journal-{r.id}.jsonl" if folder else None,
                              rover=r.id) for r in rovers}
    drives = {r.id: r.drive is not None for r in rovers}
    owners = {r.id: fault_owners(r) for r in rovers}
    live_rovers: set[str] = set()
    session = rt.session
    assert session is not None

    def on_token(s: zenoh.Sample) -> None:
        rover, _ = keys.split(str(s.key_expr))
        if s.kind == zenoh.SampleKind.PUT:
            live_rovers.add(rover)

    rt.keep(session.liveliness().declare_subscriber(
        keys.service("*", "*"), on_token, history=True))

    def on_event(s: Sample) -> None:
        """An event a service published on its own key: journalled and relayed on the rover's
        ``event`` key if its ``source`` is that service, refused (and said) if not."""
        ev = decode(s.payload, Event)
        if len(s.parts) != 2 or ev.source != s.parts[1]:
            rt.event(s.rover, "critical", "rejected", s.key,
                     f"forged event refused: published on {s.key}, the key of the "
                     f"{s.parts[-1]} service, it claims to come from {shown(ev.source)} "
                     f"({ev.kind}: {shown(ev.message)}); not journalled")
            return
        relay(s.rover, journals[s.rover].record(ev, time.monotonic()))
        if ev.source == "clock" and ev.kind == "session" and ev.session > rt.session_id[s.rover] \
                and "started_wall" in (ev.params or {}):
            # the clock's word that a session begins: a write answered here after it is in
            # that session, whether its first tick has come or not (ids grow: a session's
            # event replayed from a cache never takes this service back)
            rt.enter_session(s.rover, ev.session)

    def relay(rover: str, written: list[Event]) -> None:
        """What the journal wrote, unchanged, on ``lunaris/<rover>/event``: the journal's
        stream (complete, authenticated, floods summarised)."""
        for ev in written:
            rt.publish_bytes(keys.event(rover), encode(ev), zenoh.Encoding.APPLICATION_JSON,
                             reliable=True, cache=EVENT_CACHE)

    def end_floods(force: bool = False) -> None:
        """Summaries of the floods that have ended (all of them, ``force``), and the events
        that never came back counted."""
        for rover, journal in journals.items():
            relay(rover, journal.tick(time.monotonic(), flood_over=force))

    def on_instructor_key(s: Sample) -> None:
        if s.rover not in rt.rovers and s.rover not in live_rovers:
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
            on_control(s)
            return
        family = keys.family_of(s.parts)
        if family is None or family.direction != "in":
            writable = ", ".join(f.name for f in keys.families("in"))
            raise BadInput(f"no such input or command {'/'.join(s.parts)!r} (the twin reads: "
                           f"{writable}, fault/...)")
        if family.owner == "drive" and not drives[s.rover]:
            raise BadInput(f"rover {s.rover} has no drive section in its rover file: it does not "
                           "drive, so it cannot follow a traverse")

    def on_wildcard(s: Sample) -> None:
        """A write on a key naming many (``lunaris/**``): no service took it; refused once, in
        words, for each rover served here that it reaches."""
        verb = "delete" if s.deleted else "put"
        expr = zenoh.KeyExpr(s.key)
        for rover in sorted(rt.rovers):
            if zenoh.KeyExpr(keys.under(rover)).intersects(expr):
                rt.reject(rover, s.key, f"a {verb} on {s.key} names many keys (it holds a wildcard: "
                                        "*, ** or $*); a write names exactly one key. Nothing changed")

    def on_control(s: Sample) -> None:
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

    def gather_snapshots(rover: str) -> list[SnapshotInfo]:
        merged: dict[str, SnapshotInfo] = {}
        for reply in session.get(keys.snapshots_of(rover, "*"), timeout=GATHER_TIMEOUT_S,
                                 consolidation=zenoh.ConsolidationMode.NONE):
            if reply.ok is None:
                continue
            for info in msgspec.json.decode(reply.ok.payload.to_bytes(), type=list[SnapshotInfo]):
                known = merged.setdefault(info.name, SnapshotInfo(info.name, info.t_s,
                                                                  info.saved_at, []))
                known.services.extend(info.services)
        return [merged[n] for n in sorted(merged)]

    def on_snapshots_query(q: zenoh.Query) -> None:
        with q:
            for rover in sorted(journals):
                key = keys.snapshots(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    q.reply(key, msgspec.json.encode(gather_snapshots(rover)),
                            encoding=zenoh.Encoding.APPLICATION_JSON)

    def running(rover: str) -> str:
        """The session running: as the ticks say, or the journal's latest."""
        return rt.session_id.get(rover) or journals[rover].sessions.running

    def on_journal_query(q: zenoh.Query) -> None:
        with q:
            last = q.parameters.get("last")
            if last is not None and not last.isdigit():
                q.reply_err(f"last={last!r}: give a whole number of events")
                return
            asked = q.parameters.get("session")
            if asked is not None and asked != "all" and not SESSION_ID.match(asked):
                q.reply_err(f"session={shown(asked)}: give a session's id (YYYYMMDD-HHMMSS, as "
                            "get sessions lists them) or all")
                return
            for rover, journal in journals.items():
                key = keys.faults_journal(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    session = running(rover) if asked is None else asked
                    if session not in ("all", running(rover)) and not journal.sessions.known(session):
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

    def on_sessions_query(q: zenoh.Query) -> None:
        with q:
            for rover, journal in journals.items():
                key = keys.sessions(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    q.reply(key, msgspec.json.encode(journal.session_infos(running(rover))),
                            encoding=zenoh.Encoding.APPLICATION_JSON)

    def on_faults_query(q: zenoh.Query) -> None:
        # Answered on Zenoh's thread: the owners are asked at once, and the query is
        # finalised when their answers are in (or the timeout ends the gathering).
        wanted = [r for r in sorted(journals) if zenoh.KeyExpr(keys.faults(r)).intersects(q.key_expr)]
        if not wanted:
            q.drop()
            return
        gathered: dict[str, list[ActiveFault]] = {r: [] for r in wanted}
        answered: dict[str, set[str]] = {r: set() for r in wanted}
        lock = threading.Lock()

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is None:
                return
            rover, _ = keys.split(str(reply.ok.key_expr))
            answer = decode(reply.ok.payload.to_bytes(), ActiveFaults)
            with lock:
                if rover in gathered:
                    gathered[rover].extend(answer.faults)
                    answered[rover].add(answer.service)

        def on_done() -> None:
            with q:
                for rover in wanted:
                    faults = sorted(gathered[rover], key=lambda f: (f.since_t_s, f.key))
                    q.reply(keys.faults(rover), msgspec.json.encode(faults),
                            encoding=zenoh.Encoding.APPLICATION_JSON)
                    for service in sorted(owners[rover] - answered[rover]):
                        q.reply_err(f"the {service} service of {rover} did not answer within "
                                    f"{GATHER_TIMEOUT_S:g} s: its faults are not listed")

        rover_chunk = wanted[0] if len(wanted) == 1 else "*"
        session.get(keys.faults_active(rover_chunk, "*"),
                    zenoh.handlers.Callback(on_reply, on_done),
                    consolidation=zenoh.ConsolidationMode.NONE,
                    timeout=GATHER_TIMEOUT_S)

    rt.on_wildcard(on_wildcard)
    rt.subscribe(keys.event_of("*", "*"), on_event, history=True)
    for rover, journal in journals.items():
        if journal.damage:
            rt.state_damaged(rover, f"faults journal of {rover} damaged: {journal.damage}",
                             keys.faults_journal(rover))
    # A new journal's first line, in the session the clock's ticks say (once one has come)
    unopened = {rover for rover, journal in journals.items() if journal.count == 0}

    def open_journal(rover: str, tick: object = None) -> None:
        if rover in unopened and rt.session_id.get(rover):
            unopened.discard(rover)
            rt.event(rover, "info", "session", keys.faults_journal(rover),
                     f"journal opened: the journal of {rover} begins in session "
                     f"{rt.session_id[rover]}")

    for rover in sorted(unopened):
        open_journal(rover)
    rt.on_tick(lambda rover, tick: open_journal(rover) if unopened else None)
    rt.every(1.0, end_floods)
    rt.on_exit(lambda: end_floods(force=True))
    def on_one_chunk(s: Sample) -> None:
        if s.parts[0] in ("clock", "event") or any(h.startswith(s.parts[0] + "/") for h in WRITABLE):
            return  # telemetry (its writer is the router's to check), or answered above
        on_instructor_key(s)

    for head in WRITABLE:
        rt.subscribe(keys.under("*", head), on_instructor_key, any_rover=True, writes="gate")
    rt.subscribe(keys.under("*", "*"), on_one_chunk, any_rover=True, telemetry=True, writes="gate")
    rt.keep(session.declare_queryable(keys.faults("*"), on_faults_query))
    rt.queryable(keys.faults_journal("*"), on_journal_query)
    rt.queryable(keys.snapshots("*"), on_snapshots_query)
    rt.queryable(keys.sessions("*"), on_sessions_query)
