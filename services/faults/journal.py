"""The journal of a rover's session on disk: every event, in order, bounded only by the disk.

One JSON line per event in ``<state-dir>/faults-journal-<rover>.jsonl``, appended as events
come and read back when the faults service restarts, so the whole session's history
survives restarts of any service. A flood of rejections is summarised
(:class:`~services.faults.model.FloodGate`). Events replayed from the publishers' caches
after a restart are recognised and not written twice. Without a state directory the
journal is kept in memory for the life of the service.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import msgspec

from common.messages import Event
from services.faults.model import FloodGate

__all__ = ["Journal"]

_RECENT = 4096  # identities of the latest events, to recognise a replayed cache


def _identity(ev: Event) -> tuple:
    return (ev.source_id, ev.seq) if ev.source_id else (ev.t_s, ev.source, ev.kind, ev.key, ev.message)


class Journal:
    def __init__(self, path: Path | None = None, gate: FloodGate | None = None):
        self.path = path
        self.gate = gate or FloodGate()
        self._memory: list[bytes] = []
        self._recent: deque[tuple] = deque(maxlen=_RECENT)
        self._recent_set: set[tuple] = set()
        self._spans: dict[str, list[tuple[int, int]]] = {}  # summarised seqs per source
        self.count = 0
        self.summarised = 0
        if path is not None and path.is_file():
            for line in path.read_bytes().splitlines():
                self._note(msgspec.json.decode(line, type=Event))

    def _note(self, ev: Event) -> None:
        self._remember(_identity(ev))
        self.count += 1
        params = ev.params or {}
        if ev.kind == "rejected" and "summarised" in params:
            self.summarised += int(params["summarised"])
            for source_id, (lo, hi) in (params.get("seq") or {}).items():
                self._spans.setdefault(source_id, []).append((int(lo), int(hi)))

    def _remember(self, ident: tuple) -> None:
        if len(self._recent) == self._recent.maxlen:
            self._recent_set.discard(self._recent[0])
        self._recent.append(ident)
        self._recent_set.add(ident)

    def _known(self, ev: Event) -> bool:
        """Already journalled, one by one or in a summary (a cache replayed after a restart)."""
        if not ev.source_id:
            return False
        if _identity(ev) in self._recent_set:
            return True
        return any(lo <= ev.seq <= hi for lo, hi in self._spans.get(ev.source_id, ()))

    def record(self, ev: Event, now_s: float) -> list[Event]:
        """Journal ``ev``, received at wall time ``now_s``, unless it is already in; the
        events written (to relay: it, nothing while a flood is held, a summary)."""
        if self._known(ev):
            return []  # replayed from a cache after a restart
        self._remember(_identity(ev))  # written now, or counted into a summary to come
        return self._write(self.gate.offer(ev, now_s))

    def tick(self, now_s: float) -> list[Event]:
        """Write the summary of a flood that has ended; the events written."""
        return self._write(self.gate.flush(now_s))

    def _write(self, events: list[Event]) -> list[Event]:
        if not events:
            return events
        lines = [msgspec.json.encode(ev) for ev in events]
        for ev in events:
            self._note(ev)
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
