"""Whether a rover is reachable now, judged from its clock (DECISIONS D3).

The clock of a rover ticks at its ``tick_hz`` even while paused, so a rover whose ticks stop
arriving is cut off (a partition, a router gone, the clock stopped). Its link is *lost* when no
tick has arrived for :data:`LINK_TIMEOUT_S` (longer for a clock that ticks slower than twice in
that time) or when its clock's liveliness token went away; *up* again with the next tick. Zenoh
takes its lease (about 10 s) to notice a cut; the ticks tell within 2 s, so a tool that looks
at least twice a second shows the loss within 3 s. Pure: the caller gives the wall time.
"""

from __future__ import annotations

import statistics
import time
from collections import deque
from typing import Literal, NamedTuple

__all__ = ["LINK_TIMEOUT_S", "Link", "LinkState", "LinkTracker", "clock_time"]

LINK_TIMEOUT_S = 2.0  # no tick for this long: the link is lost
_SLOW_FACTOR = 2.5  # a slow clock: lost after this many of its intervals without a tick
_GAPS = 5  # the latest gaps between ticks; their median is the clock's interval (an outage is one)

LinkState = Literal["unknown", "up", "lost"]


def clock_time(t: float) -> str:
    """A wall time as the user's clock shows it: ``14:02:11``."""
    return time.strftime("%H:%M:%S", time.localtime(t))


class Link(NamedTuple):
    """A rover's link: ``up``, ``lost`` or ``unknown`` (no tick seen yet), since when (wall
    time, None while unknown) and why, in words."""

    state: LinkState
    since: float | None
    reason: str

    def as_json(self) -> dict[str, object]:
        return {"state": self.state, "since": self.since, "reason": self.reason}


class LinkTracker:
    """One rover's link, from its clock's ticks and its clock's liveliness token."""

    def __init__(self, timeout_s: float = LINK_TIMEOUT_S):
        self.timeout_s = timeout_s
        self.last_tick: float | None = None
        self.gaps: deque[float] = deque(maxlen=_GAPS)  # the latest gaps between ticks [s]
        self.clock_alive: bool | None = None  # None: its token never seen
        self.clock_changed: float | None = None  # when the token came or went
        self.up_since: float | None = None

    def limit_s(self) -> float:
        """How long without a tick before the link counts as lost: :data:`LINK_TIMEOUT_S`, or
        for a clock that ticks slower than that, a few of its usual intervals."""
        if len(self.gaps) < 3:
            return self.timeout_s
        return max(self.timeout_s, _SLOW_FACTOR * statistics.median(self.gaps))

    def tick(self, now: float) -> None:
        last = self.last_tick
        if last is None or now - last > self.limit_s() or self.up_since is None:
            self.up_since = now
        if last is not None and now > last:
            self.gaps.append(now - last)
        self.last_tick = now

    def clock_token(self, alive: bool, now: float) -> None:
        if alive != self.clock_alive:
            self.clock_alive, self.clock_changed = alive, now
            if not alive:
                self.up_since = None

    def state(self, now: float) -> Link:
        if self.clock_alive is False:
            since = self.clock_changed if self.clock_changed is not None else now
            return Link("lost", since, f"its clock service is unreachable since {clock_time(since)} "
                                       "(its liveliness token went away)")
        if self.last_tick is None:
            seen = self.clock_changed if self.clock_alive else None
            waited = now - seen if seen is not None else 0.0
            if waited > self.limit_s():
                return Link("lost", seen, f"no clock tick within {waited:.0f} s of its "
                                                        "clock service being seen")
            return Link("unknown", None, "no clock tick received yet")
        if now - self.last_tick > self.limit_s():
            return Link("lost", self.last_tick, f"no clock tick since {clock_time(self.last_tick)} "
                                                f"({now - self.last_tick:.0f} s)")
        return Link("up", self.up_since if self.up_since is not None else self.last_tick,
                    "clock ticking")
