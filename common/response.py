"""The crew's response to each fault of a session, measured (SPEC §12d).

Longer than 450 lines on purpose: the faults' lives, the crew's actions, the sessions and the
expectations are read from one stream and depend on one another's state (an action belongs to
the faults in effect in its session, a session's end ends its faults); the results' Structs are
here with them, and what a symptom is per kind lives in :mod:`common.symptoms`.

Pure: no Zenoh, no clock. A :class:`Response` follows one rover: it is fed the rover's samples
in the order they were received - telemetry with :meth:`Response.value`, events with
:meth:`Response.event` (each event once: the caller takes them by ``(source_id, seq)``, as the
client's mirror and the report do) - and tells, at any time, per session
(:meth:`Response.sessions`, :meth:`Response.live`):

- for every fault injected in the session (by hand or by a scenario): when it was injected;
  when the crew could first see a symptom of it; the crew's actions after it, in order; and
  when it was resolved;
- the scenario's expectations, met (when) or missed.

The same object serves a recording (``lunaris report``) and the live twin (the console, from
the client's mirror). Times are the rover's simulated time [s], as the payloads carry it.

**A symptom** is what the crew's own topics show (the bridge's, SPEC §7 and §12b: telemetry and
the twin's own alarms, never the injected fault): the first, after the injection and while the
fault is in effect, of

- a derived alarm raised (``fault_raised``, SPEC §6: over-current, tripped, over-temperature,
  no output ...) on the fault's component or on what it sits on (a load's rail; the loads of a
  failed rail), but for those on no crew topic (:data:`common.symptoms.UNSEEN_ALARMS`: a
  load's own over-current, which still holds its fault unresolved until it clears);
- the affected value leaving the band it kept before the injection, per fault kind
  (:data:`common.symptoms.SYMPTOMS`): the band is the range of the value over the minute
  before, widened by a tolerance and, for smooth values, by the trend it had (a temperature
  already rising must rise faster than it did). A load's power counts only on a live rail (its
  payload's ``on``): an open load shows as 0 W there, also when its rail comes on after the
  injection. A kind whose value does not leave its band (a load stuck at the power it drew
  anyway, a radio degraded while the rover stays in range) has no symptom: ``null``; the
  module :mod:`common.symptoms` says when each kind shows nothing, and why.

**The crew's actions** are the events with ``actor: crew`` (rail commands, the drive stopped,
inputs; accepted, or refused with the twin's reason) from the injection until the fault is
settled: cleared, its alarms cleared and the rails it affected back in their state before it
(a rail the crew switched off to isolate a fault and never switched back keeps the window open
to the session's end), and that act on what the fault touches (SPEC §13a): its component, the
rail it sits on, the rails and loads its symptoms reached (:func:`unit_of` names each). Three
faults at once and the crew switching one load's rail off: that is an action on the short of
the load, none on the dust of a panel or the heating of the pack (found by an instructor: both
listed it, "acted 1 min 42 s after the symptom").

**Resolved** is when the alarms the fault caused had all cleared and the rails it affected
(the load's rail, the failed rail) were back in their state before it - the latest such moment
while the fault is in effect (a rail reset onto a short that trips again is not resolved) - or,
failing that, when the fault was cleared. A fault still in effect at the session's end, or
cleared only by the session's end, is not resolved (``null``).

**Sessions** are the clock's (SPEC §12c, :mod:`services.faults.sessions` places the journal's
lines the same way): an event's ``session`` names its session, a clock tick's ``session`` the
session of the telemetry after it. A session id not seen before that is later than the running
one (ids are the UTC time each began, growing) begins a new session, which ends the running one
(its faults in effect end with it); a late event of an ended session goes to that session and
never makes it run again. An event without a session (a service that had heard no tick yet)
belongs to the running session; what comes before any session id is known belongs to the first
session named. A session's trainee is the one the clock's ``session`` event that opened it
names (``null`` when that event was not heard). A reset or a restore within a session (a new
epoch) begins no session, but the faults in effect end with it (unresolved, as at a session's
end), and nothing before it counts for a fault injected after it (the clock's times start
again): the values' bands, the alarms, the crew's actions. A recording of a twin older
than sessions is one session, named ``""``.

**Expectations** come from the journal (``scenario`` events whose params hold an
``expectation``, :class:`common.messages.ExpectationMark`) and, while they are not yet scored,
from the runner's progress (``scenario/progress``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec

from common.events import session_opened
from common.faults import NAMED_COMPONENTS
from common.symptoms import (
    SMOOTH_POWER,
    SYMPTOMS,
    TOLERANCE,
    UNSEEN_ALARMS,
    Band,
    Direction,
    Series,
    SymptomSpec,
    quantity,
)

__all__ = [
    "CrewAction",
    "Expectation",
    "FaultResponse",
    "LiveFault",
    "LiveResponse",
    "Response",
    "SessionResponse",
]

_TWIN_RAIL_STATES = ("tripped", "shed", "failed")  # a rail state the twin puts it in, not the crew
_BATTERY_CAPACITY = ("battery/state", "capacity_j")
_BATTERY_VOLTAGE = ("battery/state", "voltage_v")
_BATTERY_TEMPERATURE = ("battery/state", "temperature_c")
_BATTERY_OPERATIONAL = ("battery/state", "operational")
_UMBILICAL = ("umbilical/state", "power_w")


# -- results ------------------------------------------------------------------------------------


class CrewAction(msgspec.Struct, omit_defaults=False):
    """One action of the crew (an event with ``actor: crew``)."""

    t_s: float
    action: str  # rail on, rail off, rail reset, rail command (refused), drive stop, traverse, input
    target: str  # the rail's name, drive, or the input's key under the rover
    accepted: bool  # False: refused, and why in reason
    key: str = ""
    message: str = ""  # the twin's answer in words (the refusal's reason)


class FaultResponse(msgspec.Struct, omit_defaults=False):
    """One fault injected in a session and the crew's response to it."""

    key: str  # lunaris/<rover>/fault/<component>/<kind>
    injected_t_s: float
    first_symptom_t_s: float | None
    first_crew_action_t_s: float | None
    resolved_t_s: float | None
    crew_actions: list[CrewAction]
    fault: str = ""  # <component>/<kind>: load/nav_camera/short
    kind: str = ""
    params: dict[str, Any] = {}
    injected_by: str = ""  # instructor, scenario
    symptom: str = ""  # what the crew could see first, in words ("" while none)
    resolved_by: str = ""  # "cleared", or the alarms cleared and the rails back
    cleared_t_s: float | None = None
    active: bool = True  # still in effect (at the session's end, or now)
    response_s: float | None = None  # first crew action - first symptom
    note: str = ""  # what the times cannot say: injected before the recording (or the watching) began


class Expectation(msgspec.Struct, omit_defaults=False):
    """An expectation of a scenario (a step ``expect:``): met (when) or missed."""

    label: str
    met: bool | None  # null: not yet scored (live only)
    at_t_s: float | None  # when it was met (sim time)
    within_s: float
    condition: str = ""
    scenario: str = ""
    step: int = 0  # its step, from 0
    armed_t_s: float | None = None  # when the crew's time began (sim time)
    deadline_t_s: float | None = None  # when it is missed unless met (sim time)
    detail: str = ""


class SessionResponse(msgspec.Struct, omit_defaults=False):
    """The crew's response in one session of one rover (``lunaris report --json``)."""

    session: str
    trainee: str | None
    faults: list[FaultResponse]
    expectations: list[Expectation]
    rover: str = ""
    start_t_s: float | None = None  # the session's first sim time seen (of its own clock ticks)
    end_t_s: float | None = None  # its last
    started_wall: float | None = None  # when it began, UTC epoch seconds (the clock's word of it)


class LiveFault(FaultResponse):
    """A fault as the console shows it live."""

    since_injection_s: float | None = None  # now - injected_t_s, while active
    crew_acted: bool = False


class LiveResponse(msgspec.Struct, omit_defaults=False):
    """The running session's response now (the console's)."""

    rover: str
    session: str
    trainee: str | None
    t_s: float | None  # the rover's sim time now
    faults: list[LiveFault]
    expectations: list[Expectation]
    version: int = 0  # changes whenever the response does


# -- reading payloads: dicts (JSON) or Structs alike ---------------------------------------------


def _get(payload: Any, name: str, default: Any = None) -> Any:
    if isinstance(payload, dict | Mapping):
        return payload.get(name, default)
    return getattr(payload, name, default)


# -- values and their bands ----------------------------------------------------------------------


# -- one fault's life -------------------------------------------------------------------------------


@dataclass
class _Fault:
    key: str
    path: str  # load/nav_camera/short
    component: str
    name: str | None
    kind: str
    params: dict[str, Any]
    actor: str
    injected_t: float
    scopes: tuple[str, ...]  # the derived alarms' keys under lunaris/<rover>/ that count: prefixes
    rails: dict[str, str | None]  # rail -> its state before the fault
    watch: tuple[str, str] | None = None  # (series, field) whose band it watches
    direction: Direction = "any"
    live: str = ""  # nothing: when its value counts, in words (SymptomSpec.live)
    band: Band | None = None
    before: Any = None  # a state's value before the fault (change, lost)
    cleared_t: float | None = None
    ended: bool = False  # cleared by the session's end
    symptom_t: float | None = None
    symptom: str = ""
    caused: set[str] = field(default_factory=set)  # its alarms still raised
    caused_any: bool = False
    resolved_t: float | None = None
    resolved_by: str = ""
    settled_t: float | None = None  # no more actions collected after this
    actions: list[CrewAction] = field(default_factory=list)  # the crew's, while it was open
    touches: set[str] = field(default_factory=set)  # what it touches: "load/cam", "rail/5V", "battery"
    era: int = 0  # its session's epochs before the one it was injected in (_Session.era)

    @property
    def active(self) -> bool:
        return self.cleared_t is None and not self.ended

    def found(self, t: float, words: str) -> bool:
        """A symptom at ``t``; True when it is the first (the earliest)."""
        if self.symptom_t is None or t < self.symptom_t:
            self.symptom_t, self.symptom = t, words
            return True
        return False

    def acted(self) -> list[CrewAction]:
        """The crew's actions on what it touches (SPEC 13a): another fault's rail switched off
        while this one was in effect is no response to this one."""
        return [a for a in self.actions if action_unit(a.key) in self.touches]

    def result(self, cls: type[FaultResponse] = FaultResponse, **extra: Any) -> Any:
        acted = self.acted()
        first = acted[0].t_s if acted else None
        return cls(
            key=self.key, injected_t_s=self.injected_t, first_symptom_t_s=self.symptom_t,
            first_crew_action_t_s=first, resolved_t_s=self.resolved_t,
            crew_actions=acted, fault=self.path, kind=self.kind, params=dict(self.params),
            injected_by=self.actor, symptom=self.symptom, resolved_by=self.resolved_by,
            cleared_t_s=self.cleared_t, active=self.active,
            response_s=None if first is None or self.symptom_t is None else first - self.symptom_t,
            **extra)


@dataclass
class _Session:
    id: str  # the clock's session id; "" until one is known
    trainee: str | None = None  # from the clock's event that opened it
    started_wall: float | None = None  # from the same event
    faults: list[_Fault] = field(default_factory=list)
    active: dict[str, _Fault] = field(default_factory=dict)  # fault key -> the fault in effect
    raised: dict[str, float] = field(default_factory=dict)  # derived alarm key -> raised at
    recent_raises: deque[tuple[float, str, str]] = field(default_factory=lambda: deque(maxlen=64))
    recent_actions: deque[CrewAction] = field(default_factory=lambda: deque(maxlen=64))
    scored: dict[tuple, Expectation] = field(default_factory=dict)  # from the journal
    pending: dict[str, list[tuple[tuple, Expectation]]] = field(default_factory=dict)  # progress
    start_t: float | None = None
    last_t: float | None = None
    ticks: int = 0  # clock samples seen in it: a session only replayed has none
    era: int = 0  # resets and restores within it so far (each a new epoch of the clock)

    def empty(self) -> bool:
        return not (self.faults or self.scored or self.pending)


def _scopes(rover_prefix: str, component: str, name: str | None) -> tuple[str, ...]:
    return (rover_prefix + "/".join(p for p in (component, name) if p) + "/",)


def unit_of(tail: str) -> str:
    """The part of the rover a key under ``lunaris/<rover>/`` is about: ``rail/5V_CH2`` of
    ``rail/5V_CH2/tripped`` or ``cmd/rail/5V_CH2``, ``solar/left`` of ``input/solar/left/dust``,
    ``battery`` of ``battery/no_output``, ``drive`` of ``input/drive/traverse``."""
    parts = tail.split("/")
    if parts[0] in ("cmd", "input", "fault"):
        parts = parts[1:]
    if not parts or not parts[0]:
        return ""
    return "/".join(parts[:2]) if parts[0] in NAMED_COMPONENTS and len(parts) > 1 else parts[0]


def action_unit(key: str) -> str:
    """:func:`unit_of` a crew action's full key (``lunaris/<rover>/cmd/rail/5V``)."""
    chunks = key.split("/", 2)
    return unit_of(chunks[2]) if len(chunks) == 3 else ""


class Response:
    """The crew's response on one rover, every session of it, fed in order (module text)."""

    def __init__(self, rover: str):
        self.rover = rover
        self.prefix = f"lunaris/{rover}/"
        self.version = 0
        self._sessions: list[_Session] = [_Session("")]
        self._by_id: dict[str, _Session] = {}
        self._current = self._sessions[0]
        self._epoch: int | None = None
        self._t: float | None = None
        self._series: dict[tuple[str, str], Series] = {}
        self._states: dict[str, Any] = {}  # rail name -> state; "radio/<n>" -> in_range ...
        self._load_rail: dict[str, str] = {}
        self._plugged: bool | None = None  # the umbilical plugged in (None: not known)
        self._unplugged_last: tuple[float, Any] | None = None  # its last state while not
        self._watchers: dict[tuple[str, str], list[_Fault]] = {}
        self._rail_faults: dict[str, list[_Fault]] = {}

    # -- sessions ------------------------------------------------------------------------------

    @property
    def session_id(self) -> str:
        """The running session's id ("" before any is known)."""
        return self._current.id

    def _session_of(self, sid: str, t: float | None) -> _Session:
        """The session ``sid`` names: known, the first named (what came before it is its own),
        or new: running from now when later than the running one (which ends: what it holds
        in effect ends with it), else an ended one heard late."""
        s = self._by_id.get(sid)
        if s is not None:
            return s
        cur = self._current
        if not cur.id:
            cur.id = sid
            self._by_id[sid] = cur
            self.version += 1
            return cur
        s = self._by_id[sid] = _Session(sid, start_t=t if sid > cur.id else None)
        self._sessions.append(s)
        self._sessions.sort(key=lambda x: x.id)
        if sid < cur.id:
            return s
        for f in cur.active.values():
            f.ended = True
        cur.active.clear()
        self._current = s
        self._watchers.clear()
        self._rail_faults.clear()
        self._forget_values()
        self.version += 1
        return s

    def know_rails(self, load_rail: Mapping[str, str]) -> None:
        """Which rail feeds each load, known before the events come: a recording made after a
        fault holds the journal's history first and the loads' telemetry (which says their
        rails) only after it, and a short's rail trip was then no alarm of the short's (it was
        taken as resolved once the load's own alarm cleared, the rail still tripped)."""
        self._load_rail.update(load_rail)

    # -- telemetry ---------------------------------------------------------------------------------

    def value(self, parts: Sequence[str], payload: Any) -> str:
        """A telemetry sample of this rover (``parts``: its key's chunks after
        ``lunaris/<rover>/``; ``payload``: its JSON object or its Struct). Returns the session
        it belongs to. (Called for every sample of an hour's recording: written for speed.)"""
        if isinstance(payload, dict):
            get = payload.get
        else:
            def get(name: str, default: Any = None) -> Any:
                return getattr(payload, name, default)
        n = len(parts)
        head = parts[0] if n else ""
        t = get("t_s")
        if t is None:
            return self._current.id
        if n == 3:
            name = parts[1]
            if head == "load":
                rail = get("rail")
                if rail:
                    self._load_rail[name] = rail
                if get("on") is not False:  # on a dead rail every load draws 0 W, whatever ails it
                    self._number(("load/" + name + "/power", "power_w"), t, get("power_w"))
            elif head == "rail":
                self._rail(name, t, get("state"))
            elif head == "solar":
                self._number(("solar/" + name + "/power", "power_w"), t, get("power_w"))
            elif head == "radio":
                self._state(("radio/" + name + "/link", "in_range"), t, get("in_range"))
        elif head == "clock" and n == 1:
            self._clock(t, get)
        elif head == "battery" and n == 2:
            self._number(_BATTERY_CAPACITY, t, get("capacity_j"))
            self._number(_BATTERY_VOLTAGE, t, get("voltage_v"))
            self._number(_BATTERY_TEMPERATURE, t, get("temperature_c"))
            self._state(_BATTERY_OPERATIONAL, t, get("operational"))
        elif head == "umbilical" and n == 2:
            self._umbilical(t, get("connected"), get("power_w"))
        elif head == "scenario" and n == 2 and parts[1] == "progress":
            self._progress(payload)
        cur = self._current
        if cur.start_t is None and not cur.id:  # a twin older than sessions: no tick names one
            cur.start_t = t
        return cur.id

    def _clock(self, t: float, get: Any) -> None:
        epoch, sid = get("epoch", 0) or 0, get("session", "") or ""
        running = self._current
        if sid and sid != self._current.id:
            if self._session_of(sid, t) is not self._current:
                return  # a late tick of an ended session: none of the running one's time
        if self._epoch is not None and epoch > self._epoch and self._current is running:
            self._new_epoch()
        if self._epoch is not None and epoch != self._epoch:
            self._forget_values()
        if self._epoch is None or epoch >= self._epoch:
            self._epoch = epoch
        s = self._current
        s.ticks += 1
        self._t = t
        if s.start_t is None:
            s.start_t = t
        if s.last_t is None or t > s.last_t:
            s.last_t = t

    def _new_epoch(self) -> None:
        """A reset or a restore within the running session: the faults in effect end with the
        twin's state (the reset cleared them: unresolved, as at a session's end), and nothing
        heard before it - an alarm, a crew action - belongs to a fault injected after it (the
        clock starts again from the reset's time, so the two epochs' times overlap). Found: a
        drill played after faults injected by hand, in one session, showed the drill's fault
        acted upon with the actions before the reset."""
        s = self._current
        s.era += 1
        for f in s.active.values():
            f.ended = True
        s.active.clear()
        s.raised.clear()
        s.recent_raises.clear()
        s.recent_actions.clear()
        self._watchers.clear()
        self._rail_faults.clear()
        self.version += 1

    def _forget_values(self) -> None:
        """A new epoch or session: the values before it are no band of anything after it."""
        for series in self._series.values():
            series.clear()
        self._states.clear()
        self._plugged, self._unplugged_last = None, None

    def _umbilical(self, t: float, connected: Any, power_w: Any) -> None:
        """The umbilical's supply counts only while it is plugged in: its state says connected,
        or the last plug heard (:meth:`_plug`) plugged it in - a cut umbilical says it is not
        connected, plugged or not. Unplugged, it supplies nothing, whatever ails it."""
        if connected:
            self._plugged = True
        if connected is None or connected or self._plugged:
            self._number(_UMBILICAL, t, power_w)
        else:
            self._unplugged_last = (t, power_w)

    def _plug(self, t: float, params: Any) -> None:
        """The umbilical plugged in or out (``input/umbilical``, accepted, whoever did it). Its
        state of the tick it was plugged in at came first (its service says so after): it
        counts now."""
        plugged = params.get("connected") if isinstance(params, Mapping) else None
        if not isinstance(plugged, bool):
            return
        self._plugged = plugged
        last, self._unplugged_last = self._unplugged_last, None
        if plugged and last is not None and last[0] >= t:
            self._number(_UMBILICAL, *last)

    def _series_of(self, key: tuple[str, str]) -> Series:
        series = self._series.get(key)
        if series is None:
            series = self._series[key] = Series()
        return series

    def _number(self, key: tuple[str, str], t: float, v: Any) -> None:
        if v is None or isinstance(v, bool):
            return
        series = self._series.get(key)
        if series is None:
            series = self._series[key] = Series()
        series.add(t, v)
        faults = self._watchers.get(key)
        if faults:
            for f in list(faults):
                self._look(f, t, v)

    def _state(self, key: tuple[str, str], t: float, v: Any) -> None:
        if v is None:
            return
        series = self._series.get(key)
        if series is None:
            series = self._series[key] = Series()
        series.add_state(t, v)
        faults = self._watchers.get(key)
        if faults:
            for f in list(faults):
                self._look(f, t, v)

    def _rail(self, rail: str, t: float, state: Any) -> None:
        if state is None:
            return
        if self._states.get(rail) == state:
            return  # (its series keeps the changes only)
        self._state(("rail/" + rail + "/state", "state"), t, state)
        self._states[rail] = state
        for f in self._rail_faults.get(rail, ()):
            if f.active and state in _TWIN_RAIL_STATES:
                f.caused_any = True
            self._settle(f, t)

    def _look(self, f: _Fault, t: float, v: Any) -> None:
        """A watched value at ``t``: a symptom of ``f`` if it left its band."""
        if not f.active or t < f.injected_t:
            return
        assert f.watch is not None
        tail, fld = f.watch
        words = ""
        if f.direction == "change":
            if f.before is not None and v != f.before:
                words = f"{tail.rsplit('/', 1)[0]} {fld} {f.before} -> {v}"
        elif f.direction == "lost":
            if f.before is True and v is False:
                words = f"{tail.rsplit('/', 1)[0]} out of range"
            f.before = v  # out of range before: the next loss of the link counts
        elif f.direction == "nothing" and f.band is None:
            if not isinstance(v, bool) and v <= TOLERANCE.get(fld, (0.0, 0.0, False))[0]:
                name, unit = quantity(fld)
                words = f"{tail.rsplit('/', 1)[0]} {name} {v:.3g} {unit} {f.live}".rstrip()
        elif f.band is not None and not isinstance(v, bool):
            way = f.band.outside(t, v, "down" if f.direction == "nothing" else f.direction)
            if way:
                name, unit = quantity(fld)
                words = (f"{tail.rsplit('/', 1)[0]} {name} {v:.3g} {unit}, {way} "
                         f"{f.band.words(unit)} before").replace(" ,", ",")
        if words and f.found(t, words):
            self._unwatch(f)
            self.version += 1

    def _unwatch(self, f: _Fault) -> None:
        if f.watch is not None:
            faults = self._watchers.get(f.watch, [])
            if f in faults:
                faults.remove(f)

    # -- events ------------------------------------------------------------------------------------

    def event(self, ev: Any) -> str:
        """An event of this rover (an :class:`common.messages.Event` or its JSON object), each
        once. Returns the session it belongs to."""
        kind, key = _get(ev, "kind", ""), _get(ev, "key", "") or ""
        t = _get(ev, "t_s") or 0.0
        sid = _get(ev, "session", "") or ""
        s = self._session_of(sid, None) if sid else self._current  # its start: its own first tick
        params = _get(ev, "params") or {}
        opened = session_opened(ev)
        if opened is not None and opened[0] == s.id:  # the clock's word that it opened
            s.trainee = opened[1]
            wall = params.get("started_wall") if isinstance(params, Mapping) else None
            s.started_wall = float(wall) if isinstance(wall, int | float) else None
            self.version += 1
        if kind == "fault_injected":
            self._inject(s, key, t, params if isinstance(params, Mapping) else {}, _get(ev, "actor", ""))
        elif kind == "fault_cleared":
            self._clear(s, key, t)
        elif kind == "fault_raised":
            self._alarm(s, key, t, True)
        elif kind == "fault_resolved":
            self._alarm(s, key, t, False)
        elif kind == "input" and key == self.prefix + "input/umbilical" and s is self._current:
            self._plug(t, params)
        elif kind == "scenario" and isinstance(params, Mapping) and params.get("what") == "expect":
            self._scored(s, params)
        if _get(ev, "actor", "") == "crew" and kind in ("command", "input", "rejected", "clock"):
            self._crew(s, self._action(ev, kind, key, t, params))
        return s.id

    # -- faults --------------------------------------------------------------------------------------

    def _inject(self, s: _Session, key: str, t: float, params: Mapping, actor: str) -> None:
        if not key.startswith(self.prefix + "fault/"):
            return
        path = key[len(self.prefix) + len("fault/"):]
        chunks = path.split("/")
        if len(chunks) not in (2, 3):
            return
        known = s.active.get(key)
        if known is not None:  # injected again: new parameters, in effect since the first
            known.params = dict(params)
            self.version += 1
            return
        component, kind = chunks[0], chunks[-1]
        name = chunks[1] if len(chunks) == 3 else None
        scopes = list(_scopes(self.prefix, component, name))
        rails: dict[str, str | None] = {}
        if component == "load" and name is not None and name in self._load_rail:
            rail = self._load_rail[name]
            rails[rail] = self._states.get(rail)
            scopes += _scopes(self.prefix, "rail", rail)
        elif component == "rail" and name is not None:
            rails[name] = self._states.get(name)
            scopes += [self.prefix + f"load/{ld}/" for ld, r in self._load_rail.items() if r == name]
        f = _Fault(key, path, component, name, kind, dict(params), actor or "", t, tuple(scopes), rails,
                   era=s.era)
        f.touches.add(unit_of(path))
        f.touches.update("rail/" + r for r in rails)
        s.faults.append(f)
        if s is not self._current:  # of a session that ended, heard late: the twin moved on
            f.ended = True
            return
        s.active[key] = f
        for rail in rails:
            self._rail_faults.setdefault(rail, []).append(f)
        spec = SYMPTOMS.get((component, kind))
        if spec is not None:
            tail = spec.family.replace("{name}", name or "")
            self._watch(f, tail, spec)
        for raised_t, alarm, message in s.recent_raises:  # heard before the injection
            if raised_t >= t and alarm in s.raised and alarm.startswith(f.scopes):
                self._caused(f, alarm, raised_t, message)
        # actions heard before it, at its tick or after (each service's events come their own way)
        f.actions.extend(sorted((a for a in s.recent_actions if a.t_s >= t), key=lambda a: a.t_s))
        self.version += 1

    def _watch(self, f: _Fault, tail: str, spec: SymptomSpec) -> None:
        key = (tail, spec.field)
        f.watch, f.direction, f.live = key, spec.direction, spec.live
        series = self._series_of(key)
        if spec.direction in ("change", "lost"):
            f.before = series.last_before(f.injected_t)
            if f.before is None and spec.direction == "change":
                return  # no value before it: nothing to compare with
        else:
            points = series.before(f.injected_t)
            if not points and spec.direction != "nothing":
                return  # no value before it: its band is not known
            trend = TOLERANCE.get(spec.field, (0, 0, False))[2] or (
                spec.field == "power_w" and f.component in SMOOTH_POWER)
            if points:  # (nothing: none before is a value never live, 0 when live a symptom)
                f.band = Band.of(points, spec.field, trend)
        self._watchers.setdefault(key, []).append(f)
        for ts, v in list(series.recent):  # what came before the injection was heard
            if ts >= f.injected_t:
                self._look(f, ts, v)

    def _clear(self, s: _Session, key: str, t: float) -> None:
        f = s.active.pop(key, None)
        if f is None:
            return  # not injected in this session (a reset's clearing, heard after it)
        if s is not self._current:
            f.ended = True  # cleared with the end of its session
        else:
            f.cleared_t = t
            if f.resolved_t is None:
                f.resolved_t, f.resolved_by = t, "cleared"
        self._unwatch(f)
        self._settle(f, t)
        self.version += 1

    def _alarm(self, s: _Session, key: str, t: float, raised: bool) -> None:
        message = key[len(self.prefix):] if key.startswith(self.prefix) else key
        if raised:
            s.raised[key] = t
            s.recent_raises.append((t, key, message))
            for f in s.active.values():
                if t >= f.injected_t and key.startswith(f.scopes):
                    self._caused(f, key, t, message)
            return
        s.raised.pop(key, None)
        for f in s.faults:
            if key in f.caused:
                f.caused.discard(key)
                self._settle(f, t)

    def _caused(self, f: _Fault, key: str, t: float, message: str) -> None:
        unit = unit_of(message)
        f.touches.add(unit)  # what its symptoms reached, and a load's rail with it
        if unit.startswith("load/") and unit[5:] in self._load_rail:
            f.touches.add("rail/" + self._load_rail[unit[5:]])
        f.caused.add(key)
        f.caused_any = True
        parts = message.split("/")
        if (parts[0], parts[-1]) not in UNSEEN_ALARMS:  # (one the crew never sees is none)
            f.found(t, f"alarm {message}")
        if f.resolved_t is not None and f.active:
            f.resolved_t, f.resolved_by = None, ""  # not resolved after all
        self.version += 1

    def _settle(self, f: _Fault, t: float) -> None:
        """Resolved (while in effect) and settled (no more actions collected) as they stand."""
        rails_back = all(pre is None or self._states.get(r) == pre for r, pre in f.rails.items())
        if f.active and f.caused_any:
            holds = not f.caused and rails_back
            if holds and f.resolved_t is None:
                back = ", ".join(f"{r} back {pre}" for r, pre in f.rails.items() if pre)
                f.resolved_t = t
                f.resolved_by = "its alarms cleared" + (f" and {back}" if back else "")
                self.version += 1
            elif not holds and f.resolved_t is not None:
                f.resolved_t, f.resolved_by = None, ""
                self.version += 1
        if not f.active and f.settled_t is None and not f.caused and rails_back:
            f.settled_t = t

    # -- the crew ------------------------------------------------------------------------------------

    def _action(self, ev: Any, kind: str, key: str, t: float, params: Any) -> CrewAction:
        tail = key[len(self.prefix):] if key.startswith(self.prefix) else key
        parts = tail.split("/")
        accepted = kind != "rejected"
        message = str(_get(ev, "message", "") or "")
        p = params if isinstance(params, Mapping) else {}
        if parts[:2] == ["cmd", "rail"] and len(parts) == 3:
            target = parts[2]
            what = []
            if p.get("reset"):
                what.append("reset")
            if p.get("on") is not None:
                what.append("on" if p["on"] else "off")
            action = "rail " + " and ".join(what) if accepted and what else "rail command"
        elif tail == "input/drive/traverse":
            target = "drive"
            stop = message.startswith("traverse stopped") or "to stop" in message
            action = "drive stop" if stop else "traverse"
        elif parts[0] == "input":
            action, target = "input", "/".join(parts[1:])
        else:
            action, target = kind, tail
        return CrewAction(t, action, target, accepted, key, message)

    def _crew(self, s: _Session, action: CrewAction) -> None:
        t = action.t_s
        s.recent_actions.append(action)
        for f in s.faults:
            if f.era == s.era and t >= f.injected_t and (f.settled_t is None or t <= f.settled_t):
                f.actions.append(action)
                if len(f.actions) > 1 and f.actions[-2].t_s > t:
                    f.actions.sort(key=lambda a: a.t_s)
        self.version += 1

    # -- expectations -----------------------------------------------------------------------------

    def _scored(self, s: _Session, params: Mapping) -> None:
        e = params.get("expectation")
        if not isinstance(e, Mapping):
            return
        scenario = str(params.get("scenario", ""))
        armed, start = e.get("armed_t_s"), e.get("start_t_s")
        within = float(e.get("within_s") or 0.0)
        s.scored[(scenario, e.get("index"), _rounded(start))] = Expectation(
            label=str(e.get("label", "")), met=bool(e.get("met")), at_t_s=e.get("at_t_s"),
            within_s=within, condition=str(e.get("condition", "")), scenario=scenario,
            step=int(e.get("index") or 0), armed_t_s=armed,
            deadline_t_s=None if armed is None else armed + within, detail=str(e.get("detail", "")))
        self.version += 1

    def _progress(self, p: Any) -> None:
        """The runner's progress: the expectations of the scenario as they stand."""
        scenario = str(_get(p, "scenario", ""))
        t, rel = _get(p, "t_s"), _get(p, "t_rel_s")
        start = None if t is None or rel is None else t - rel
        out = []
        for step in _get(p, "steps", None) or []:
            x = _get(step, "expect")
            if x is None:
                continue
            armed_rel, met_rel, deadline_rel = (_get(step, "armed_t_s"), _get(x, "met_t_s"),
                                                _get(x, "deadline_t_s"))

            def sim(rel_t: float | None) -> float | None:
                return None if rel_t is None or start is None else start + rel_t
            index = int(_get(step, "index", 0))
            out.append(((scenario, index, _rounded(start)), Expectation(
                label=str(_get(x, "label", "")), met=_get(x, "met"), at_t_s=sim(met_rel),
                within_s=float(_get(x, "within_s", 0.0)), condition=str(_get(x, "condition", "")),
                scenario=scenario, step=index, armed_t_s=sim(armed_rel),
                deadline_t_s=sim(deadline_rel), detail=str(_get(step, "detail", "")))))
        s = self._current
        state = _get(p, "state", "")
        played_in = _get(p, "session", "") or ""
        if played_in and s.id and played_in != s.id:
            return  # a drill of another session: none of this one's (SPEC 13a)
        if state != "playing" and scenario not in s.pending:
            return  # the end of a run this session did not see play (a cached progress)
        if s.pending.get(scenario) != out:
            s.pending[scenario] = out
            self.version += 1

    # -- what it tells -------------------------------------------------------------------------------

    def _expectations(self, s: _Session) -> list[Expectation]:
        out = dict(s.scored)
        for entries in s.pending.values():
            for key, e in entries:
                out.setdefault(key, e)
        return sorted(out.values(), key=lambda e: (e.armed_t_s is None, e.armed_t_s or 0.0,
                                                   e.scenario, e.step))

    def _result(self, s: _Session) -> SessionResponse:
        return SessionResponse(
            session=s.id, trainee=s.trainee, faults=[f.result(note=_before_seen(f, s)) for f in s.faults],
            expectations=self._expectations(s), rover=self.rover, start_t_s=s.start_t,
            end_t_s=s.last_t, started_wall=s.started_wall)

    def sessions(self, *, recorded_only: bool = False) -> list[SessionResponse]:
        """Every session seen, in order (``recorded_only``: those the clock ticked in, not
        those only heard of in replayed events)."""
        return [self._result(s) for s in self._sessions
                if not (recorded_only and s.ticks == 0) and not (s.empty() and s.ticks == 0)]

    def session(self, sid: str) -> SessionResponse | None:
        s = next((s for s in self._sessions if s.id == sid), None)
        return None if s is None else self._result(s)

    def live(self) -> LiveResponse:
        """The running session now: each fault with the time since its injection (while in
        effect) and whether the crew has acted, the expectations as they stand."""
        s, now = self._current, self._t
        faults = [f.result(LiveFault, since_injection_s=(
            None if now is None or not f.active else max(0.0, now - f.injected_t)),
            crew_acted=bool(f.acted())) for f in s.faults]
        return LiveResponse(self.rover, s.id, s.trainee, now, faults,
                            self._expectations(s), self.version)


def _before_seen(f: _Fault, s: _Session) -> str:
    """Words for a fault injected before the first tick of its session this response saw (a
    recording begun after it): its symptom and the crew's first moments may not be in it.
    Found: a recording started 16 s after a short gave its times as if it had seen them all."""
    if f.era != 0 or s.start_t is None or s.ticks == 0 or f.injected_t >= s.start_t:
        return ""
    return (f"injected at {f.injected_t:.1f} s, before the recording began ({s.start_t:.1f} s): "
            "what came between is not in it")


def _rounded(t: Any) -> float | None:
    return None if t is None or not isinstance(t, int | float) or not math.isfinite(t) else round(t, 2)
