"""A live mirror of the twin: what every tool that shows the twin reads (STYLE habit 11).

Longer than 450 lines: one lock over everything a tool reads of the twin (values, history,
events, trainee sessions, services, links), kept and bounded together.

One :class:`Mirror` per tool subscribes, for one rover or every rover (``"*"``), to

- the telemetry key families it is asked for (advanced subscribers with history: a tool that
  joins a running session has the current values at once), keeping each key's latest value,
  decoded by its family's Struct, and for some families a bounded history (at most one point
  per ``history_every_s``);
- the events on ``lunaris/<rover>/event`` and ``event/<service>`` (DECISIONS D1), each taken
  once (:mod:`lunaris.client.events`), the latest ``keep_events`` per rover;
- each rover's trainee session (SPEC §12c): its id from the clock's ticks, its trainee from the
  clock's event that opened it. When a tick says another session runs, the rover's history
  and events are dropped (a tool's plots and event log start empty with each session) and the
  listeners are told (a ``session`` change); an event of an earlier session (late, or replayed
  from a cache) is not kept, one of a later session (the event that opens it comes before its
  first tick) is kept but not read before the tick says that session runs. Session ids grow
  (the UTC time each began, ``YYYYMMDD-HHMMSS``), which says earlier from later;
- the services' liveliness tokens: which services are live, and since when one is gone;

and judges each rover's link from its clock (:mod:`lunaris.client.link`): lost when no tick
came for 2 s or the clock's token went away, up again with the next tick.

What it keeps is bounded whoever publishes: at most ``max_rovers`` rovers, ``max_names``
components per family of a rover, samples of at most ``MAX_SAMPLE_BYTES``, and the latest
values within ``budget_bytes``; a rover with no live service is forgotten after a while
(:meth:`Mirror.sweep`), one that never had one sooner. A sample it cannot read (not its
key's Struct, too large, past a bound) is skipped and said once.

Zenoh calls back on its own threads: everything is behind one lock; listeners
(:meth:`Mirror.listen`) are told of each change on those threads, after the mirror holds it.
The entry points :meth:`Mirror.feed` and :meth:`Mirror.feed_token` take plain keys and bytes,
so the mirror is tested without Zenoh, with a clock of the test's own.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.conditions import Lookup
from common.messages import Event
from lunaris.client.events import EventWindow, event_identity, in_session, session_opened, source_mismatch
from lunaris.client.link import LINK_TIMEOUT_S, Link, LinkTracker, clock_time
from lunaris.client.records import Change, Session, Token, Value, _Rover
from lunaris.client.session import ignored

__all__ = ["MAX_SAMPLE_BYTES", "Change", "Mirror", "Session", "Token", "Value"]

MAX_ROVERS = 256  # rovers kept at once (a fleet of 200 is measured in docs/fleet.md)
MAX_NAMES = 64  # components of one family of one rover (loads, rails, panels, radios ...)
MAX_SAMPLE_BYTES = 32_768  # telemetry is well under 2 kB; the faults in effect a few kB
MAX_EVENT_BYTES = 4_096  # an event's message is at most a thousand characters
BUDGET_BYTES = 32 * 1024 * 1024  # the latest values of every key, together
FORGET_S = 600.0  # a rover whose services are all gone is forgotten after this long quiet
STRANGER_S = 30.0  # ... one that never had a live service, sooner
TRAINEES_KEPT = 8  # the trainees of the latest sessions, per rover
SWEEP_EVERY_S = 5.0


class Mirror:
    """The twin as one tool sees it, kept up to date by Zenoh (see the module's text)."""

    def __init__(self, rover: str = "*", *, families: Iterable[str] | None = None,
                 events: bool = True, event_history: bool = True, keep_events: int = 300,
                 history: Mapping[str, int] | None = None, history_every_s: float = 1.0,
                 max_rovers: int = MAX_ROVERS, max_names: int = MAX_NAMES,
                 budget_bytes: int = BUDGET_BYTES, link_timeout_s: float = LINK_TIMEOUT_S,
                 clock: Callable[[], float] = time.time):
        out = {f.name: f for f in keys.families("out") if f.name != "event"}
        chosen = list(out) if families is None else list(families)
        unknown = [name for name in chosen if name not in out]
        if unknown:
            raise ValueError(f"no telemetry family {', '.join(unknown)} (families: {', '.join(out)})")
        if "clock" not in chosen:
            chosen.insert(0, "clock")  # the link is judged from the clock
        self.rover = rover
        self.families = tuple(out[name] for name in chosen)
        self.events_on = events
        self.event_history = event_history
        self.keep_events = keep_events
        self.history_len = dict(history or {})
        self.history_every_s = history_every_s
        self.max_rovers, self.max_names, self.budget_bytes = max_rovers, max_names, budget_bytes
        self.link_timeout_s = link_timeout_s
        self.clock = clock
        self.connected: bool | None = None  # the router: None until asked
        self.disconnected_at: float | None = None
        self._lock = threading.Lock()
        self._rovers: dict[str, _Rover] = {}
        self._window = EventWindow()
        self._bytes = 0
        self._decoders: dict[type, msgspec.json.Decoder] = {}
        self._listeners: list[Callable[[Change], None]] = []
        self._keep: list[Any] = []
        self._last_sweep = clock()
        self._forgotten: deque[str] = deque(maxlen=1024)  # told at the next sweep
        self.session: zenoh.Session | None = None
        self.started_at: float | None = None  # when start() subscribed

    # -- Zenoh ------------------------------------------------------------------------------

    def start(self, session: zenoh.Session) -> Mirror:
        """Subscribe (the publishers' caches are replayed first) and ask the router which
        services are live. The question comes before the liveliness subscription: a session
        with one answers such questions itself, from what it has heard so far (at first,
        nothing)."""
        self.session = session
        self.started_at = self.clock()
        history = zext.HistoryConfig(detect_late_publishers=True)
        for family in self.families:
            self._keep.append(zext.declare_advanced_subscriber(
                session, family.pattern(self.rover), self._on_sample, history=history))
        if self.events_on:
            pattern = keys.under(self.rover, "event/**")
            self._keep.append(
                zext.declare_advanced_subscriber(session, pattern, self._on_sample, history=history)
                if self.event_history else session.declare_subscriber(pattern, self._on_sample))
        self.sync()
        self._keep.append(session.liveliness().declare_subscriber(
            keys.service(self.rover, "*"), self._on_token, history=True))
        return self

    def sync(self, timeout_s: float = 2.0) -> dict[str, set[str]]:
        """Ask which services are live now (rover -> services) and hold them."""
        assert self.session is not None, "start the mirror first"
        found: dict[str, set[str]] = {}
        for reply in self.session.liveliness().get(keys.service(self.rover, "*"), timeout=timeout_s):
            if reply.ok is not None:
                try:
                    rover, parts = keys.split(str(reply.ok.key_expr))
                except ValueError:
                    continue
                found.setdefault(rover, set()).add(parts[-1])
                self.feed_token(str(reply.ok.key_expr), True)
        return found

    def barrier(self, timeout_s: float = 2.0) -> None:
        """A round trip to the router: it handles a client's messages in order, so once it has
        answered, every subscription declared before is in place there. (A liveliness question
        on a key no token has, and that no subscription of ours matches, so the router answers.)"""
        assert self.session is not None, "start the mirror first"
        list(self.session.liveliness().get(keys.under(self.rover, "service"), timeout=timeout_s))

    def refresh_connection(self) -> bool:
        """Whether the session has a router now (asked of Zenoh; Zenoh reconnects by itself)."""
        session = self.session
        try:
            connected = session is not None and bool(list(session.info.routers_zid()))
        except zenoh.ZError:
            connected = False
        with self._lock:
            if connected != self.connected:
                if not connected:
                    self.disconnected_at = self.clock()
                self.connected = connected
        return connected

    def close(self) -> None:
        self._keep.clear()

    def _on_sample(self, s: zenoh.Sample) -> None:
        self.feed(str(s.key_expr), s.payload.to_bytes(), s.kind == zenoh.SampleKind.PUT)

    def _on_token(self, s: zenoh.Sample) -> None:
        self.feed_token(str(s.key_expr), s.kind == zenoh.SampleKind.PUT)

    def listen(self, listener: Callable[[Change], None]) -> None:
        """Call ``listener(change)`` for every change, on Zenoh's threads."""
        self._listeners.append(listener)

    # -- what comes in ------------------------------------------------------------------------

    def feed(self, key: str, raw: bytes, put: bool = True) -> Change | None:
        """A sample on ``key``; the change it made, or None when it made none."""
        try:
            rover, parts = keys.split(key)
        except ValueError:
            return None
        if not put:
            return None  # telemetry and events are puts; a delete of one means nothing
        told: Change | None = None
        if parts and parts[0] == "event":
            change, told = self._event(key, rover, parts, raw)
        else:
            change, told = self._value(key, rover, parts, raw)
        for c in (told, change):
            if c is not None:
                for listener in self._listeners:
                    listener(c)
        return change

    def _decode(self, typ: type, raw: bytes) -> Any:
        dec = self._decoders.get(typ)
        if dec is None:
            dec = self._decoders[typ] = msgspec.json.Decoder(typ)
        return dec.decode(raw)

    def _value(self, key: str, rover: str, parts: list[str], raw: bytes
               ) -> tuple[Change | None, Change | None]:
        """(the change, a session change it brought first or None)."""
        family = next((f for f in self.families if f.matches(parts)), None)
        if family is None:
            return None, None
        if len(raw) > MAX_SAMPLE_BYTES:
            ignored(key, f"{len(raw)} bytes, more than a {family.name} sample ever holds")
            return None, None
        try:
            value = self._decode(family.payload, raw)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            ignored(key, f"not a valid {family.payload.__name__} ({exc})")
            return None, None
        now = self.clock()
        told: Change | None = None
        with self._lock:
            r = self._admit(rover, key, now)
            if r is None:
                return None, None
            if family.name == "clock" and value.session and value.session != r.session:
                told = self._new_session(r, rover, value.session)
            old = r.latest.get(key)
            if old is None:
                if family.placeholder is not None:
                    names = r.names.setdefault(family.name, set())
                    name = parts[family.chunks.index(f"{{{family.placeholder}}}")]
                    if name not in names and len(names) >= self.max_names:
                        refused = f"{rover} has {self.max_names} {family.placeholder}s already"
                        name = ""
                    else:
                        names.add(name)
                        refused = ""
                    if not name:
                        ignored(key, refused)
                        return None, told
                if self._bytes + len(raw) > self.budget_bytes:
                    ignored(key, f"the values held reached {self.budget_bytes // 2**20} MB")
                    return None, told
            self._bytes += len(raw) - (len(old.raw) if old is not None else 0)
            v = r.latest[key] = Value(raw, value, now)
            points = self.history_len.get(family.name)
            if points:
                h = r.history.get(key)
                if h is None:
                    h = r.history[key] = deque(maxlen=points)
                if not h or now - h[-1].at >= self.history_every_s:
                    h.append(v)
            if family.name == "clock":
                r.link.tick(now)
            self._maybe_sweep(now)
        return Change("value", rover, key, raw, value), told

    def _new_session(self, r: _Rover, rover: str, session: str) -> Change:
        """(Lock held.) The clock says ``session`` runs: what the mirror kept of the previous
        one goes (its history; its events, and those of no session). At the first tick heard
        only the events of other sessions go (replayed from the caches)."""
        first = not r.session  # the first tick heard: the history is the caches' latest values
        r.session = session
        if not first:
            for h in r.history.values():
                h.clear()
        r.events = deque((ev, raw) for ev, raw in r.events
                         if ev.session == session or (first and not ev.session))
        return Change("session", rover, keys.rover_prefix(rover), b"",
                      Session(session, r.trainees.get(session)))

    def _event(self, key: str, rover: str, parts: list[str], raw: bytes
               ) -> tuple[Change | None, Change | None]:
        """(the change, a session change it brought first or None: the trainee of the
        running session learnt)."""
        if len(raw) > MAX_EVENT_BYTES:
            ignored(key, f"an event of {len(raw)} bytes (at most {MAX_EVENT_BYTES})")
            return None, None
        try:
            ev = self._decode(Event, raw)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            ignored(key, f"not an event ({exc})")
            return None, None
        wrong = source_mismatch(parts, ev)
        if wrong is not None:
            ignored(key, wrong)
            return None, None
        now = self.clock()
        told: Change | None = None
        with self._lock:
            if not self._window.first(event_identity(rover, ev)):
                return None, None  # heard on the journal's key and the service's, or replayed
            r = self._admit(rover, key, now)
            if r is None:
                return None, None
            opened = session_opened(ev)
            if opened is not None and opened[0] not in r.trainees:
                r.trainees[opened[0]] = opened[1]
                while len(r.trainees) > TRAINEES_KEPT:
                    del r.trainees[next(iter(r.trainees))]
                if opened[0] == r.session:
                    told = Change("session", rover, keys.rover_prefix(rover), b"",
                                  Session(r.session, opened[1]))
            if r.session and ev.session and ev.session < r.session:
                return None, told  # an earlier session's, late or replayed
            r.events.append((ev, raw))
            while len(r.events) > self.keep_events:
                r.events.popleft()
            if not in_session(ev, r.session):
                return None, told  # a later session's: told once its first tick has come
        return Change("event", rover, key, raw, ev), told

    def feed_token(self, key: str, alive: bool) -> Change | None:
        """A liveliness token of ``lunaris/<rover>/service/<name>`` put (alive) or gone."""
        try:
            rover, parts = keys.split(key)
        except ValueError:
            return None
        if len(parts) != 2 or parts[0] != "service":
            return None
        now = self.clock()
        with self._lock:
            r = self._rovers.get(rover) if not alive else self._admit(rover, key, now)
            if r is None:
                return None
            before = r.tokens.get(parts[1])
            if before is not None and before.alive == alive:
                return None
            if not alive and before is None:
                return None
            r.tokens[parts[1]] = Token(alive, now)
            r.ever_live = r.ever_live or alive
            r.seen = now
            if parts[1] == "clock":
                r.link.clock_token(alive, now)
            live = sorted(r.live())
        change = Change("services", rover, keys.rover_prefix(rover), b"", live)
        for listener in self._listeners:
            listener(change)
        return change

    def _admit(self, rover: str, key: str, now: float) -> _Rover | None:
        """The rover's record, made if there is room (lock held)."""
        r = self._rovers.get(rover)
        if r is None:
            if len(self._rovers) >= self.max_rovers and not self._evict_one():
                ignored(key, f"{self.max_rovers} rovers are shown already")
                return None
            r = self._rovers[rover] = _Rover(link=LinkTracker(self.link_timeout_s))
        r.seen = now
        return r

    # -- forgetting ---------------------------------------------------------------------------

    def _evict_one(self) -> bool:
        quiet = [(r.seen, name) for name, r in self._rovers.items() if not r.live()]
        if not quiet:
            return False
        self._drop(min(quiet)[1])
        return True

    def _drop(self, rover: str) -> None:
        r = self._rovers.pop(rover)
        self._bytes -= sum(len(v.raw) for v in r.latest.values())
        self._forgotten.append(rover)

    def _maybe_sweep(self, now: float) -> None:
        if now - self._last_sweep >= SWEEP_EVERY_S:
            self._sweep(now)

    def _sweep(self, now: float) -> None:
        self._last_sweep = now
        for name, r in list(self._rovers.items()):
            if r.live():
                continue
            quiet = now - r.seen
            if quiet > (FORGET_S if r.ever_live else STRANGER_S):
                self._drop(name)

    def sweep(self) -> list[str]:
        """Forget the rovers long without a live service; the rovers forgotten since the last
        call (by this or by making room), each told to the listeners as a ``forget``."""
        with self._lock:
            self._sweep(self.clock())
            gone = list(self._forgotten)
            self._forgotten.clear()
        for rover in gone:
            change = Change("forget", rover, keys.rover_prefix(rover), b"", None)
            for listener in self._listeners:
                listener(change)
        return gone

    # -- what is read ---------------------------------------------------------------------------

    def rovers(self) -> list[str]:
        with self._lock:
            return sorted(self._rovers)

    def get(self, key: str) -> Value | None:
        rover, _ = keys.split(key)
        with self._lock:
            r = self._rovers.get(rover)
            return None if r is None else r.latest.get(key)

    def value(self, key: str) -> Any:
        """The latest decoded value of ``key`` (its family's Struct), or None."""
        got = self.get(key)
        return None if got is None else got.value

    def latest(self, rover: str | None = None) -> dict[str, Value]:
        """Every key's latest sample (of one rover, or of all)."""
        with self._lock:
            rs = [self._rovers[rover]] if rover in self._rovers else [] if rover else list(
                self._rovers.values())
            return {k: v for r in rs for k, v in r.latest.items()}

    def history(self, key: str) -> list[Value]:
        rover, _ = keys.split(key)
        with self._lock:
            r = self._rovers.get(rover)
            return list(r.history.get(key, ())) if r is not None else []

    def events(self, rover: str | None = None) -> list[tuple[str, Event, bytes]]:
        """(rover, event, payload) of the events kept of each rover's running session,
        oldest first per rover."""
        with self._lock:
            names = [rover] if rover is not None else sorted(self._rovers)
            return [(n, ev, raw) for n in names if n in self._rovers
                    for ev, raw in self._rovers[n].events if in_session(ev, self._rovers[n].session)]

    def session_of(self, rover: str) -> Session | None:
        """The rover's running session (None before its clock's first tick)."""
        with self._lock:
            r = self._rovers.get(rover)
            if r is None or not r.session:
                return None
            return Session(r.session, r.trainees.get(r.session))

    def sessions(self) -> dict[str, Session]:
        """Every rover's running session (the rovers whose clock has ticked)."""
        with self._lock:
            return {name: Session(r.session, r.trainees.get(r.session))
                    for name, r in self._rovers.items() if r.session}

    def services(self, rover: str) -> set[str]:
        """The services of ``rover`` whose liveliness token is there now."""
        with self._lock:
            r = self._rovers.get(rover)
            return r.live() if r is not None else set()

    def all_services(self) -> dict[str, set[str]]:
        with self._lock:
            return {name: r.live() for name, r in self._rovers.items()}

    def token(self, rover: str, service: str) -> Token | None:
        """A service's token as last seen (None: never seen)."""
        with self._lock:
            r = self._rovers.get(rover)
            return None if r is None else r.tokens.get(service)

    def link(self, rover: str) -> Link:
        """The rover's link now (lost while the router is gone, whatever its clock did)."""
        now = self.clock()
        with self._lock:
            if self.connected is False:
                since = self.disconnected_at or now
                return Link("lost", since, f"the router is unreachable since {clock_time(since)}")
            r = self._rovers.get(rover)
            link = Link("unknown", None, "nothing heard of it yet") if r is None else r.link.state(now)
            waited = now - self.started_at if self.started_at is not None else 0.0
            if link.state == "unknown" and self.connected and waited > self.link_timeout_s:
                # a rover asked for that has not ticked since the tool connected: cut off, or
                # not running (a tool started during a partition must say so, not wait)
                return Link("lost", self.started_at, f"no clock tick of {rover} in the {waited:.0f} s "
                                                     "since this tool connected: unreachable or not "
                                                     "running")
            return link

    def links(self) -> dict[str, Link]:
        return {rover: self.link(rover) for rover in self.rovers()}

    def lookup(self, rover: str) -> Lookup:
        """The scenario conditions' view of a rover: key chunks -> the latest payload's fields."""
        prefix = keys.rover_prefix(rover) + "/"

        def look(parts: tuple[str, ...]) -> dict | None:
            got = self.get(prefix + "/".join(parts))
            return None if got is None else msgspec.structs.asdict(got.value)
        return look

    def stats(self) -> dict[str, int]:
        """What is held, counted (for tests and benchmarks of the bounds)."""
        with self._lock:
            return {"rovers": len(self._rovers), "keys": sum(len(r.latest) for r in self._rovers.values()),
                    "events": sum(len(r.events) for r in self._rovers.values()),
                    "history": sum(len(h) for r in self._rovers.values() for h in r.history.values()),
                    "bytes": self._bytes, "event_window": len(self._window)}

