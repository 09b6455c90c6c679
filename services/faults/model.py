"""What the journal keeps of a flood: the logic, without files or clocks.

Every event of a session goes into the journal, but a flood (a fuzzer's bad input, a
misbehaving dashboard's thousand crew calls a second) must not bury the session's history
nor fill the disk. A :class:`FloodGate` folds one sort of event: the first ``burst`` of any
``window_s`` of wall time pass one by one, the rest are counted, and one summary event for
them is handed back when the window closes, saying how many were summarised, over which
span of sim time, on which keys, and the last of them. The journal has two gates: bad input
of any actor (the default: 50 a second), and the crew's accepted commands
(:func:`crew_commands`). Every event folded is still answered live by its service; only the journal folds.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from common.messages import Event

__all__ = ["CREW_BURST", "FloodGate", "crew_commands"]

CREW_BURST = 20  # crew commands a second journalled one by one; the rest summarised


class FloodGate:
    """Folds the events ``folds`` picks (by default: rejections); the summary is an event of
    their kind whose ``params`` say ``summarised`` (how many), ``seq`` (per ``source_id`` the
    span of ``seq`` folded), ``keys``, ``from_t_s`` and ``to_t_s``."""

    def __init__(self, burst: int = 50, window_s: float = 1.0,
                 folds: Callable[[Event], bool] | None = None, noun: str = "rejections"):
        self.burst, self.window_s = burst, window_s
        self.folds = folds or (lambda ev: ev.kind == "rejected")
        self.noun = noun
        self._window_start = -1e300
        self._passed = 0
        self._held: list[Event] = []
        self._keys: Counter[str] = Counter()

    def offer(self, ev: Event, now_s: float) -> list[Event]:
        """The events to write now for ``ev`` received at wall time ``now_s``: the event
        itself, nothing (counted for a summary), and a summary of the last window first
        when a new window begins."""
        out = self.flush(now_s)
        if not self.folds(ev):
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
        """The summary of the held events once their window is over (or ``force``)."""
        if not self._held or (not force and now_s - self._window_start < self.window_s):
            return []
        first, last = self._held[0], self._held[-1]
        top = ", ".join(f"{k} x{n}" for k, n in self._keys.most_common(3))
        spans: dict[str, list[int]] = {}  # source_id -> [first seq, last seq] summarised
        for ev in self._held:
            span = spans.setdefault(ev.source_id, [ev.seq, ev.seq])
            span[0], span[1] = min(span[0], ev.seq), max(span[1], ev.seq)
        params = {"summarised": len(self._held), "from_t_s": first.t_s, "to_t_s": last.t_s,
                  "keys": dict(self._keys.most_common(10)), "seq": spans}
        if last.kind == "command" and last.params:  # the rail's state after the last of them
            params.update({k: v for k, v in last.params.items() if k in ("on", "reset", "state")})
        summary = Event(
            t_s=last.t_s, severity=last.severity if last.kind != "rejected" else "warning",
            source=first.source, kind=last.kind, key=last.key,
            message=f"{len(self._held)} more {self.noun} summarised (sim t {first.t_s:.1f} to "
                    f"{last.t_s:.1f} s; {top}); the last: {last.message}",
            params=params, actor=last.actor if last.kind != "rejected" else "",
            session=last.session)
        self._held, self._keys = [], Counter()
        return [summary]


def crew_commands(burst: int = CREW_BURST) -> FloodGate:
    """The gate of the crew's accepted commands (a dashboard calling a rail's set_enabled a
    thousand times a second wrote ~1.1 GB of journal an hour): ``burst`` a second one by one,
    the rest summarised ("N more crew commands summarised ... cmd/rail/5V_CH2 x980")."""
    return FloodGate(burst, folds=lambda ev: ev.kind == "command" and ev.actor == "crew",
                     noun="crew commands")
