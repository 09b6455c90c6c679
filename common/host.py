"""What the fault book and the session keeper need of the service they serve: :class:`Host`, a
protocol the one runtime (:class:`common.runtime.Runtime`) satisfies, and :class:`Sample`, the
sample it hands its handlers.

The fault book (:mod:`common.fault_book`) and the session keeper (:mod:`common.session`) are
parts of the runtime, made by it; they depended on :class:`~common.runtime.Runtime` itself, and
the house had one circle, ``runtime -> fault_book -> runtime`` (issue 30: a real import of the
runtime added to the fault book still passed the layer tests, which waived that edge). They
depend on this protocol now, which imports nothing of the runtime: the layer contract
(``tests/architecture/test_layers.py``) holds with no waiver and fails when the circle closes
again.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import msgspec
import zenoh

from common.messages import ActiveFault, EventKind, Severity
from common.state_store import StateStore

__all__ = ["Faults", "Handler", "Host", "Sample"]


class Sample(NamedTuple):
    key: str
    rover: str
    parts: list[str]  # the key's chunks after lunaris/<rover>/
    payload: bytes
    deleted: bool
    attachment: bytes | None = None
    sent_at: float | None = None  # a write's Zenoh timestamp [s since the epoch]; None: none
    age_s: float = 0.0  # how long after sent_at the write arrived here [s]


Handler = Callable[[Sample], None]


class Faults(Protocol):
    """What the session keeper asks of the fault book (:class:`common.fault_book.FaultBook`)."""

    def clear_all(self, rover: str) -> None: ...

    def reinject(self, rover: str, fault: ActiveFault) -> None: ...

    def publish(self, rover: str) -> None: ...

    def injected_faults(self, rover: str) -> list[ActiveFault]: ...


class Host(Protocol):
    """The service a fault book or a session keeper belongs to (its runtime)."""

    name: str
    rovers: set[str]
    t_s: dict[str, float]
    epoch: dict[str, int]
    session_id: dict[str, str]
    store: StateStore

    @property
    def faults(self) -> Faults: ...

    @property
    def has_faults(self) -> bool: ...

    def save_state(self, what: str, data: Any, durable: bool = True) -> bool: ...

    def state_damaged(self, rover: str, message: str, key: str | None = None,
                      params: dict | None = None, severity: Severity = "critical") -> None: ...

    def enter_session(self, rover: str, session: str) -> None: ...

    def on_exit(self, fn: Callable[[], None]) -> None: ...

    def every(self, period_s: float, fn: Callable[[], None]) -> None: ...

    def subscribe(self, keyexpr: str, handler: Handler, *, any_rover: bool = False,
                  history: bool = False, telemetry: bool = False, urgent: bool = False,
                  writes: Any = ..., urgent_if: Callable[[Sample], bool] | None = None) -> None: ...

    def queryable(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> None: ...

    def publish(self, key: str, msg: msgspec.Struct, *, reliable: bool = False,
                cache: int = 1) -> None: ...

    def event(self, rover: str, severity: Severity, kind: EventKind, key: str, message: str,
              params: dict | None = None, *, actor: str | None = None,
              t_s: float | None = None) -> None: ...

    def events_after(self) -> contextlib.AbstractContextManager[list[tuple[tuple, dict]]]: ...

