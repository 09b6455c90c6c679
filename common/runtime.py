"""The one service runtime: every Lunaris service is a model wrapped by this shell.

What it gives a service:

- a Zenoh session from the shared connection options, with a liveliness token
  ``lunaris/<rover>/service/<name>`` per rover served, declared once the service
  is set up (a live token means its subscribers are in place);
- :meth:`Runtime.publish`: JSON on a ``zenoh.ext`` advanced publisher whose cache
  keeps the last sample for late joiners;
- :meth:`Runtime.subscribe`: samples are queued and handled one at a time on a
  single worker thread, so models need no locks. After the queue runs dry the
  ``after_batch`` hooks run: a burst of inputs is folded into one recomputation,
  while a single input (a fault) is acted on at once;
- one way to refuse input: a handler raises :class:`~common.messages.BadInput`
  and the runtime publishes a ``rejected`` event naming the key and the reason;
- fault injection and clearing for the components a service owns
  (:meth:`Runtime.handle_faults`), derived faults raised and resolved on
  transitions (:meth:`Runtime.sync_derived`), both journalled as events;
- persisted state under ``--state-dir``; clean shutdown on SIGINT or SIGTERM.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NamedTuple

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.faults import FaultKey, parse_fault_key, parse_params
from common.messages import BadInput, Clock, Event, decode, encode

__all__ = ["ActiveFault", "Runtime", "Sample"]

EVENT_CACHE = 256  # recent events kept for a journal that joins late


class Sample(NamedTuple):
    key: str
    rover: str
    parts: list[str]  # the key's chunks after lunaris/<rover>/
    payload: bytes
    deleted: bool
    attachment: bytes | None = None


class ActiveFault(msgspec.Struct):
    key: str
    params: dict[str, Any]
    since_t_s: float
    origin: str  # injected | derived
    severity: str = "warning"


Handler = Callable[[Sample], None]
FaultApply = Callable[[str, FaultKey, dict | None], None]  # rover, key, params (None: clear)


class Runtime:
    """A running service: its session, its worker thread and its bookkeeping."""

    def __init__(
        self,
        name: str,
        rovers: Iterable[str],
        conf: zenoh.Config,
        state_dir: str | os.PathLike | None = None,
    ):
        self.name = name
        self.rovers: set[str] = set(rovers)
        self.now: dict[str, float] = dict.fromkeys(self.rovers, 0.0)  # sim time per rover
        self.state_dir = Path(state_dir) if state_dir else None
        self.injected: dict[str, dict[str, ActiveFault]] = {r: {} for r in self.rovers}
        self.derived: dict[str, dict[str, ActiveFault]] = {r: {} for r in self.rovers}
        self._conf = conf
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._after_batch: list[Callable[[], None]] = []
        self.batch_linger_s = 0.0
        self._exit_hooks: list[Callable[[], None]] = []
        self._timers: list[list] = []  # [period_s, due, fn]
        self._publishers: dict[str, Any] = {}
        self._fault_appliers: dict[str, FaultApply] = {}
        self._keep: list[Any] = []  # subscribers, tokens, queryables
        self.session: zenoh.Session | None = None

    # -- lifecycle --------------------------------------------------------------------------

    def open(self) -> Runtime:
        self.session = zenoh.open(self._conf)
        # Sim time is tracked on Zenoh's thread, before any handler runs, so that every
        # event and payload of every service carries the rover's current t_s.
        self._keep.append(self.session.declare_subscriber(keys.clock("*"), self._on_clock))
        return self

    def _on_clock(self, s: zenoh.Sample) -> None:
        rover, _ = keys.split(str(s.key_expr))
        if rover in self.rovers:
            self.now[rover] = max(self.now[rover], decode(s.payload.to_bytes(), Clock).t_s)

    def stop(self) -> None:
        self._stop.set()
        self._queue.put(None)

    def on_exit(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on the worker thread when the service stops (persist state)."""
        self._exit_hooks.append(fn)

    def run(self) -> None:
        """Serve until SIGINT or SIGTERM: handle queued samples and timers on this thread."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self.stop())
        # The tokens go up once every handler is declared: live means listening.
        for rover in sorted(self.rovers):
            self._keep.append(self.session.liveliness().declare_token(keys.service(rover, self.name)))
        try:
            self._loop()
        finally:
            for hook in self._exit_hooks:
                self._guard(hook)
            self.close()

    def close(self) -> None:
        self._keep.clear()
        self._publishers.clear()
        if self.session is not None:
            self.session.close()
            self.session = None

    def _loop(self) -> None:
        while not self._stop.is_set():
            timeout = self._run_timers()
            try:
                item = self._queue.get(timeout=timeout)
            except queue.Empty:
                continue
            linger_until = time.monotonic() + self.batch_linger_s
            while item is not None:
                self._guard(*item)
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    wait = linger_until - time.monotonic() if self._after_batch else 0.0
                    try:
                        item = self._queue.get(timeout=wait) if wait > 0 else None
                    except queue.Empty:
                        item = None
            for hook in self._after_batch:
                self._guard(hook)

    def _run_timers(self) -> float:
        now = time.monotonic()
        wait = 0.25
        for timer in self._timers:
            period, due, fn = timer
            if now >= due:
                timer[1] = max(due + period, now)
                self._guard(fn)
            wait = min(wait, max(0.0, timer[1] - now))
        return wait

    def _guard(self, fn: Callable, *args: Any) -> None:
        """Run a handler; input errors become rejection events, bugs are reported, never fatal."""
        try:
            fn(*args)
        except BadInput as exc:
            sample = args[0] if args and isinstance(args[0], Sample) else None
            if sample is not None:
                self.reject(sample.rover, sample.key, str(exc))
        except Exception as exc:  # a bug must not take a training session down
            traceback.print_exc(file=sys.stderr)
            sample = args[0] if args and isinstance(args[0], Sample) else None
            rover = sample.rover if sample else next(iter(sorted(self.rovers)), "unknown")
            self.event(rover, "critical", "internal_error", sample.key if sample else "",
                       f"{self.name}: {type(exc).__name__}: {exc}")

    # -- scheduling -------------------------------------------------------------------------

    def after_batch(self, fn: Callable[[], None], linger_s: float = 0.0) -> None:
        """Call ``fn`` once the queue has run dry, having waited up to ``linger_s`` after the
        first sample of a batch for more to arrive (a burst of samples that each tick sends
        over a millisecond or so is then folded into one call)."""
        self._after_batch.append(fn)
        self.batch_linger_s = max(self.batch_linger_s, linger_s)

    def every(self, period_s: float, fn: Callable[[], None]) -> None:
        """Call ``fn`` on the worker thread every ``period_s`` of wall time. A timer that
        falls behind skips ahead instead of firing a burst of late calls."""
        self._timers.append([period_s, time.monotonic() + period_s, fn])

    def call_soon(self, fn: Callable, *args: Any) -> None:
        self._queue.put((fn, *args))

    # -- Zenoh ------------------------------------------------------------------------------

    def keep(self, entity: Any) -> None:
        """Hold a declared Zenoh entity for the life of the service."""
        self._keep.append(entity)

    def subscribe(self, keyexpr: str, handler: Handler, *, any_rover: bool = False,
                  history: bool = False) -> None:
        """Queue every sample on ``keyexpr`` for ``handler``; samples for rovers this service
        does not serve are dropped unless ``any_rover``. With ``history`` the publishers'
        caches are replayed first (an advanced subscriber), for a service that joins late."""
        assert self.session is not None, "open() first"

        def on_sample(s: zenoh.Sample) -> None:
            key = str(s.key_expr)
            try:
                rover, parts = keys.split(key)
            except ValueError:
                return
            if not any_rover and rover not in self.rovers:
                return
            att = s.attachment.to_bytes() if s.attachment is not None else None
            sample = Sample(key, rover, parts, s.payload.to_bytes(),
                            s.kind == zenoh.SampleKind.DELETE, att)
            self._queue.put((handler, sample))

        if history:
            self._keep.append(zext.declare_advanced_subscriber(
                self.session, keyexpr, on_sample,
                history=zext.HistoryConfig(detect_late_publishers=True),
                subscriber_detection=True))
        else:
            self._keep.append(self.session.declare_subscriber(keyexpr, on_sample))

    def queryable(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> None:
        """Answer queries on the worker thread (the model state is only read there)."""
        assert self.session is not None, "open() first"
        self._keep.append(
            self.session.declare_queryable(keyexpr, lambda q: self._queue.put((handler, q)))
        )

    def publish(self, key: str, msg: msgspec.Struct) -> None:
        self.publish_bytes(key, encode(msg), zenoh.Encoding.APPLICATION_JSON)

    def publish_bytes(self, key: str, payload: bytes, encoding: zenoh.Encoding,
                      attachment: bytes | None = None) -> None:
        """Publish an already encoded payload (CDR for the bridge), with the same last-value
        cache as :meth:`publish`."""
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._declare_publisher(key, 1, encoding)
        pub.put(payload, attachment=attachment)

    def _declare_publisher(self, key: str, cache: int,
                           encoding: zenoh.Encoding = zenoh.Encoding.APPLICATION_JSON) -> Any:
        pub = zext.declare_advanced_publisher(
            self.session, key,
            encoding=encoding,
            cache=zext.CacheConfig(max_samples=cache),
            publisher_detection=True,
        )
        self._publishers[key] = pub
        return pub

    # -- events and rejection ---------------------------------------------------------------

    def event(self, rover: str, severity: str, kind: str, key: str, message: str,
              params: dict | None = None) -> None:
        ekey = keys.event(rover)
        if ekey not in self._publishers:
            self._declare_publisher(ekey, EVENT_CACHE)
        self.publish(ekey, Event(t_s=self.now.get(rover, 0.0), severity=severity,
                                 source=self.name, kind=kind, key=key, message=message,
                                 params=params))

    def reject(self, rover: str, key: str, reason: str) -> None:
        """Refuse an input: nothing changes, and a warning event says why."""
        self.event(rover, "warning", "rejected", key, f"rejected: {reason}")

    # -- faults -----------------------------------------------------------------------------

    def handle_faults(
        self,
        component: str,
        names: Callable[[str], Iterable[str]] | None,
        apply: FaultApply,
    ) -> None:
        """Own the faults of one component type.

        ``names(rover)`` lists the component's instances (loads, rails ...) for the named
        types. ``apply(rover, key, params)`` changes the model; ``params`` is None to clear.
        Validation, the journal events and the registry of active faults are done here.
        """
        def on_fault(s: Sample) -> None:
            fk = parse_fault_key(s.parts[1:])
            if names is not None and fk.name not in set(names(s.rover)):
                known = ", ".join(sorted(names(s.rover))) or "none"
                raise BadInput(f"rover {s.rover} has no {component} {fk.name!r} (known: {known})")
            active = self.injected[s.rover]
            if s.deleted:
                if fk.path not in active:
                    raise BadInput(f"no active fault {fk.path} to clear")
                apply(s.rover, fk, None)
                del active[fk.path]
                self.event(s.rover, "info", "fault_cleared", s.key, f"cleared {fk.path}")
            else:
                params = parse_params(fk, s.payload)
                apply(s.rover, fk, params)
                replaced = fk.path in active
                active[fk.path] = ActiveFault(s.key, params, self.now[s.rover], "injected")
                verb = "replaced" if replaced else "injected"
                self.event(s.rover, "warning", "fault_injected", s.key,
                           f"{verb} {fk.path} {json.dumps(params)}", params)
            self._save_faults()

        # The owner answers for every key of its component, well formed or not.
        self.subscribe(f"{keys.ROOT}/*/fault/{component}/**", on_fault)
        self._fault_appliers[component] = apply

    def restore_faults(self) -> None:
        """Re-apply the injected faults persisted by an earlier run of this service."""
        saved = self.load_state("faults") or {}
        for rover, faults in saved.items():
            if rover not in self.rovers:
                continue
            for path, raw in faults.items():
                fault = msgspec.convert(raw, ActiveFault)
                fk = parse_fault_key(path.split("/"))
                apply = self._fault_appliers.get(fk.component)
                if apply is None:
                    continue
                apply(rover, fk, fault.params)
                self.injected[rover][path] = fault

    def _save_faults(self) -> None:
        self.save_state("faults", {r: {p: msgspec.structs.asdict(f) for p, f in fs.items()}
                                   for r, fs in self.injected.items()})

    def sync_derived(self, rover: str, component: str, active: dict[str, tuple[str, str]]) -> None:
        """Raise and resolve derived faults on transitions.

        ``active`` maps a fault name to ``(severity, message)`` for every derived fault of
        ``component`` (``battery``, ``rail/12V``) that holds now.
        """
        registry = self.derived[rover]
        prefix = f"{component}/"
        for name, (severity, message) in active.items():
            path = prefix + name
            if path not in registry:
                key = f"{keys.rover_prefix(rover)}/{path}"
                registry[path] = ActiveFault(key, {}, self.now[rover], "derived", severity)
                self.event(rover, severity, "fault_raised", key, message)
        for path in [p for p in registry if p.startswith(prefix)]:
            if path[len(prefix):] not in active:
                fault = registry.pop(path)
                self.event(rover, "info", "fault_resolved", fault.key, f"resolved {path}")

    # -- persisted state --------------------------------------------------------------------

    def _state_path(self, what: str) -> Path | None:
        if self.state_dir is None:
            return None
        return self.state_dir / f"{self.name}-{what}.json"

    def save_state(self, what: str, data: Any) -> None:
        path = self._state_path(what)
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(msgspec.json.encode(data))
        os.replace(tmp, path)  # atomic: a kill mid-write leaves the previous state

    def load_state(self, what: str) -> Any:
        path = self._state_path(what)
        if path is None or not path.is_file():
            return None
        try:
            return msgspec.json.decode(path.read_bytes())
        except msgspec.DecodeError:
            print(f"{self.name}: ignoring unreadable state {path}", file=sys.stderr)
            return None
