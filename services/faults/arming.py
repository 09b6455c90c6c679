"""The faults service's armed faults (SPEC 13b): the Zenoh side of :mod:`services.faults.armed`.

- **Arming** (``put lunaris/<rover>/faults/armed/<component>/<kind>``, an
  :class:`~common.messages.ArmFault`): checked as the tools check it
  (:func:`common.armed.parse_arm`) and against the rover's names; a bad one is a ``rejected``
  event, as every bad write. A good one is saved, then answered with ``fault_armed``. A
  ``delete`` cancels it (``fault_cancelled``, by its actor).
- **Each tick**: the faults armed in an epoch or a session the ticks have left (a reset, a
  restore, a new trainee's session) are cancelled, each said with its reason and journalled
  in the session it was armed in; then the warnings and firings due are given
  (``fault_warned``, ``fault_fired``). Fired, the fault is put on ``fault/<component>/<kind>``
  with the arming actor's attachment, exactly as that actor's injection would be, after its
  ``fault_fired`` event: every owner applies it as usual and answers with ``fault_injected``.
- **Conditions** read the latest telemetry of the keys they name, and only those: a
  subscription per key while a condition waits for it (the publishers' caches replayed, so
  the current value comes at once), a payload kept as it came, decoded at the tick.
- **Kept across restarts** in the runtime's state store (``faults-armed.json``), written
  durably before an arming or a cancellation is answered; a damaged file is said in a
  ``critical`` event and set aside. ``get lunaris/<rover>/faults/armed`` lists them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.armed import parse_arm
from common.config import Rover
from common.connection import ACTORS
from common.connection import write as put_or_delete
from common.messages import ArmFault, BadInput, Clock, EventKind, Severity
from common.runtime import Runtime, Sample
from common.state_store import Damaged
from services.faults.armed import Armed, ArmedBook, arm

__all__ = ["Arms", "RoverArms"]


@dataclass
class RoverArms:
    """One rover's armed faults, and what their conditions read."""

    book: ArmedBook = field(default_factory=ArmedBook)
    ticked: tuple[int, str] | None = None  # the (epoch, session) of the latest tick
    # the latest payload of each key a condition reads (written on Zenoh's thread), and the
    # subscriptions that keep it
    latest: dict[tuple[str, ...], bytes] = field(default_factory=dict)
    watching: dict[tuple[str, ...], Any] = field(default_factory=dict)

    def lookup(self, parts: tuple[str, ...]) -> dict | None:
        raw = self.latest.get(tuple(parts))
        if raw is None:
            return None
        try:
            value = msgspec.json.decode(raw)
        except msgspec.DecodeError:
            return None
        return value if isinstance(value, dict) else None


class Arms:
    """The armed faults of every rover the faults service serves (on its worker thread)."""

    def __init__(self, rt: Runtime, configs: dict[str, Rover]):
        self.rt, self.configs = rt, configs
        self.rovers = {rover: RoverArms() for rover in configs}

    def on_arm(self, rover: str, msg: ArmFault | None, s: Sample) -> None:
        """A put arms a fault, a delete cancels it (see the module)."""
        rt, st = self.rt, self.rovers[rover]
        if msg is None:
            gone = st.book.cancel(s.key)
            if gone is None:
                raise BadInput(f"no fault is armed on {s.key}: nothing to cancel")
            self.save()
            self.rewatch(rover)
            self.event(rover, "fault_cancelled", gone, f"cancelled by the {rt.actor(s)}",
                       reason="cancelled")
            return
        arming = parse_arm(s.parts[2:], s.payload, self.configs[rover])
        if st.ticked is None:
            raise BadInput(f"the clock of {rover} has not ticked yet: a fault is armed on the "
                           "rover's sim time; try again once it runs")
        actor = rt.actor(s)
        armed = arm(s.key, arming, rt.t_s[rover], actor if actor in ACTORS else "instructor",
                    *st.ticked)
        replaced = st.book.arm(armed)
        self.save()
        self.rewatch(rover)
        self.event(rover, "fault_armed", armed,
                   f"armed {_fault_words(armed)} {armed.trigger()}, warning {armed.warn_s:g} s "
                   "before" + (" (replaces the one armed there)" if replaced else ""))

    def on_tick(self, rover: str, tick: Clock) -> None:
        """The faults armed in an epoch or session the twin has left are cancelled, then the
        warnings and firings due are given, in order."""
        st = self.rovers[rover]
        st.ticked = (tick.epoch, tick.session)
        if not st.book:
            return
        ended = st.book.outside(tick.epoch, tick.session)
        for a in ended:
            why = _ended_why(a, tick)
            self.event(rover, "fault_cancelled", a, f"cancelled: {why}", actor="twin",
                       reason=why, session=a.session)
        steps = st.book.tick(tick.t_s, st.lookup)
        for what, a in steps:
            if what == "warn":
                cond = a.condition()
                held = f": {a.when} holds ({cond.describe(st.lookup)})" if cond else ""
                self.event(rover, "fault_warned", a, f"warning: {_fault_words(a)} fires in "
                           f"{a.warn_s:g} s, at t={a.due_t_s:.1f} s{held}", severity="warning",
                           actor=a.actor)
            else:
                # journalled before the put: the journal says it fired before its injection
                self.event(rover, "fault_fired", a, f"fired: {_fault_words(a)}", actor=a.actor)
                put_or_delete(self.rt.zenoh_session, keys.under(rover, f"fault/{a.fault}"),
                              a.payload.encode(), actor=a.actor)
        if ended or steps:
            self.save()
            self.rewatch(rover)

    def event(self, rover: str, kind: EventKind, a: Armed, message: str, *,
              severity: Severity = "info", actor: str | None = None, reason: str | None = None,
              session: str | None = None) -> None:
        """An armed fault's event (``key``: its armed key), its request and times in
        ``params``; ``actor``: by default the write's being handled (arming, cancelling);
        ``session``: by default the running one."""
        params = {"fault": a.fault, "value": a.value, "at_t_s": a.at_t_s, "in_s": a.in_s,
                  "when": a.when, "warn_s": a.warn_s, "armed_t_s": a.armed_t_s,
                  "due_t_s": a.due_t_s, "warned_t_s": a.warned_t_s, "armed_by": a.actor}
        if reason is not None:
            params["reason"] = reason
        self.rt.event(rover, severity, kind, a.key, message, params, actor=actor, session=session)

    def rewatch(self, rover: str) -> None:
        """Subscribe to the telemetry the conditions still waiting read, and to nothing else."""
        st = self.rovers[rover]
        wanted = st.book.watched()
        for parts in set(st.watching) - wanted:
            st.watching.pop(parts).undeclare()
            st.latest.pop(parts, None)
        for parts in wanted - set(st.watching):
            st.watching[parts] = zext.declare_advanced_subscriber(
                self.rt.zenoh_session, keys.under(rover, "/".join(parts)),
                partial(_keep_latest, st.latest, parts),
                history=zext.HistoryConfig(detect_late_publishers=True))

    def save(self) -> None:
        """Every rover's armed faults on disk, durably: answered once it survives a restart."""
        self.rt.save_state("armed", {r: st.book.saved() for r, st in sorted(self.rovers.items())})

    def load(self) -> None:
        """The armed faults saved before a restart, each rover's checked; a damaged record is
        said and set aside (the faults it held are not armed)."""
        rt = self.rt
        try:
            saved = rt.store.load("armed")
        except Damaged as exc:
            for rover in sorted(self.rovers):
                rt.state_damaged(rover, f"faults armed faults of {rover} damaged ({exc.reason}): "
                                 f"none is armed; {exc.where()}", keys.faults_armed(rover))
            return
        if not isinstance(saved, dict):
            return
        bad = False
        for rover, st in sorted(self.rovers.items()):
            try:
                st.book.restore(saved.get(rover, []))
            except ValueError as exc:
                bad = True
                rt.state_damaged(rover, f"faults armed faults of {rover} damaged ({exc}): none "
                                 "is armed", keys.faults_armed(rover))
            self.rewatch(rover)
        if bad:
            rt.store.set_aside("armed")

    def on_query(self, q: zenoh.Query) -> None:
        """``get lunaris/<rover>/faults/armed``: the list of each rover the query names."""
        with q:
            for rover, st in sorted(self.rovers.items()):
                key = keys.faults_armed(rover)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    q.reply(key, msgspec.json.encode(st.book.listed()),
                            encoding=zenoh.Encoding.APPLICATION_JSON)


def _fault_words(a: Armed) -> str:
    """``load/nav_camera short {"resistance_ohm":0.05}``: the fault as an instructor types it."""
    component, _, kind = a.fault.rpartition("/")
    value = "" if a.value is None else " " + msgspec.json.encode(a.value).decode()
    return f"{component} {kind}{value}"


def _ended_why(a: Armed, tick: Clock) -> str:
    """Why a fault armed in ``a``'s epoch and session ends at ``tick``, in words."""
    if tick.session != a.session:
        return f"its session ended (session {tick.session} began)"
    if tick.cause.startswith("restore:"):
        return f"the twin was restored to snapshot {tick.cause.removeprefix('restore:')!r}"
    return "the twin was reset"


def _keep_latest(latest: dict[tuple[str, ...], bytes], parts: tuple[str, ...],
                 s: zenoh.Sample) -> None:
    """On Zenoh's thread: the latest payload of a key a condition reads (a store, no work)."""
    latest[parts] = s.payload.to_bytes()
