"""A write on the twin and its answer, without Zenoh: the one copy of the waiting.

Every writer that waits for the twin's answer (the tools' :class:`lunaris.client.Writer`, the
bridge's crew controls) keeps its writes in flight in an :class:`Awaiting` and hands it each
event it reads on a service's own key (``lunaris/<rover>/event/<service>``, DECISIONS D1) or
the journal's; what answers a write is :func:`answers`: its rejection, by its owner or the
gatekeeper, or the accepting event from its owner (:func:`common.writes.answer_of`, the one
table of which event answers which write). The answer is one of

- :class:`Accepted`: the accepting event (``fault_injected``, ``command``, ``input`` ...);
- :class:`Rejected`: the ``rejected`` event, and its reason in words;
- :class:`NotApplied`: the write did not reach its owner, or nothing answered in time, and why
  (the writer says which: it knows the owner's liveliness).

A write is waited for :data:`ANSWER_S` at most: longer than the ``WRITE_MAX_AGE_S`` after
which an owner refuses a write that arrives late (DECISIONS D3), so "not applied" is the
truth: the twin refuses it if it arrives later.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from common.events import EVENT_WINDOW, EventWindow, event_identity, source_mismatch
from common.messages import Event, humane
from common.writes import Write

__all__ = ["ANSWER_S", "Accepted", "Answer", "Awaiting", "NotApplied", "Pending", "Rejected",
           "answers"]

ANSWER_S = 3.0  # how long a write waits for its answer: longer than the 2 s of WRITE_MAX_AGE_S


@dataclass(frozen=True)
class Accepted:
    """The owner applied the write; ``event`` says what it did."""

    write: Write
    event: Event

    @property
    def message(self) -> str:
        return self.event.message

    @property
    def recorded(self) -> bool:
        """False when the answer says the write could not be recorded (the journal's disk
        full, SPEC 13e: "not recorded: the disk is full ..."): applied, not on disk."""
        return (self.event.params or {}).get("recorded") is not False


@dataclass(frozen=True)
class Rejected:
    """The twin refused the write; nothing changed. ``message``: the reason in words."""

    write: Write
    event: Event

    @property
    def message(self) -> str:
        return humane(self.event.message.removeprefix("rejected: "))


@dataclass(frozen=True)
class NotApplied:
    """The write did not take effect and will not: ``reason`` says why. ``unreachable``: the
    owner is known to be out of reach (else nothing answered in time); ``sent``: it was sent."""

    write: Write
    reason: str
    unreachable: bool
    sent: bool

    @property
    def message(self) -> str:
        return self.reason


Answer = Accepted | Rejected | NotApplied


@dataclass
class Pending:
    """A write sent and waiting for its answer."""

    write: Write
    deadline: float  # monotonic
    on_answer: Callable[[Answer], None] | None = None
    answer: Answer | None = None
    done: threading.Event = field(default_factory=threading.Event)


def answers(write: Write, ev: Event) -> bool:
    """Whether ``ev`` is the answer to ``write``: its rejection (by its owner or the
    gatekeeper), or the accepting event from its owner."""
    if ev.key != write.key:
        return False
    return ev.kind == "rejected" or (ev.kind == write.accepted and ev.source == write.owner)


class Awaiting:
    """The writes in flight and the events that answer them; thread-safe. Each event is taken
    once by its identity (``(source_id, seq)``: a reader of the journal's key and of the
    services' own hears each twice), and answers the oldest write it answers."""

    def __init__(self, window: int = EVENT_WINDOW):
        self._lock = threading.Lock()
        self._pending: list[Pending] = []
        self._window = EventWindow(window)

    def __len__(self) -> int:
        with self._lock:
            return len(self._pending)

    def add(self, p: Pending) -> Pending:
        """Wait for the answer to ``p`` (add it before sending: the answer may come at once)."""
        with self._lock:
            self._pending.append(p)
        return p

    def settle(self, p: Pending, answer: Answer) -> bool:
        """Give ``p`` its answer, unless it has one: the first answer wins. Wakes its waiters
        and calls its ``on_answer`` (on this thread). Whether this answer was the one."""
        with self._lock:
            if p.answer is not None:
                return False
            p.answer = answer
            if p in self._pending:
                self._pending.remove(p)
        p.done.set()
        if p.on_answer is not None:
            p.on_answer(answer)
        return True

    def hear(self, rover: str, parts: list[str] | tuple[str, ...], ev: Event) -> Pending | None:
        """An event read on ``lunaris/<rover>/<parts>``: the write it answers, now settled, or
        None. An event on a service's key that does not come from that service is no answer."""
        if source_mismatch(parts, ev) is not None:
            return None
        with self._lock:  # every event is remembered: its copy on the journal's key is no answer
            if not self._window.first(event_identity(rover, ev)) or not self._pending:
                return None
            match = next((p for p in self._pending if answers(p.write, ev)), None)
            if match is None:
                return None
        self.settle(match, Rejected(match.write, ev) if ev.kind == "rejected"
                    else Accepted(match.write, ev))
        return match

    def withdraw(self, p: Pending) -> Answer | None:
        """Stop waiting for ``p``: its answer if it came, else None (the caller settles it)."""
        with self._lock:
            if p.answer is None and p in self._pending:
                self._pending.remove(p)
            return p.answer

    def overdue(self, now: float) -> list[Pending]:
        """The writes whose deadline (monotonic) has passed without an answer, no longer
        waited for: the caller settles each (not applied, and why)."""
        with self._lock:
            late = [p for p in self._pending if p.deadline <= now]
            for p in late:
                self._pending.remove(p)
        return late
