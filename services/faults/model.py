"""The journal: every event of a training session, in order.

Built only from ``event`` samples. The faults in effect are not kept here: each service
keeps the record of its own components' faults (``common.fault_book``); the faults
service gathers them when asked.
"""

from __future__ import annotations

from collections import deque

from common.messages import Event

__all__ = ["Journal"]


class Journal:
    def __init__(self, max_events: int = 10000):
        self.events: deque[Event] = deque(maxlen=max_events)

    def record(self, ev: Event) -> None:
        self.events.append(ev)
