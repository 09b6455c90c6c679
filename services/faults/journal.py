"""The journal of a rover's session on disk: every event, in order, bounded only by the disk.

One JSON line per event in ``<state-dir>/faults-journal-<rover>.jsonl``, appended as events
come and read back when the faults service restarts, so the whole session's history
survives restarts of any service. A flood of rejections is summarised
(:class:`~services.faults.model.FloodGate`). Every event is accounted for by its
``(source_id, seq)`` (:class:`~services.faults.ledger.Ledger`): events replayed from the
publishers' caches after a restart are recognised and not written twice, and those that
never come back (beyond what a cache kept) are counted and said in a ``journal_gap`` event:
every event journalled one by one, summarised, or counted lost. Without a state directory
the journal is kept in memory for the life of the service.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import msgspec

from common import keys
from common.messages import Event
from services.faults.ledger import Gap, Ledger
from services.faults.model import FloodGate

__all__ = ["Journal"]

_RECENT = 4096  # identities of the latest events, to recognise a replayed cache


def _identity(ev: Event) -> tuple:
    return (ev.source_id, ev.seq) if ev.source_id else (ev.t_s, ev.source, ev.kind, ev.key, ev.message)


class Journal:
    def __init__(self, path: Path | None = None, gate: FloodGate | None = None, rover: str = "",
                 ledger: Ledger | None = None):
        self.path = path
        self.rover = rover
        self.gate = gate or FloodGate()
        self.ledger = ledger or Ledger()
        self._memory: list[bytes] = []
        self._recent: deque[tuple] = deque(maxlen=_RECENT)  # events without a source_id
        self._recent_set: set[tuple] = set()
        self._last_t_s = 0.0
        self.count = 0
        self.summarised = 0
        self.lost = 0  # events counted lost in journal_gap events
        if path is not None and path.is_file():
            for line in path.read_bytes().splitlines():
                self._note(msgspec.json.decode(line, type=Event), 0.0)

    def _note(self, ev: Event, now_s: float) -> None:
        """A written event, accounted for (and what a summary or a gap counts)."""
        self._account(ev, now_s)
        self.count += 1
        self._last_t_s = max(self._last_t_s, ev.t_s)
        params = ev.params or {}
        if ev.kind == "rejected" and "summarised" in params:
            self.summarised += int(params["summarised"])
            for source_id, (lo, hi) in (params.get("seq") or {}).items():
                self.ledger.account(source_id, ev.source, int(lo), int(hi), now_s)
        elif ev.kind == "journal_gap":
            self.lost += int(params.get("lost", 0))
            self.ledger.account(str(params.get("source_id", "")), str(params.get("source", "")),
                                int(params.get("from_seq", 0)), int(params.get("to_seq", 0)), now_s)

    def _account(self, ev: Event, now_s: float) -> None:
        if ev.source_id:
            self.ledger.account(ev.source_id, ev.source, ev.seq, ev.seq, now_s)
            return
        ident = _identity(ev)
        if len(self._recent) == self._recent.maxlen:
            self._recent_set.discard(self._recent[0])
        self._recent.append(ident)
        self._recent_set.add(ident)

    def _known(self, ev: Event) -> bool:
        """Already accounted for: journalled one by one, in a summary, or counted lost (a
        cache replayed after a restart)."""
        if ev.source_id:
            return self.ledger.known(ev.source_id, ev.seq)
        return _identity(ev) in self._recent_set

    def record(self, ev: Event, now_s: float) -> list[Event]:
        """Journal ``ev``, received at wall time ``now_s``, unless it is already in; the
        events written (to relay: it, nothing while a flood is held, a summary)."""
        if self._known(ev):
            return []  # replayed from a cache after a restart
        self._account(ev, now_s)  # written now, or counted into a summary to come
        return self._write(self.gate.offer(ev, now_s), now_s)

    def tick(self, now_s: float, flood_over: bool = False) -> list[Event]:
        """Write the summary of a flood that has ended (``flood_over``: any flood held) and
        count the events that have not come back within the ledger's wait; the events
        written."""
        written = self.gate.flush(now_s, force=flood_over)
        written += [self._gap_event(gap) for gap in self.ledger.gaps(now_s)]
        return self._write(written, now_s)

    def _gap_event(self, gap: Gap) -> Event:
        n = gap.last - gap.first + 1
        what = f"{n} event{'s' if n > 1 else ''} of the {gap.source} service"
        return Event(
            t_s=self._last_t_s, severity="warning", source="faults", kind="journal_gap",
            key=keys.event_of(self.rover or "?", gap.source or "?"),
            message=f"{what} (seq {gap.first} to {gap.last}) never reached the journal: lost "
                    "while the faults service was down or cut off, beyond what the service "
                    "kept for it; counted here, not listed",
            params={"lost": n, "source": gap.source, "source_id": gap.source_id,
                    "from_seq": gap.first, "to_seq": gap.last})

    def _write(self, events: list[Event], now_s: float) -> list[Event]:
        if not events:
            return events
        lines = [msgspec.json.encode(ev) for ev in events]
        for ev in events:
            self._note(ev, now_s)
        if self.path is None:
            self._memory.extend(lines)
            return events
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("ab") as f:
            f.write(b"".join(line + b"\n" for line in lines))
        return events

    def lines(self) -> list[bytes]:
        """Every journalled event as its JSON text, oldest first."""
        if self.path is None:
            return list(self._memory)
        if not self.path.is_file():
            return []
        return self.path.read_bytes().splitlines()
