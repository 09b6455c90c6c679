"""What the journal keeps of a flood of rejections: the logic, without files or clocks.

Every event of a session goes into the journal, but a flood of bad input (a fuzzer, a
misbehaving dashboard) must not bury the session's history. :class:`FloodGate` lets the
first ``burst`` rejections of any ``window_s`` of wall time through one by one, counts
the rest, and hands back one summary event for them when the window closes, saying how
many were summarised, over which span of sim time, on which keys and why.
"""

from __future__ import annotations

from collections import Counter

from common.messages import Event

__all__ = ["FloodGate"]


class FloodGate:
    def __init__(self, burst: int = 50, window_s: float = 1.0):
        self.burst, self.window_s = burst, window_s
        self._window_start = -1e300
        self._passed = 0
        self._held: list[Event] = []
        self._keys: Counter[str] = Counter()

    def offer(self, ev: Event, now_s: float) -> list[Event]:
        """The events to write now for ``ev`` received at wall time ``now_s``: the event
        itself, nothing (counted for a summary), and a summary of the last window first
        when a new window begins."""
        out = self.flush(now_s)
        if ev.kind != "rejected":
            return out + [ev]
        if now_s - self._window_start >= self.window_s:
            self._window_start, self._passed = now_s, 0
        if self._passed < self.burst:
            self._passed += 1
            return out + [ev]
        self._held.append(ev)
        self._keys[ev.key] += 1
        return out

    def flush(self, now_s: float, force: bool = False) -> list[Event]:
        """The summary of the held rejections once their window is over (or ``force``)."""
        if not self._held or (not force and now_s - self._window_start < self.window_s):
            return []
        first, last = self._held[0], self._held[-1]
        top = ", ".join(f"{k} x{n}" for k, n in self._keys.most_common(3))
        spans: dict[str, list[int]] = {}  # source_id -> [first seq, last seq] summarised
        for ev in self._held:
            span = spans.setdefault(ev.source_id, [ev.seq, ev.seq])
            span[0], span[1] = min(span[0], ev.seq), max(span[1], ev.seq)
        summary = Event(
            t_s=last.t_s, severity="warning", source=first.source, kind="rejected", key=last.key,
            message=f"{len(self._held)} more rejections summarised (sim t {first.t_s:.1f} to "
                    f"{last.t_s:.1f} s; {top}); the last: {last.message}",
            params={"summarised": len(self._held), "from_t_s": first.t_s, "to_t_s": last.t_s,
                    "keys": dict(self._keys.most_common(10)), "seq": spans},
            session=last.session)
        self._held, self._keys = [], Counter()
        return [summary]
