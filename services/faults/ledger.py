"""Which events of each source the journal has accounted for, and which it never will get.

Every event a service publishes for a rover carries ``(source_id, seq)``: its session's
Zenoh id and a count from 1, per rover (:meth:`common.runtime.Runtime.event`). The journal
accounts for each: written one by one, counted into a flood's summary, or - when it never
arrives - counted as lost. :class:`Ledger` keeps, per source, the highest ``seq`` up to which
everything is accounted for and the ones accounted above it; a hole below one that arrived
is a gap. A gap may still fill (the publishers' caches replayed after the faults service
restarts or its link returns: Zenoh's advanced subscriber asks each publisher again), so it
is declared lost only after ``wait_s`` of wall time without filling, and then said once, in a
``journal_gap`` event that counts it. Pure: the caller gives the wall time.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["Gap", "Ledger"]

GAP_WAIT_S = 5.0  # how long a hole may wait for a replayed cache before it is counted lost


class Gap(NamedTuple):
    source_id: str
    source: str  # the service whose events these were
    first: int  # seq
    last: int


class _Source:
    __slots__ = ("above", "hole_since", "name", "upto")

    def __init__(self, name: str):
        self.name = name
        self.upto = 0  # every seq <= upto is accounted for
        self.above: set[int] = set()  # accounted for, above upto
        self.hole_since: float | None = None  # when a hole below ``above`` was first seen

    def settle(self) -> None:
        while self.upto + 1 in self.above:
            self.upto += 1
            self.above.discard(self.upto)
        if not self.above:
            self.hole_since = None


class Ledger:
    def __init__(self, wait_s: float = GAP_WAIT_S):
        self.wait_s = wait_s
        self._sources: dict[str, _Source] = {}

    def _source(self, source_id: str, name: str) -> _Source:
        src = self._sources.get(source_id)
        if src is None:
            src = self._sources[source_id] = _Source(name)
        return src

    def known(self, source_id: str, seq: int) -> bool:
        """Whether ``seq`` of that source is accounted for already."""
        src = self._sources.get(source_id)
        return src is not None and (seq <= src.upto or seq in src.above)

    def account(self, source_id: str, name: str, first: int, last: int, now_s: float) -> None:
        """``first..last`` of a source are accounted for (an event: ``first == last``)."""
        src = self._source(source_id, name)
        if first <= src.upto + 1:
            if last > src.upto:
                if last > src.upto + 1:  # a range: what it covers above is accounted for now
                    src.above = {s for s in src.above if s > last}
                src.above.discard(last)
                src.upto = last
        else:
            src.above.update(range(first, last + 1))
        src.settle()
        if src.above and src.hole_since is None:
            src.hole_since = now_s

    def gaps(self, now_s: float, force: bool = False) -> list[Gap]:
        """The holes that waited ``wait_s`` (or all, ``force``) without filling: each counted
        as lost, now accounted for."""
        out = []
        for source_id, src in self._sources.items():
            if not src.above or src.hole_since is None:
                continue
            if not force and now_s - src.hole_since < self.wait_s:
                continue
            first, last = src.upto + 1, min(src.above) - 1
            out.append(Gap(source_id, src.name, first, last))
            src.upto = last
            src.settle()
            src.hole_since = now_s if src.above else None
        return out
