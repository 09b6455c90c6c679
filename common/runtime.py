"""The one service runtime: every Lunaris service is a model wrapped by this shell.

Longer than 450 lines: the session, the subscriptions that feed the worker
(:mod:`common.worker`), and the publishers and events are one shell.

A :class:`Runtime` is a context manager: ``with Runtime(name, rovers, conf, state_dir) as rt:``
opens the Zenoh session, the service declares what it needs (a node's ports,
:meth:`common.node.Node.attach`; the bridge's ``serve(rt, rovers)``), and
:meth:`Runtime.run` serves until SIGINT or SIGTERM. What it gives a service:

- a liveliness token ``lunaris/<rover>/service/<name>`` per rover served, declared once
  the service is set up (a live token means its subscribers are in place);
- simulated time: one subscription to each rover's clock; :attr:`Runtime.t_s` is the sim
  time of the tick being handled, and :meth:`on_tick` handlers run with it, on the worker
  thread, so every payload a handler publishes carries the time of its own tick;
- :meth:`publish`: JSON on a ``zenoh.ext`` advanced publisher whose cache keeps the last
  sample for late joiners;
- :meth:`subscribe`: samples are handled one at a time on the service's worker thread
  (:mod:`common.worker`: the order of faults, telemetry, inputs, hooks and timers), so
  models need no locks; a burst of inputs is folded into one recomputation, a fault is
  acted on at once (``urgent``), and a fleet's stream never holds back the hooks and
  timers. A service of a fleet (``POLL_FROM_ROVERS`` rovers or more) takes its tick-rate
  telemetry (``telemetry=True``, the clock included) from Zenoh channels the worker drains,
  not through a Python callback per sample (which costs about twice the CPU: a thread
  hand-off and the GIL for each sample), and declares each key it hears from there in its
  session (see :meth:`subscribe`); inputs, commands, faults and queries stay callbacks;
- one way to refuse input: a handler raises :class:`~common.messages.BadInput` and the
  runtime publishes a ``rejected`` event naming the key and the reason;
- writes name exactly one key: a sample whose key holds a wildcard (``lunaris/**``) is never
  handed to a handler (the faults service, the gatekeeper, refuses it once:
  :meth:`on_wildcard`); a write older than ``WRITE_MAX_AGE_S`` when it arrives (held back by a
  cut link) is refused by its owner, never applied late (:meth:`refusal`);
- :meth:`event`: events on the service's own key ``lunaris/<rover>/event/<service>`` (the
  faults service journals and relays them on ``lunaris/<rover>/event``), each saying who
  acted: the ``actor`` a write carries as its attachment (``instructor`` without one), or
  ``twin`` for its own;
- :attr:`faults`, the :class:`~common.fault_book.FaultBook` of the components the service
  owns, and :attr:`store`, its :class:`~common.state_store.StateStore` on disk;
- the trainee session (SPEC §12c): :attr:`Runtime.session_id` is the session the clock's
  ticks say is running, and every event the service publishes carries it (``session``); it is
  saved with the time, so a restarted service is in its session before its first tick. What
  ends with a session is that session's: a fault cleared or an alarm resolved within
  ``SESSION_GRACE_S`` of a new session's beginning, when it was injected or raised in the
  session that ended, carries that session (the previous trainee's short, cleared by the new
  session's reset, and the trip it caused, resolved as the rails come back on, are never in
  the next trainee's timeline);
- time that never goes back within an epoch: the sim time a service has reached (and its
  epoch) is saved under ``--state-dir`` (``<service>-time.json``); a restarted service
  starts from it (or from the running clock, if that is later), publishes nothing stamped
  with time before the clock's first tick has reached it (what it published before it was
  killed may be later than what it last saved), and ignores a tick from before the time it
  has reached (a clock that lost its own);
- :meth:`claim`: one instance of a service per rover, also when two start at once.

"""

from __future__ import annotations

import contextlib
import fcntl
import gc
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Literal

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.connection import ACTORS, PRIORITY, WRITE_MAX_AGE_S, actor_of
from common.fault_book import FaultBook
from common.host import Handler, Sample
from common.input_events import InputLog, InputNote
from common.messages import BadInput, Clock, Event, EventKind, Severity, decode, encode, humane
from common.reasons import shown
from common.session import SessionKeeper, StateCheck, StateDamaged, StateGet, StateReset, StateSet
from common.state_store import Damaged, StateStore, not_finite
from common.worker import POLL_S, Worker

__all__ = ["AlreadyRunning", "Runtime", "Sample"]

EVENT_CACHE = 256  # recent events kept for a late joiner (the journal's relay)
# The events a service keeps for the journal, shared among the rovers it serves (at least
# EVENT_CACHE each): a faults service that comes back after an outage or a kill -9 asks every
# publisher for them (an advanced subscriber) and journals what it missed; what is older is
# counted lost (services.faults.ledger). At ~0.5 kB an event, ~8 MB when full. Measured: with
# 256, 800 events published during a 2 s outage of the faults service left 544 unaccounted.
EVENT_HISTORY = 16384
# A fleet's telemetry is drained from channels: from this many rovers the samples of a tick
# (hundreds to thousands a second per service) cost less polled than called back one by one.
POLL_FROM_ROVERS = 20
CHANNEL_CAPACITY = 65536  # samples a telemetry channel holds before Zenoh waits on it
# Python's cyclic garbage collector walks every object the process holds, in a full
# collection: at 100 rovers a bridge shard's (its ~5,000 outlets and publishers) took 115-312 ms
# each time, and the faults waited behind it. What exists once the service is set up, and
# again after these delays (the publishers declared with the first samples), is frozen: kept
# out of the collections (still freed when no longer referenced).
FREEZE_AGAIN_S = (5.0, 30.0)
SAVE_TIME_S = 1.0  # wall time between saves of the sim time reached
# Two instances started at once both claim; each looks again this long after its own claim
# reached the router, so that of two claims each sees the other, or the later one sees the
# earlier one's ownership (see Runtime.claim).
CLAIM_SETTLE_S = 0.5


class AlreadyRunning(RuntimeError):
    """Another instance of the service serves the same rover, or holds its state."""


# A fault cleared or an alarm resolved this soon after a session began is the ending session's
# when it began in that one (see Runtime.event): the reset's consequences reach every service
# within a tick or two (0.1 s each) of the clock's.
SESSION_GRACE_S = 2.0
_OPENS = frozenset({"fault_injected", "fault_raised"})
_CLOSES = frozenset({"fault_cleared", "fault_resolved"})
OPENED_KEPT = 4096  # (rover, key) of the faults in effect whose session is remembered

# Events that are the twin's own whoever's write set them off: protection, derived faults, bugs.
TWIN_KINDS = frozenset({"fault_raised", "fault_resolved", "internal_error", "disk_full"})
WriteRole = Literal["own", "follow", "gate"]


TickHandler = Callable[[str, Clock], None]


class Runtime:
    """A running service: its session, its worker thread and its bookkeeping."""

    def __init__(self, name: str, rovers: Iterable[str], conf: zenoh.Config,
                 state_dir: str | os.PathLike | None = None):
        self.name = name
        self.rovers: set[str] = set(rovers)
        self.t_s: dict[str, float] = dict.fromkeys(self.rovers, 0.0)  # sim time per rover
        self.epoch: dict[str, int] = dict.fromkeys(self.rovers, 0)  # the epoch of t_s
        # the trainee session of t_s, as the ticks say (the clock: as it begins them)
        self.session_id: dict[str, str] = dict.fromkeys(self.rovers, "")
        self._session_ended: dict[str, tuple[str, float]] = {}  # rover -> (session, monotonic)
        self._sessions_left: dict[str, list[str]] = {}  # rover -> the sessions it has ended
        self._opened_in: dict[tuple[str, str], str] = {}  # (rover, fault key) -> its session
        self.store = StateStore(state_dir, name)
        # Rovers whose time came from the disk, not from a tick: nothing stamped with time is
        # published for them until the clock's first tick has reached that time.
        self._waiting: set[str] = set()
        self._saved_time: dict[str, tuple[int, float]] = {}  # what <name>-time.json held
        self._saved_session: dict[str, str] = {}  # ... and the session of that time
        self._time_written = b""
        self._behind: set[str] = set()  # rovers whose clock is behind (said once)
        self._makes_time = False  # the clock: it ticks, and waits for no tick
        self._unsaved: dict[str, str] = {}  # what could not be saved -> the error, said once
        self._owner_tokens: list[Any] = []  # claim() won: held until the service tokens are up
        self._conf = conf
        self.worker = Worker(self._guard)
        self._exit_hooks: list[Callable[[], None]] = []
        self._publishers: dict[str, Any] = {}
        self._tick_handlers: list[TickHandler] = []
        self._keep: list[Any] = []  # subscribers, tokens, queryables
        self._faults: FaultBook | None = None
        self._session_keeper: SessionKeeper | None = None
        self._zid = ""
        self._lock_file: Any = None
        self._heard_epoch: dict[str, tuple[int, str]] = {}  # rover -> its ticks' (epoch, session)
        self._claim_tokens: list[Any] = []  # this instance's claims, from __enter__ to claim()
        self._claim_started = 0.0  # monotonic time they were declared
        self._claim_refused = ""  # the state directory is another instance's: why, in words
        self._event_seq: dict[str, int] = {}  # per served rover; "" for the rovers not served
        self._own_events: Callable[[str, Event], Event] | None = None  # see record_own_events
        self._held: list[tuple[tuple, dict]] | None = None  # see events_after
        self._last_tick: dict[str, tuple[int, int, float]] = {}  # rover -> the tick handled last
        self._acting: str | None = None  # the actor of the sample being handled
        self._inputs: InputLog | None = None
        self._heard: dict[str, Any] = {}  # telemetry key -> its declared key expression
        self._subscribed: list[zenoh.KeyExpr] = []  # every subscription's key expression, in order
        self._on_wildcard: Handler | None = None
        self.polled = len(self.rovers) >= POLL_FROM_ROVERS
        self.session: zenoh.Session | None = None

    # -- lifecycle --------------------------------------------------------------------------

    def __enter__(self) -> Runtime:
        self.session = zenoh.open(self._conf)
        self._zid = str(self.session.info.zid())
        self._begin_claim()  # settles while the time is learnt: one wait, not two
        # A tick that begins an epoch or a session is handled ahead of everything waiting, as
        # a fault is: a write sent once the new session was seen must never be applied in
        # the old one and undone by its reset (one of ten pokes so was, under load). (A
        # fleet's ticks are drained from a channel, the first, ahead of the other streams.)
        self.subscribe(keys.clock("*"), self._on_clock, telemetry=True,
                       urgent_if=self._begins_epoch)
        self._learn_time()
        self.every(SAVE_TIME_S, self.save_time)
        self.on_exit(self.save_time)
        return self

    def _learn_time(self, wait_s: float = 0.5) -> None:
        """Start at the time this service had reached (saved) or at the running clock's,
        whichever is later: what it publishes never carries a time older than what it, or the
        twin, already published in the same epoch. A time from the disk alone may be a little
        older than what the service published before it was killed: until a tick reaches it,
        nothing stamped with time goes out (:attr:`_waiting`)."""
        self._saved_time = self._read_time()
        seen: dict[str, tuple[int, float]] = {}
        sessions: dict[str, str] = {}
        done = threading.Event()

        def on_tick(s: zenoh.Sample) -> None:
            rover, _ = keys.split(str(s.key_expr))
            if rover in self.rovers and rover not in seen:
                try:
                    tick = decode(s.payload.to_bytes(), Clock)
                except (msgspec.DecodeError, msgspec.ValidationError):
                    return
                seen[rover] = (tick.epoch, tick.t_s)
                sessions[rover] = tick.session
                if len(seen) == len(self.rovers):
                    done.set()

        sub = self.zenoh_session.declare_subscriber(keys.clock("*"), on_tick)
        done.wait(wait_s)  # a running clock ticks every 0.1 s; none at all: a fresh twin
        sub.undeclare()
        for rover in self.rovers:
            live, disk = seen.get(rover), self._saved_time.get(rover)
            if live is not None and (disk is None or live >= disk):
                self.epoch[rover], self.t_s[rover] = live
                self.session_id[rover] = sessions.get(rover) or self._saved_session.get(rover, "")
            elif disk is not None:
                self.epoch[rover], self.t_s[rover] = disk
                self.session_id[rover] = self._saved_session.get(rover, "")
                self._waiting.add(rover)

    def _read_time(self) -> dict[str, tuple[int, float]]:
        """The (epoch, sim time) each rover had reached, from ``<name>-time.json`` (and its
        session, in :attr:`_saved_session`); a damaged record is said aloud and left out."""
        try:
            saved = self.store.load("time")
        except Damaged as exc:
            for rover in sorted(self.rovers):
                self.state_damaged(rover, f"{self.name} saved time of {rover} damaged "
                                   f"({exc.reason}): not used; {exc.where()}")
            return {}
        if saved is None:
            return {}
        out: dict[str, tuple[int, float]] = {}
        bad: dict[str, str] = {}
        for rover in sorted(self.rovers):
            record = saved.get(rover) if isinstance(saved, dict) else saved
            if record is None:
                continue
            try:
                if not isinstance(record, dict):
                    raise ValueError(f"a {type(record).__name__} where a mapping was expected")
                epoch, t_s = record.get("epoch"), record.get("t_s")
                if type(epoch) is not int or epoch < 0:
                    raise ValueError(f"epoch {epoch!r} is not a whole number >= 0")
                if isinstance(t_s, bool) or not isinstance(t_s, int | float) or not_finite(
                        float(t_s)) or t_s < 0:
                    raise ValueError(f"t_s {t_s!r} is not a finite number >= 0")
                session = record.get("session", "")
                if not isinstance(session, str):
                    raise ValueError(f"session {session!r} is not text")
            except ValueError as exc:
                bad[rover] = str(exc)
                continue
            out[rover] = (epoch, float(t_s))
            self._saved_session[rover] = session
        if bad:
            moved = self.store.set_aside("time")
            where = f"the file was moved to {moved.name}" if moved else "the file is left where it is"
            for rover, reason in bad.items():
                self.state_damaged(rover, f"{self.name} saved time of {rover} damaged ({reason}): "
                                   f"not used; {where}")
        return out

    def save_time(self, durable: bool = True) -> None:
        """Save the (epoch, sim time, session) each rover has reached, when it has moved."""
        if self.store.dir is None:
            return
        record = {r: {"epoch": self.epoch[r], "t_s": self.t_s[r], "session": self.session_id[r]}
                  for r in sorted(self.rovers)}
        data = msgspec.json.encode(record)
        if data != self._time_written and self.save_state("time", record, durable):
            self._time_written = data

    def saved_time(self, rover: str) -> tuple[int, float] | None:
        """The (epoch, sim time) ``rover`` had reached when this service last saved it."""
        return self._saved_time.get(rover)

    def saved_session(self, rover: str) -> str:
        """The session of the time :meth:`saved_time` gives ("" when none was saved)."""
        return self._saved_session.get(rover, "")

    def makes_time(self) -> None:
        """This service is the clock: it publishes the ticks, so it waits for none and judges
        none against its own time."""
        self._makes_time = True
        self._waiting.clear()

    def save_state(self, what: str, data: Any, durable: bool = True) -> bool:
        """Save ``data`` in the store; a disk that refuses it is said once in a ``critical``
        event (and again if the error changes), not at every save. Whether it was saved."""
        try:
            self.store.save(what, data, durable)
        except OSError as exc:
            error = f"{type(exc).__name__}: {exc.strerror or exc}"
            if self._unsaved.get(what) != error:
                self._unsaved[what] = error
                for rover in sorted(self.rovers):
                    self.event(rover, "critical", "state_damaged", keys.service(rover, self.name),
                               f"{self.name} cannot save its {what} in {self.store.path(what)} "
                               f"({error}): a restart would lose what changed since")
            return False
        if self._unsaved.pop(what, None) is not None:
            print(f"{self.name}: its {what} is saved again", file=sys.stderr, flush=True)
        return True

    def state_damaged(self, rover: str, message: str, key: str | None = None,
                      params: dict | None = None, severity: Severity = "critical") -> None:
        """Say in an event (``critical``: damaged; ``warning``: saved with another rover file)
        that saved state could not be used, and what was done (the message names the service:
        "battery state of mapp-1 damaged (...): ...")."""
        print(f"{self.name}: {message}", file=sys.stderr, flush=True)
        self.event(rover, severity, "state_damaged", key or keys.service(rover, self.name),
                   message, params)

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _begin_claim(self) -> None:
        """Lock the state directory and declare this instance's claims (see :meth:`claim`),
        as soon as the session is open: the claims settle while the runtime learns the time
        (:meth:`__enter__`), so a service starts after one wait of half a second, not two."""
        self._claim_started = time.monotonic()
        if self.store.dir is not None:
            self.store.dir.mkdir(parents=True, exist_ok=True)
            self._lock_file = open(self.store.dir / f"{self.name}.lock", "w")  # noqa: SIM115
            try:
                fcntl.flock(self._lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:  # said by claim(); no claim of ours to mislead another
                self._lock_file.close()
                self._lock_file = None
                self._claim_refused = f"another {self.name} service holds {self.store.dir}"
                return
        liveliness = self.zenoh_session.liveliness()
        self._claim_tokens = [liveliness.declare_token(keys.service_claim(rover, self.name, self._zid))
                              for rover in sorted(self.rovers)]

    def claim(self, wait_s: float = 3.0) -> None:
        """Refuse to run beside another instance of this service for the same rovers.

        Two instances would each tick, step and write the same keys and state files (the
        clock ticking twice as fast, the battery drained twice). The state directory is
        locked, and the rovers are claimed on the router:

        - a live token ``lunaris/<rover>/service/<name>`` (an instance serving) or
          ``.../service/<name>/owner/<zid>`` (an instance that has won its claim and is
          setting up) means another instance has the rover: :class:`AlreadyRunning`
          (``lunaris run`` exits with status 3). One still up after ``wait_s`` is a live
          instance, not the last one going away (a restart right after a crash: the router
          drops a dead session's tokens at once);
        - else each instance has declared ``.../service/<name>/claim/<zid>`` (when its
          session opened: :meth:`_begin_claim`), looks ``CLAIM_SETTLE_S`` after that or
          later, and gives way to a claim of a smaller Zenoh id. Of two instances started at
          once, either each sees the other's claim (and both pick the same one), or the later
          one's claim came after the earlier one looked: the earlier one has won and owns the
          rover by the time the later one looks.
        """
        if self._claim_refused:
            raise AlreadyRunning(self._claim_refused)
        liveliness = self.zenoh_session.liveliness()
        me = self._zid
        try:
            start = time.monotonic()
            while True:
                owners, rivals = self._claims(me)
                now = time.monotonic()
                if owners:
                    if now - start >= wait_s:
                        raise AlreadyRunning(f"another {self.name} service already serves "
                                             f"{', '.join(owners)} (its liveliness token is up)")
                elif now - self._claim_started >= CLAIM_SETTLE_S:
                    first = {rover: zid for rover, zid in rivals.items() if zid < me}
                    if first:
                        raise AlreadyRunning(
                            f"another {self.name} service started at the same time for "
                            f"{', '.join(sorted(first))} and goes first (session "
                            f"{min(first.values())}; this one is {me})")
                    break
                time.sleep(0.1)
            # Won: the owner tokens are up before the claims go (a rival looking in between
            # would see neither, and win too), held until the service tokens are up (run),
            # which say the same from then on.
            self._owner_tokens = [liveliness.declare_token(keys.service_owner(rover, self.name, me))
                                  for rover in sorted(self.rovers)]
        finally:
            for token in self._claim_tokens:
                token.undeclare()
            self._claim_tokens = []

    def _claims(self, me: str) -> tuple[list[str], dict[str, str]]:
        """(the rovers another instance owns or serves, {rover: the smallest rival claim})."""
        owners: set[str] = set()
        rivals: dict[str, str] = {}
        for pattern in (keys.service("*", self.name), keys.service_claims("*", self.name)):
            for reply in self.zenoh_session.liveliness().get(pattern, timeout=2.0):
                if reply.ok is None:
                    continue
                rover, parts = keys.split(str(reply.ok.key_expr))
                if rover not in self.rovers:
                    continue
                if len(parts) == 2:  # service/<name>: an instance serving
                    owners.add(rover)
                elif len(parts) == 4 and parts[3] != me:
                    if parts[2] == "owner":
                        owners.add(rover)
                    elif parts[2] == "claim":
                        rivals[rover] = min(parts[3], rivals.get(rover, parts[3]))
        return sorted(owners), rivals

    def watch_parent(self, pid: int) -> None:
        """Stop when the supervisor that started this service is gone (it was killed): the
        service must not live on as an orphan beside the next supervisor's."""
        def check() -> None:
            if os.getppid() != pid:
                print(f"{self.name}: supervisor {pid} is gone; stopping", file=sys.stderr, flush=True)
                self.stop()
        self.every(0.5, check)

    @property
    def has_faults(self) -> bool:
        """Whether this service owns the faults of some component."""
        return self._faults is not None

    def own_state(self, get: StateGet, set_: StateSet, reset: StateReset, *,
                  after: Callable[[str], None] | None = None,
                  persist_every_s: float | None = 1.0, check: StateCheck | None = None,
                  damaged: StateDamaged | None = None, files: dict[str, str] | None = None) -> None:
        """Hand the service's state to the session keeper (:mod:`common.session`): kept on
        disk, reset by ``control/reset``, saved and restored by snapshots. ``after(rover)``
        republishes once the state has changed by a control. The persisted state is read back
        at once (call this before the first publish), checked against the shape of the
        state the service has now and by ``check(rover, state)`` (ranges: raise ValueError);
        a damaged one is said aloud and the rover reset (``damaged(rover)``, which returns
        what it did in words, instead of ``reset``). ``files``: each rover file's fingerprint
        (:func:`common.config.fingerprint`): a state saved with another is not resumed."""
        self._session_keeper = SessionKeeper(self, get, set_, reset, after, persist_every_s,
                                             check=check, damaged=damaged, files=files)

    @property
    def keeper(self) -> SessionKeeper:
        """The session keeper of :meth:`own_state`."""
        if self._session_keeper is None:
            raise RuntimeError(f"{self.name}: own_state() first")
        return self._session_keeper

    @property
    def faults(self) -> FaultBook:
        """The book of the faults of the components this service owns (made on first use)."""
        if self._faults is None:
            self._faults = FaultBook(self)
        return self._faults

    def on_tick(self, fn: TickHandler) -> None:
        """Call ``fn(rover, tick)`` for every clock tick, after :attr:`t_s` has moved to it."""
        self._tick_handlers.append(fn)

    def _begins_epoch(self, s: Sample) -> bool:
        """Whether a tick, as it arrives, is the first heard of a new epoch or session of its
        rover (Zenoh's thread: :attr:`_heard_epoch` is this method's alone)."""
        try:
            tick = decode(s.payload, Clock)
        except (msgspec.DecodeError, msgspec.ValidationError):
            return False  # said by _on_clock, in its turn
        heard = (tick.epoch, tick.session)
        before = self._heard_epoch.get(s.rover)
        self._heard_epoch[s.rover] = heard
        return before is not None and before != heard

    def _on_clock(self, s: Sample) -> None:
        tick = decode(s.payload, Clock)
        rover = s.rover
        heard = (tick.epoch, tick.seq, tick.t_s)
        if self._last_tick.get(rover) == heard:
            return  # the same tick again: an epoch's first comes ahead of the telemetry too
        self._last_tick[rover] = heard
        if not self._makes_time and (tick.epoch, tick.t_s) < (self.epoch[rover], self.t_s[rover]):
            self._clock_behind(rover, tick)  # a late tick of an older epoch, or a clock that
            return                           # lost its time: never back in time
        self._behind.discard(rover)
        if self._session_keeper is not None and not self._session_keeper.follow(rover, tick):
            return  # a tick from before a reset or restore
        resumed = rover in self._waiting
        self._waiting.discard(rover)
        self.epoch[rover], self.t_s[rover] = tick.epoch, tick.t_s
        if tick.session:  # (the keeper, at a new epoch, has taken it already)
            self.enter_session(rover, tick.session)
        if resumed and self._faults is not None:
            self._faults.publish(rover)  # held back until now: the record with a current time
        for fn in self._tick_handlers:
            fn(rover, tick)

    def enter_session(self, rover: str, session: str) -> None:
        """From now on the events of ``rover`` are ``session``'s (see :meth:`event` for what
        ends with the previous one). A session ended never runs again: a tick of it still in
        flight (a service that heard of the next session first) changes nothing."""
        previous = self.session_id.get(rover, "")
        if not session or session == previous:
            return  # (every tick)
        left = self._sessions_left.setdefault(rover, [])
        if session in left:
            return
        if previous:
            self._session_ended[rover] = (previous, time.monotonic())
            left.append(previous)
            del left[:-8]
        self.session_id[rover] = session

    def _session_of(self, rover: str, kind: str, key: str) -> str:
        """The session an event of ``rover`` belongs to: the running one, but for a fault
        cleared or an alarm resolved just after a new session began that was injected or
        raised in the one that ended (:data:`SESSION_GRACE_S`)."""
        current = self.session_id.get(rover, "")
        if kind in _OPENS:
            if len(self._opened_in) >= OPENED_KEPT:
                del self._opened_in[next(iter(self._opened_in))]
            self._opened_in[(rover, key)] = current
        elif kind in _CLOSES:
            opened = self._opened_in.pop((rover, key), None)
            ended = self._session_ended.get(rover)
            if opened and ended is not None and opened == ended[0] != current \
                    and time.monotonic() - ended[1] < SESSION_GRACE_S:
                return opened
        return current

    def _clock_behind(self, rover: str, tick: Clock) -> None:
        if tick.epoch < self.epoch[rover] or rover in self._behind:
            return  # a tick from before a reset or restore, late: nothing to say
        self._behind.add(rover)
        self.event(rover, "warning", "clock", keys.clock(rover),
                   f"{self.name}: the clock of {rover} is behind the time this service has "
                   f"reached (t={tick.t_s:.1f} s < {self.t_s[rover]:.1f} s in epoch "
                   f"{tick.epoch}): its ticks are ignored until it catches up")

    def stop(self) -> None:
        self.worker.stop()

    def _on_signal(self, *_: object) -> None:
        self.worker.signalled = True

    def on_exit(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on the worker thread when the service stops (persist state)."""
        self._exit_hooks.append(fn)

    def run(self) -> None:
        """Serve until SIGINT or SIGTERM: handle queued samples and timers on this thread."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            # Only a plain flag: the handler runs on this thread, which may hold the queue's lock
            # or, in a handler interrupted by a second signal, the stop Event's lock (either
            # would deadlock: a faults service hung so after kill -9 of up); the loop sees the
            # flag within a timer's wait.
            signal.signal(sig, self._on_signal)
        # The tokens go up once every handler is declared: live means listening.
        for rover in sorted(self.rovers):
            self._keep.append(self.zenoh_session.liveliness().declare_token(keys.service(rover, self.name)))
        for token in self._owner_tokens:  # after the service tokens (in order at the router)
            token.undeclare()
        self._owner_tokens.clear()
        if self.worker.channels:
            print(f"{self.name}: {len(self.rovers)} rovers: {self.worker.channels} telemetry "
                  f"subscriptions drained every {POLL_S * 1000:g} ms", file=sys.stderr, flush=True)
        # What the service has set up lives as long as it does: out of the collector's way
        # (now, and again once the publishers declared with their first samples exist).
        gc.freeze()
        for delay_s in FREEZE_AGAIN_S:
            self.worker.once(delay_s, gc.freeze)
        try:
            self.worker.run()
        finally:
            for hook in self._exit_hooks:
                self._guard(hook)

    def close(self) -> None:
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None
        self._keep.clear()
        self._claim_tokens.clear()
        self._owner_tokens.clear()
        self._heard.clear()
        self._publishers.clear()
        if self.session is not None:
            self.session.close()
            self.session = None

    @property
    def zenoh_session(self) -> zenoh.Session:
        """The open session (:attr:`session` narrowed); RuntimeError outside the ``with`` block."""
        if self.session is None:
            raise RuntimeError(f"{self.name}: the runtime is not open (use it as a context manager)")
        return self.session

    def _guard(self, fn: Callable, *args: Any) -> None:
        """Run a handler; input errors become rejection events, bugs are reported, never fatal.
        The events published meanwhile carry the actor of the sample handled (a write's)."""
        acting = self._acting
        self._acting = self.actor(args[0]) if args and isinstance(args[0], Sample) else None
        try:
            self._run(fn, *args)
        finally:
            self._acting = acting

    def _run(self, fn: Callable, *args: Any) -> None:
        try:
            fn(*args)
        except BadInput as exc:
            sample = args[0] if args and isinstance(args[0], Sample) else None
            if sample is not None:
                self.reject(sample.rover, sample.key, str(exc))
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            # A payload that is not what its key carries (a foreign or forged publisher): bad
            # input like any other, not a bug of this service.
            sample = args[0] if args and isinstance(args[0], Sample) else None
            if sample is None:
                raise
            self.reject(sample.rover, sample.key, f"not a valid payload for this key: {humane(str(exc))}")
        except Exception as exc:  # a bug must not take a training session down
            traceback.print_exc(file=sys.stderr)
            sample = args[0] if args and isinstance(args[0], Sample) else None
            rover = sample.rover if sample else next(iter(sorted(self.rovers)), "unknown")
            self.event(rover, "critical", "internal_error", sample.key if sample else "",
                       f"{self.name}: {type(exc).__name__}: {exc}")

    # -- scheduling -------------------------------------------------------------------------

    def after_batch(self, fn: Callable[[], None], linger_s: float = 0.0) -> None:
        """Call ``fn`` on the worker thread after each batch (see :mod:`common.worker`)."""
        self.worker.after_batch(fn, linger_s)

    def every(self, period_s: float, fn: Callable[[], None]) -> None:
        """Call ``fn`` on the worker thread every ``period_s`` of wall time. A timer that
        falls behind skips ahead instead of firing a burst of late calls."""
        self.worker.every(period_s, fn)

    def call_soon(self, fn: Callable, *args: Any) -> None:
        self.worker.call_soon(fn, *args)

    def urgent_first(self) -> None:
        """Handle the faults waiting, now: for a hook or timer that works through a fleet,
        between one part and the next (see :meth:`common.worker.Worker.urgent_first`)."""
        self.worker.urgent_first()

    # -- Zenoh ------------------------------------------------------------------------------

    def keep(self, entity: Any) -> None:
        """Hold a declared Zenoh entity for the life of the service."""
        self._keep.append(entity)

    def record_own_events(self, record: Callable[[str, Event], Event]) -> None:
        """Hand each event of a served rover to ``record(rover, event)`` before it is
        published: the faults service journals its own events so (heard back from Zenoh a
        moment later, a kill in that moment lost one, with no gap to show for it). What it
        returns is published (the same event, or one saying it could not be recorded)."""
        self._own_events = record

    def on_wildcard(self, handler: Handler) -> None:
        """Hand ``handler`` each sample whose key holds a wildcard (``*``, ``**``, ``$*``),
        once, however many of this service's subscriptions it reaches: the gatekeeper's, which
        refuses it in words. Every other handler of every service never sees such a sample
        (:meth:`subscribe`). The sample's ``rover`` is the key's rover chunk as written."""
        self._on_wildcard = handler

    def _wildcard(self, s: zenoh.Sample, key: str, index: int) -> None:
        """A sample whose key names more than one key: dropped, or handed to the gatekeeper by
        the first of this service's subscriptions that hears it (Zenoh gives it to each)."""
        if self._on_wildcard is None:
            return
        expr = zenoh.KeyExpr(key)
        first = next(i for i, sub in enumerate(self._subscribed) if sub.intersects(expr))
        if first != index:
            return
        chunks = key.split("/")
        sample = Sample(key, chunks[1] if len(chunks) > 1 else "", chunks[2:], s.payload.to_bytes(),
                        s.kind == zenoh.SampleKind.DELETE,
                        s.attachment.to_bytes() if s.attachment is not None else None)
        self.worker.put(self._on_wildcard, sample)

    def subscribe(self, keyexpr: str, handler: Handler, *, any_rover: bool = False,
                  history: bool = False, telemetry: bool = False, urgent: bool = False,
                  writes: WriteRole = "own",
                  urgent_if: Callable[[Sample], bool] | None = None) -> None:
        """Queue every sample on ``keyexpr`` for ``handler``; samples for rovers this service
        does not serve are dropped unless ``any_rover``. With ``history`` the publishers'
        caches are replayed first (an advanced subscriber), for a service that joins late.
        ``telemetry``: a tick-rate stream, drained from a channel when the service serves a
        fleet (:attr:`polled`). ``urgent``: handled ahead of everything waiting, the worker
        breaking off a burst of telemetry for it (a fault: what the crew is trained on).

        A sample whose key holds a wildcard (a put on ``lunaris/**``) is never input: it is
        dropped here, or handed once to the gatekeeper (:meth:`on_wildcard`).

        ``writes``: what this subscription is to the writes it hears (faults, inputs,
        commands, controls) that :meth:`refusal` refuses (sent more than
        ``WRITE_MAX_AGE_S`` before they arrived, or naming an unknown actor): their owner
        (``own``: refused with a rejection event, the handler not called), a follower of a
        write another service answers (``follow``: dropped without a word; so is a session
        control, which the faults service answers), or the gatekeeper (``gate``: the handler
        decides, with :meth:`refusal`).

        ``urgent_if(sample)``: urgent when it says so (on Zenoh's thread, as the sample
        arrives; a fleet's stream, drained from a channel, in its turn)."""
        if writes != "gate":
            handler = self._writes_checked(handler, answer=writes == "own")
        session = self.zenoh_session
        split_keys: dict[str, tuple[str, list[str]]] = {}  # the served rovers' keys, split
        polled = telemetry and self.polled
        index = len(self._subscribed)
        self._subscribed.append(zenoh.KeyExpr(keyexpr))

        def convert(s: zenoh.Sample) -> Sample | None:
            key = str(s.key_expr)
            known = split_keys.get(key)
            if known is not None:
                rover, parts = known
            elif keys.has_wildcard(key):
                self._wildcard(s, key, index)
                return None
            else:
                try:
                    rover, parts = keys.split(key)
                except ValueError:
                    return None
                # a served rover's keys, as many as a rover has: forged names cannot grow it
                if rover in self.rovers and len(split_keys) < 100 * len(self.rovers):
                    split_keys[key] = rover, parts
                    if polled:
                        self._declare_heard(key)
                elif not any_rover:
                    return None
            att = s.attachment.to_bytes() if s.attachment is not None else None
            sent_at, age_s = None, 0.0
            if keys.is_write(parts) and s.timestamp is not None:  # judged as it arrives
                sent_at = s.timestamp.get_time().timestamp()
                age_s = time.time() - sent_at
            return Sample(key, rover, parts, s.payload.to_bytes(),
                          s.kind == zenoh.SampleKind.DELETE, att, sent_at, age_s)

        def on_sample(s: zenoh.Sample) -> None:
            sample = convert(s)
            if sample is not None:
                self.worker.put(handler, sample, urgent=urgent or (
                    urgent_if is not None and urgent_if(sample)))

        how: Any = zenoh.handlers.FifoChannel(CHANNEL_CAPACITY) if polled else on_sample
        sub: Any
        if history:
            sub = zext.declare_advanced_subscriber(
                session, keyexpr, how,
                history=zext.HistoryConfig(detect_late_publishers=True),
                subscriber_detection=True)
        else:
            sub = session.declare_subscriber(keyexpr, how)
        self._keep.append(sub)
        if polled:
            self.worker.add_channel(sub, convert, handler)

    def _writes_checked(self, handler: Handler, answer: bool) -> Handler:
        def checked(sample: Sample) -> None:
            if keys.is_write(sample.parts):
                refusal = self.refusal(sample)
                if refusal is not None:
                    # a session control is answered by the faults service alone (common.session)
                    if answer and sample.parts[0] != "control":
                        raise BadInput(refusal)
                    return
            handler(sample)
        return checked

    def refusal(self, sample: Sample) -> str | None:
        """Why a write is refused before anything looks at it, in words; None if it is not:
        it arrived more than ``WRITE_MAX_AGE_S`` after it was sent (held back by a cut link:
        applied now it would be applied late), or its attachment names an unknown actor."""
        if sample.age_s > WRITE_MAX_AGE_S and sample.sent_at is not None:
            sent = time.strftime("%H:%M:%S", time.localtime(sample.sent_at))
            return (f"not applied: sent at {sent}, arrived {sample.age_s:.1f} s late (the link "
                    f"to the twin was cut; a write older than {WRITE_MAX_AGE_S:g} s is never "
                    "applied); nothing changed, send it again")
        actor = actor_of(sample.attachment)
        if actor is not None and actor not in ACTORS:
            return f"actor={shown(actor)} names no actor: a write is by {', '.join(ACTORS)}"
        return None

    def actor(self, sample: Sample) -> str:
        """Who sent a sample: the write's ``actor`` attachment, an instructor when it has none;
        the twin itself for what is not a write (telemetry, ticks)."""
        actor = actor_of(sample.attachment)
        if actor in ACTORS:
            return actor
        return "instructor" if keys.is_write(sample.parts) or keys.has_wildcard(sample.key) else "twin"

    def _declare_heard(self, key: str) -> None:
        """Declare a key this service receives a stream on. Zenoh resolves a sample's key
        against the key expressions the session has declared: for a key it does not know
        that costs time in proportion to their number (the ~1,000 publishers of a fleet's
        service: ~15 us a sample on the receive thread), for a declared one it is looked up.
        Measured with 12,000 samples/s: 14-18 % of a core on the receive thread without,
        1.5-2.5 % with. On the worker thread, as the channels are drained."""
        if key not in self._heard:
            self._heard[key] = self.zenoh_session.declare_keyexpr(key)

    def queryable(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> None:
        """Answer queries on the worker thread (the model state is only read there)."""
        self._keep.append(
            self.zenoh_session.declare_queryable(keyexpr, lambda q: self.worker.call_soon(handler, q))
        )

    def publish(self, key: str, msg: msgspec.Struct, *, reliable: bool = False,
                cache: int = 1) -> None:
        """Publish a payload on an advanced publisher that caches the last sample (``cache``:
        the last so many). Telemetry may drop a sample under congestion (the next one replaces
        it); ``reliable`` blocks instead, for what must never be lost (events, the faults in
        effect)."""
        self.publish_bytes(key, encode(msg), zenoh.Encoding.APPLICATION_JSON, reliable=reliable,
                           cache=cache)

    def publish_ahead(self, key: str, msg: msgspec.Struct) -> None:
        """Put a sample at the writes' priority (``PRIORITY``), never dropped: it goes ahead of
        the telemetry queued on the links, and nothing written after it at that priority
        overtakes it. (A put of the session: the key's publisher sends it again, cached.)"""
        self.zenoh_session.put(key, encode(msg), encoding=zenoh.Encoding.APPLICATION_JSON,
                               congestion_control=zenoh.CongestionControl.BLOCK, priority=PRIORITY)

    def publish_bytes(self, key: str, payload: bytes, encoding: zenoh.Encoding,
                      attachment: bytes | None = None, *, reliable: bool = False,
                      heartbeat_s: float | None = None, cache: int = 1) -> None:
        """Publish an already encoded payload (CDR for the bridge), with the same last-value
        cache as :meth:`publish` (``cache``: the last so many samples). ``heartbeat_s``: the
        publisher (declared on first use) also sends a sporadic heartbeat, so an advanced
        subscriber that missed the last sample fetches it from the cache (what rmw_zenoh's
        transient-local publishers do)."""
        if self._waiting and self._waits(key):
            return  # stamped with a time from the disk: the first tick republishes
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._declare_publisher(key, cache, encoding, reliable, heartbeat_s)
        pub.put(payload, attachment=attachment)

    def _waits(self, key: str) -> bool:
        """Whether a sample on ``key`` waits for its rover's first tick (see :attr:`_waiting`):
        everything but events, which say what happens now (a damaged state found)."""
        try:
            rover, parts = keys.split(key)
        except ValueError:
            return False
        return rover in self._waiting and parts[:1] != ["event"]

    def _declare_publisher(self, key: str, cache: int,
                           encoding: zenoh.Encoding = zenoh.Encoding.APPLICATION_JSON,
                           reliable: bool = False, heartbeat_s: float | None = None) -> Any:
        pub = zext.declare_advanced_publisher(
            self.zenoh_session, key,
            encoding=encoding,
            congestion_control=(zenoh.CongestionControl.BLOCK if reliable
                                else zenoh.CongestionControl.DROP),
            # what must never be lost must not wait behind a fleet's telemetry either
            priority=PRIORITY if reliable else zenoh.Priority.DATA,
            cache=zext.CacheConfig(max_samples=cache),
            sample_miss_detection=(None if heartbeat_s is None
                                   else zext.MissDetectionConfig(heartbeat=None,
                                                                sporadic_heartbeat=heartbeat_s)),
            publisher_detection=True,
        )
        self._publishers[key] = pub
        return pub

    # -- events and rejection ---------------------------------------------------------------

    def event(self, rover: str, severity: Severity, kind: EventKind, key: str, message: str,
              params: dict | None = None, *, actor: str | None = None, t_s: float | None = None,
              session: str | None = None) -> None:
        """Publish an event of a rover on this service's own key,
        ``lunaris/<rover>/event/<service>`` (the faults service journals it and relays it on
        ``lunaris/<rover>/event``). Events are never dropped under congestion (the journal is
        complete). ``t_s``: the sim time of what it tells when that was before now (a command
        answered a tick after it was applied); by default the rover's time now. ``actor``: by
        default the actor of the write being handled, ``twin`` for the twin's own
        (:data:`TWIN_KINDS`, or no write). ``session``: the trainee session
        the service is in (:attr:`session_id`), or the one given (an armed fault ended with its
        session is journalled in it). ``(source_id, seq)`` names the event
        among the rover's. A rover this service does not serve (a rejection of a key naming
        an unknown rover) gets a plain put: no publisher, cache or token is left behind per id."""
        if self._held is not None:  # (events_after)
            self._held.append(((rover, severity, kind, key, message, params),
                               {"actor": actor, "t_s": t_s, "session": session}))
            return
        if keys.has_wildcard(rover) or "/" in rover or not rover:  # never a key naming many
            print(f"{self.name}: no event for rover {rover!r}: {message}", file=sys.stderr, flush=True)
            return
        if actor is None:
            actor = "twin" if kind in TWIN_KINDS else (self._acting or "twin")
        served = rover in self.rovers
        slot = rover if served else ""
        seq = self._event_seq[slot] = self._event_seq.get(slot, 0) + 1
        ekey = keys.event_of(rover, self.name)
        now = self.t_s.get(rover, 0.0)
        ev = Event(t_s=now if t_s is None or t_s > now else t_s, severity=severity, source=self.name,
                   kind=kind,
                   key=key, message=message, params=params, source_id=self._zid, seq=seq,
                   actor=actor, session=(session or self._session_of(rover, kind, key))
                   if served else "")
        if not served:
            self.zenoh_session.put(ekey, encode(ev), encoding=zenoh.Encoding.APPLICATION_JSON,
                                   congestion_control=zenoh.CongestionControl.BLOCK,
                                   priority=PRIORITY)
            return
        if self._own_events is not None:
            ev = self._own_events(rover, ev)
        if ekey not in self._publishers:
            self._declare_publisher(ekey, max(EVENT_CACHE, EVENT_HISTORY // len(self.rovers)),
                                    reliable=True)
        self.publish(ekey, ev)

    @contextlib.contextmanager
    def events_after(self) -> Iterator[list[tuple[tuple, dict]]]:
        """Hold the events of this service published in the block: they go out at its end,
        after those the block puts in the list it is given (``(args, kwargs)`` of
        :meth:`event`). The fault book's injection goes out before the alarms its effect
        raised: the journal says the cause first (it said the load's over-current, raised
        and resolved, before the short that caused it)."""
        held, self._held = self._held, []
        first: list[tuple[tuple, dict]] = []
        try:
            yield first
        finally:
            mine, self._held = self._held, held
            for args, kwargs in first + mine:
                self.event(*args, **kwargs)

    def reject(self, rover: str, key: str, reason: str, actor: str | None = None) -> None:
        """Refuse an input: nothing changes, and a warning event says why (``actor``: whose,
        by default the write's being handled: the bridge says the crew's)."""
        self.event(rover, "warning", "rejected", key, f"rejected: {reason}", actor=actor)

    def accepted_input(self, rover: str, key: str, message: str, params: dict | None = None) -> None:
        """Journal an accepted input as an ``input`` event; a ramp's stream of them is folded
        (:class:`~common.input_events.InputLog`): one event a second at most per key."""
        if self._inputs is None:
            self._inputs = InputLog()
            self.every(0.2, lambda: self._input_events(self._inputs.flush(time.monotonic())
                                                       if self._inputs else []))
        note = InputNote(rover, key, message, params, self._acting or "")
        self._input_events(self._inputs.offer(note, time.monotonic()))

    def _input_events(self, notes: list[InputNote]) -> None:
        for note in notes:
            self.event(note.rover, "info", "input", note.key, note.message, note.params,
                       actor=note.actor or None)
