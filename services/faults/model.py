"""The fault journal: every event of a session, and the faults active now.

Built only from ``event`` samples: ``fault_injected`` / ``fault_cleared`` for
the instructor's faults, ``fault_raised`` / ``fault_resolved`` for the faults
the models derive themselves.
"""

from __future__ import annotations

from collections import deque

from common.messages import Event
from common.runtime import ActiveFault

__all__ = ["Journal"]


class Journal:
    def __init__(self, max_events: int = 10000):
        self.events: deque[Event] = deque(maxlen=max_events)
        self.active: dict[str, ActiveFault] = {}

    def record(self, ev: Event) -> None:
        self.events.append(ev)
        if ev.kind == "fault_injected":
            prev = self.active.get(ev.key)
            since = prev.since_t_s if prev is not None else ev.t_s
            self.active[ev.key] = ActiveFault(ev.key, ev.params or {}, since, "injected",
                                              ev.severity)
        elif ev.kind == "fault_raised":
            if ev.key not in self.active:
                self.active[ev.key] = ActiveFault(ev.key, ev.params or {}, ev.t_s, "derived",
                                                  ev.severity)
        elif ev.kind in ("fault_cleared", "fault_resolved"):
            self.active.pop(ev.key, None)

    def active_faults(self) -> list[ActiveFault]:
        return sorted(self.active.values(), key=lambda f: (f.since_t_s, f.key))
