"""What makes an event the same event, wherever it was read (DECISIONS D1).

A service publishes its events on ``lunaris/<rover>/event/<service>``; the faults service
republishes each journalled event unchanged on ``lunaris/<rover>/event``, and the publishers'
caches replay recent ones to a late joiner or after a reconnection. A reader of more than one
of these hears an event several times: :func:`event_identity` names it, ``(source_id, seq)``
(the publishing session and its count), and :class:`EventWindow` remembers the identities of
the latest events, a bounded number of them, so each is taken once. The offline reader of a
recording (:mod:`lunaris.report`) uses the same identity. (In :mod:`common`: the tools and the
bridge, which awaits the answers to the crew's writes, share it.)
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable, Mapping
from typing import Any

from common.messages import Event

__all__ = ["EVENT_WINDOW", "EventWindow", "event_identity", "source_mismatch"]

EVENT_WINDOW = 4096  # identities remembered: far more than the publishers' caches replay (256 each)


def event_identity(rover: str, ev: Event | Mapping[str, Any]) -> Hashable:
    """``(source_id, seq)`` of an event (a Struct or its JSON object). An event of a publisher
    that does not number its events (an older one) is named by what it says and when."""
    get = ev.get if isinstance(ev, Mapping) else lambda name, default=None: getattr(ev, name, default)
    source_id = get("source_id", "") or ""
    if source_id:
        return (source_id, get("seq", 0))
    return (rover, get("t_s"), get("source"), get("kind"), get("key"), get("message"))


def source_mismatch(parts: list[str] | tuple[str, ...], ev: Event) -> str | None:
    """Why an event read on ``lunaris/<rover>/<parts>`` is not to be believed, or None: on a
    service's own key (``event/<service>``) its ``source`` must be that service (D1); the
    journal's key (``event``) is the faults service's alone, its events already checked."""
    if len(parts) == 1 and parts[0] == "event":
        return None
    if len(parts) == 2 and parts[0] == "event":
        if ev.source != parts[1]:
            return f"an event of source {ev.source!r} on the key of service {parts[1]!r}"
        return None
    return "not an event key"


class EventWindow:
    """The identities of the latest ``size`` events taken; :meth:`first` says whether an
    event is new. Not thread-safe: the caller holds its own lock."""

    def __init__(self, size: int = EVENT_WINDOW):
        self._order: deque[Hashable] = deque()
        self._seen: set[Hashable] = set()
        self.size = size

    def first(self, ident: Hashable) -> bool:
        """True the first time ``ident`` is offered (within the window), False after."""
        if ident in self._seen:
            return False
        if len(self._order) >= self.size:
            self._seen.discard(self._order.popleft())
        self._order.append(ident)
        self._seen.add(ident)
        return True

    def __len__(self) -> int:
        return len(self._order)
