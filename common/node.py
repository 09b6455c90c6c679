"""A service as a node: its ports declared in one table, its callbacks methods, its state a
dataclass per rover.

As an rclpy node declares its subscriptions, publishers and timers, or a Basilisk module its
input and output messages (``fswAlgorithms/_fswTemplateFolder``: the module's I/O table, its
``Reset`` and ``Update``), a Lunaris service says in one place what it reads and what it
publishes, and the one runtime (:class:`common.runtime.Runtime`) does the rest: it subscribes
and publishes exactly as it does for any service (urgent faults, a fleet's telemetry drained
from channels, advanced publishers with a last-value cache, liveliness tokens, the age check
of writes, wildcard keys dropped). A node::

    @dataclass
    class Pack(PerRover):                       # the state of one rover, on the node
        model: BatteryModel
        stepped_t: float = 0.0

    class BatteryNode(Node[Pack]):
        name = "battery"
        reads = (Reads("power/summary", PowerSummary, "on_summary"),)     # telemetry
        publishes = (Publishes("battery/state", BatteryState),)
        owns = (Owns("battery", "apply_faults"),)                        # fault/battery/**
        timers = (Every(0.01, "release_held"),)

        def rover_state(self, rover: Rover) -> Pack:
            return Pack(rover.id, BatteryModel(rover.battery))

        def on_tick(self, pack: Pack, tick: Clock) -> None: ...
        def on_summary(self, pack: Pack, summary: PowerSummary, s: Sample) -> None: ...

``lunaris run battery`` finds ``NODE = BatteryNode`` in ``services/battery/service.py``, makes
it with the rovers it serves, and :meth:`Node.attach` declares every port on the runtime.

**Reads** (:class:`Reads`): a key shape after ``lunaris/<rover>/`` (``*`` for a name:
``rail/*/state``), the payload Struct (checked against the family table,
:data:`common.keys.FAMILIES`, when the class is made), the callback and the kind:

- ``telemetry``: a tick-rate stream of another model (drained from a channel for a fleet);
- ``record``: a record another service keeps and republishes on change (the faults in effect
  of a service), with its publisher's cache replayed at start (an advanced subscriber);
- ``input``, ``command``: a write of an instructor, a scenario or a dashboard, decoded
  strictly (:func:`~common.messages.decode_input`: a bad one is rejected in words); a write
  older than ``WRITE_MAX_AGE_S`` when it arrives never reaches the callback.

The callback is ``on_x(self, state, msg, sample)``: the rover's state, the payload decoded as
its Struct, and the :class:`~common.runtime.Sample` (its key's chunks name the load, rail,
panel or radio). What a delete does is the port's ``deletes``: on a write the callback is
given None (it clears, stops, or refuses the delete in words); a stream drops it, or rejects
it as any bad payload (``reject``). A port's ``check(state, sample)`` runs before the payload
is read: it raises :class:`~common.messages.BadInput` for a write naming what the rover has
not ("rover mapp-1 has no rail 'x'", whatever the payload), or returns False to let a
sample go. ``only`` names a method giving the key expressions to subscribe to instead of every
rover's (a radio's own load only, not every load of the fleet). A bad payload, a
:class:`~common.messages.BadInput` raised by a callback: a ``rejected`` event naming the key
and why (the runtime's, as for every service); nothing changes.

**Hears** (:class:`Hears`): a key expression no family of the table describes (a session
control, ``control/reset``; every service's events, ``event/*``; the gatekeeper's every
write, ``fault/**``), handed over as it came: the callback is ``on_x(self, sample)``, with no
rover's state (the sample names its rover; ``any_rover`` keeps the samples of rovers the node
does not serve) and it reads the payload itself. Its options are those of
:meth:`~common.runtime.Runtime.subscribe` (``history``, ``telemetry``, ``urgent``,
``any_rover``, ``writes``). A shape of the family table is refused: declare it with ``Reads``.

**Publishes** (:class:`Publishes`): what the node puts, whether it must never be dropped
(``reliable``) and how many of its latest samples a late joiner is given (``cache``).
:meth:`Node.publish` refuses a key no port declares. Every node also publishes its events
(``event/<service>``) and, when it owns faults, the faults in effect
(``faults/active/<service>``).

**Owns** (:class:`Owns`): the fault components whose faults the node's fault book keeps
(``fault/<component>/**``, urgent); ``apply(state, name, faults)`` gives the model every
fault in effect on one component. **Every** (:class:`Every`): a timer of wall time;
``after_batch``: a method called after each batch of samples (a burst folded into one
recomputation). **Answers** (:class:`Answers`): a ``get`` the node answers.

**State**: :meth:`Node.rover_state` makes the state of one rover (a dataclass, a subclass of
:class:`PerRover`); :attr:`Node.rovers` holds them. A node that keeps state across restarts,
resets and snapshots (``keeps_state``) says what it is and how to set it (``get_state``,
``set_state``, ``reset``, ``check_state``; ``republish`` once a control changed it); the
runtime's session keeper does the rest. A rover whose saved state is found damaged is reset,
or given to ``recover(state)`` when the node defines it (it puts the rover right and returns
what it did, in words). The clock says that it makes the time (``makes_time``: it publishes
the ticks, waits for none and judges none against its own time); the gatekeeper (the faults
service) defines ``on_wildcard(sample)``: the writes whose key holds a wildcard, which every
other service drops. :meth:`Node.on_tick` is called with every clock tick
of a rover (when a node defines it), :meth:`Node.start` once every port is declared and the
saved faults re-applied (first publications).

The callbacks, the timers and the hooks run one at a time on the service's worker thread:
the state needs no lock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, Literal, TypeVar

import msgspec

from common import keys
from common.config import Rover, fingerprint
from common.messages import BARE_FIELD, Clock, decode, decode_input
from common.runtime import Runtime, Sample, WriteRole

__all__ = ["Answers", "Every", "Hears", "Kind", "Node", "Owns", "PerRover", "Publishes", "Reads",
           "port_table"]

Kind = Literal["telemetry", "record", "input", "command"]
Deletes = Literal["drop", "reject", "pass"]
_WRITES = ("input", "command")


def _family(shape: str, payload: type[msgspec.Struct], *directions: str) -> keys.Family:
    """The family of a key shape, checked against its declared payload and direction."""
    fam = keys.family_of(shape.split("/"))
    if fam is None:
        raise TypeError(f"{shape!r} is no key family of common.keys.FAMILIES")
    if fam.payload is not payload:
        raise TypeError(f"{shape!r} carries {fam.payload.__name__}, not {payload.__name__}")
    if fam.direction not in directions:
        raise TypeError(f"{shape!r} is a family the twin {fam.direction!r}s, not "
                        f"{' or '.join(directions)}")
    return fam


@dataclass(frozen=True)
class Reads:
    """A key the node reads: ``shape`` after ``lunaris/<rover>/`` (``*`` for a name), its
    payload, the callback ``on(state, msg, sample)`` and the kind of stream (see the module)."""

    shape: str
    payload: type[msgspec.Struct]
    on: str
    kind: Kind = "telemetry"
    urgent: bool = False  # handled ahead of everything waiting (what the crew is trained on)
    deletes: Deletes | None = None  # None: "pass" for a write, "drop" for a stream
    check: str | None = None  # a method (state, sample) -> bool, run before the payload is read
    only: str | None = None  # a method () -> the key expressions to subscribe to

    def __post_init__(self) -> None:
        _family(self.shape, self.payload, *(("in",) if self.kind in _WRITES else ("out",)))
        if self.kind not in ("telemetry", "record", *_WRITES):
            raise TypeError(f"{self.shape}: no kind of port {self.kind!r}")

    @property
    def on_delete(self) -> Deletes:
        return self.deletes or ("pass" if self.kind in _WRITES else "drop")

    def pattern(self) -> str:
        """The key expression of every rover's keys of this port."""
        return keys.under("*", self.shape)


@dataclass(frozen=True)
class Hears:
    """A key expression outside the family table (``shape`` after ``lunaris/<rover>/``, with
    ``*`` and ``**``), its samples handed as they came to ``on(sample)``; the options as
    :meth:`~common.runtime.Runtime.subscribe`'s (see the module)."""

    shape: str
    on: str
    history: bool = False
    telemetry: bool = False
    urgent: bool = False
    any_rover: bool = False
    writes: WriteRole = "own"

    def __post_init__(self) -> None:
        fam = keys.family_of(self.shape.split("/"))
        if fam is not None:
            raise TypeError(f"{self.shape!r} is the family {fam.name} of common.keys.FAMILIES: "
                            "declare it with Reads")

    def pattern(self) -> str:
        """The key expression of every rover's keys of this port."""
        return keys.under("*", self.shape)


@dataclass(frozen=True)
class Publishes:
    """A key the node publishes (``shape`` as for :class:`Reads`) and its payload;
    ``reliable``: never dropped under congestion (it waits instead); ``cache``: see the module."""

    shape: str
    payload: type[msgspec.Struct]
    reliable: bool = False
    cache: int = 1  # the publisher's cache: the latest so many samples, for late joiners

    def __post_init__(self) -> None:
        _family(self.shape, self.payload, "out")

    def matches(self, parts: list[str]) -> bool:
        chunks = self.shape.split("/")
        return len(parts) == len(chunks) and all(c in ("*", p) for c, p in zip(chunks, parts,
                                                                                strict=True))


@dataclass(frozen=True)
class Owns:
    """A component whose faults the node owns (``fault/<component>/**``): ``apply(state,
    name, faults)`` gives the model every fault in effect on one of them; ``names(state)``
    lists the components of a named kind (None: the battery, the umbilical)."""

    component: str
    apply: str
    names: str | None = None


@dataclass(frozen=True)
class Every:
    """A method called every ``period_s`` of wall time (skipping ahead when late)."""

    period_s: float
    call: str


@dataclass(frozen=True)
class Answers:
    """A ``get`` the node answers: ``on(query)`` on the worker thread, for every rover."""

    shape: str
    payload: type[msgspec.Struct]
    on: str

    def __post_init__(self) -> None:
        _family(self.shape, self.payload, "query")


@dataclass
class PerRover:
    """The state a node keeps for one rover: subclass it with the rover's models and what the
    node remembers of it."""

    id: str


S = TypeVar("S", bound=PerRover)


class Node(Generic[S]):
    """A service: its ports (class attributes), its state per rover and its callbacks."""

    name: ClassVar[str]
    reads: ClassVar[tuple[Reads, ...]] = ()
    hears: ClassVar[tuple[Hears, ...]] = ()
    publishes: ClassVar[tuple[Publishes, ...]] = ()
    owns: ClassVar[tuple[Owns, ...]] = ()
    answers: ClassVar[tuple[Answers, ...]] = ()
    timers: ClassVar[tuple[Every, ...]] = ()
    after_batch: ClassVar[str | None] = None
    keeps_state: ClassVar[bool] = True
    makes_time: ClassVar[bool] = False  # the clock: it publishes the ticks (Runtime.makes_time)
    persist_every_s: ClassVar[float | None] = 1.0  # wall time between saves of the state

    rt: Runtime

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        named = [p.on for p in cls.reads] + [h.on for h in cls.hears] + [a.on for a in cls.answers]
        named += [t.call for t in cls.timers]
        named += [n for p in cls.reads for n in (p.check, p.only) if n]
        named += [n for o in cls.owns for n in (o.apply, o.names) if n]
        named += [cls.after_batch] if cls.after_batch else []
        missing = [n for n in named if not callable(getattr(cls, n, None))]
        if missing:
            raise TypeError(f"{cls.__name__}: its ports name no method {', '.join(missing)}")

    def __init__(self, rovers: Iterable[Rover], seed: int | None = None):
        self.seed = seed
        self.configs = {r.id: r for r in rovers}
        self.rovers: dict[str, S] = {r.id: self.rover_state(r) for r in self.configs.values()}
        self._ports: dict[str, Publishes] = {}  # key published -> its port

    @classmethod
    def serves(cls, rover: Rover) -> bool:
        """Whether the node has something to do for this rover (``lunaris run`` leaves the
        others out)."""
        return True

    # -- what a node defines ----------------------------------------------------------------

    def rover_state(self, rover: Rover) -> S:
        """The state of one rover as the rover file starts it."""
        raise NotImplementedError

    def on_tick(self, st: S, tick: Clock) -> None:
        """A clock tick of a rover, after :attr:`Runtime.t_s` has moved to it (not called
        for a node that does not define it)."""

    def get_state(self, st: S) -> dict[str, Any]:
        """What evolves of a rover, as saved on disk and in snapshots."""
        return {}

    def set_state(self, st: S, state: dict[str, Any]) -> None:
        """Resume from what :meth:`get_state` returned (checked: see :meth:`check_state`)."""

    def reset(self, st: S) -> None:
        """Back to the rover file's initial conditions (a session reset)."""

    def check_state(self, st: S, state: dict[str, Any]) -> None:
        """The ranges of a saved state: raise ValueError naming what is out of range (the
        keeper has checked the shape, the types and that every number is finite)."""

    def recover(self, st: S) -> str:
        """A rover whose saved state was found damaged: put it right and say what was done, in
        words (not called for a node that does not define it: the keeper resets the rover)."""
        raise NotImplementedError

    def on_wildcard(self, sample: Sample) -> None:
        """A write whose key holds a wildcard, which every service drops: the gatekeeper's
        (:meth:`~common.runtime.Runtime.on_wildcard`; not declared for a node that does not
        define it)."""

    def republish(self, st: S) -> None:
        """Publish a rover's state again once a control (reset, restore) changed it."""

    def start(self) -> None:
        """Once every port is declared and the saved faults are re-applied: first publications."""

    # -- what the base gives ----------------------------------------------------------------

    def attach(self, rt: Runtime) -> None:
        """Declare the node's ports on the runtime: subscriptions, ticks, fault components,
        state, timers, queries; then :meth:`start`."""
        self.rt = rt
        if self.makes_time:
            rt.makes_time()
        if type(self).on_wildcard is not Node.on_wildcard:
            rt.on_wildcard(self.on_wildcard)
        if type(self).on_tick is not Node.on_tick:
            rt.on_tick(_PerRoverCall(self, self.on_tick))
        for port in self.reads:
            targets = getattr(self, port.only)() if port.only else [port.pattern()]
            for keyexpr in targets:
                rt.subscribe(keyexpr, _Delivery(self, port), telemetry=port.kind == "telemetry",
                             history=port.kind == "record", urgent=port.urgent)
        for heard in self.hears:
            rt.subscribe(heard.pattern(), getattr(self, heard.on), any_rover=heard.any_rover,
                         history=heard.history, telemetry=heard.telemetry, urgent=heard.urgent,
                         writes=heard.writes)
        for answer in self.answers:
            rt.queryable(keys.under("*", answer.shape), getattr(self, answer.on))
        for owned in self.owns:
            rt.faults.own(owned.component,
                          _PerRoverCall(self, getattr(self, owned.names)) if owned.names else None,
                          _PerRoverCall(self, getattr(self, owned.apply)))
        if self.keeps_state:
            rt.own_state(_PerRoverCall(self, self.get_state), _PerRoverCall(self, self.set_state),
                         _PerRoverCall(self, self.reset), after=_PerRoverCall(self, self.republish),
                         persist_every_s=self.persist_every_s,
                         check=_PerRoverCall(self, self.check_state),
                         damaged=(_PerRoverCall(self, self.recover)
                                  if type(self).recover is not Node.recover else None),
                         files={rid: fingerprint(cfg) for rid, cfg in self.configs.items()})
        if self.owns:
            rt.faults.restore()
        if self.after_batch:
            rt.after_batch(getattr(self, self.after_batch))
        for timer in self.timers:
            rt.every(timer.period_s, getattr(self, timer.call))
        self.start()

    def publish(self, key: str, msg: msgspec.Struct) -> None:
        """Publish on a key a :class:`Publishes` port declares (ValueError for another: a bug),
        reliably and with the cache the port says."""
        port = self._ports.get(key)
        if port is None:
            port = self._ports[key] = self._port_of(key, msg)
        self.rt.publish(key, msg, reliable=port.reliable, cache=port.cache)

    def _port_of(self, key: str, msg: msgspec.Struct) -> Publishes:
        _, parts = keys.split(key)
        for port in self.publishes:
            if port.matches(parts) and isinstance(msg, port.payload):
                return port
        raise ValueError(f"{self.name} publishes no {type(msg).__name__} on {key}: "
                         "no Publishes port declares it")


class _PerRoverCall:
    """A node's method of a rover's state, called as the runtime calls with a rover's id:
    ``fn(state, *args)`` for ``(rover, *args)``."""

    __slots__ = ("fn", "rovers")

    def __init__(self, node: Node, fn: Callable[..., Any]):
        self.fn, self.rovers = fn, node.rovers

    def __call__(self, rover: str, *args: Any) -> Any:
        return self.fn(self.rovers[rover], *args)


class _Delivery:
    """A port's samples to its callback: the rover's state, the payload decoded as the
    port's Struct (strictly for a write), deletes as the port says."""

    __slots__ = ("bare", "check", "deletes", "fn", "payload", "rovers", "write")

    def __init__(self, node: Node, port: Reads):
        self.fn = getattr(node, port.on)
        self.check = getattr(node, port.check) if port.check else None
        self.rovers = node.rovers
        self.payload = port.payload
        self.write = port.kind in _WRITES
        self.bare = BARE_FIELD.get(port.payload)
        self.deletes = port.on_delete

    def __call__(self, s: Sample) -> None:
        st = self.rovers.get(s.rover)
        if st is None or (self.check is not None and not self.check(st, s)):
            return
        if s.deleted and self.deletes != "reject":
            if self.deletes == "pass":
                self.fn(st, None, s)
            return
        if self.write:
            msg = decode_input(s.payload, self.payload, bare=self.bare)
        else:  # the twin's own (a delete's empty payload fails here: rejected)
            msg = decode(s.payload, self.payload)
        self.fn(st, msg, s)


def port_table(node: type[Node]) -> list[tuple[str, str, str, str]]:
    """A node's ports as rows ``(direction, key, payload, what)``, for a reader or a test."""
    rows = [("reads", p.pattern(), p.payload.__name__, f"{p.kind} -> {p.on}") for p in node.reads]
    rows += [("hears", h.pattern(), "-", h.on) for h in node.hears]
    rows += [("publishes", keys.under("*", p.shape), p.payload.__name__,
              "reliable" if p.reliable else "telemetry") for p in node.publishes]
    rows += [("answers", keys.under("*", a.shape), a.payload.__name__, a.on) for a in node.answers]
    rows += [("owns", keys.fault_prefix("*", o.component), "Fault", o.apply) for o in node.owns]
    return rows
