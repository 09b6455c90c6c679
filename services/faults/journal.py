"""The journal of a rover's session on disk: every event, in order, bounded only by the disk.

One JSON line per event in ``<state-dir>/faults-journal-<rover>.jsonl``, appended as events
come and read back when the faults service restarts, so the whole session's history
survives restarts of any service. A damaged journal (a last line cut short by a kill
mid-write, a line that is not an event, a folder in place of the file) never keeps the
service down: the intact lines are kept, the file as found is moved aside
(``.damaged-<time>``), a new one holds the intact lines, and :attr:`Journal.damage` says
what was found, for the service to say in a ``critical`` event. A flood of rejections is summarised
(:class:`~services.faults.model.FloodGate`). Events replayed from the publishers' caches
after a restart are recognised and not written twice. Without a state directory the
journal is kept in memory for the life of the service.
"""

from __future__ import annotations

import os
from collections import deque
from pathlib import Path

import msgspec

from common.messages import Event
from common.state_store import set_aside, write_atomically
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
        self.damage: str | None = None  # what was wrong with the file read back, in words
        if path is not None and os.path.lexists(path):
            self._read_back(path)

    def _read_back(self, path: Path) -> None:
        """Journal again every intact line of ``path``; set the rest aside (see the module)."""
        try:
            if path.is_dir():
                raise OSError("a folder in place of the file")
            raw = path.read_bytes()
        except OSError as exc:
            moved = set_aside(path)
            self.damage = (f"{path.name} unreadable ({exc.strerror or exc}): the journal starts "
                           f"anew; {_where(moved)}")
            return
        lines = raw.split(b"\n")
        tail = lines.pop()  # what follows the last newline: nothing, unless cut short
        good: list[bytes] = []
        bad = 0
        for line in [*lines, tail] if tail.strip() else lines:
            if not line.strip():
                continue
            try:
                ev = msgspec.json.decode(line, type=Event)
            except (msgspec.DecodeError, msgspec.ValidationError):
                bad += 1
                continue
            self._note(ev)
            good.append(line)
        if not bad and not tail.strip():
            return
        torn = bool(tail.strip()) and (not good or good[-1] is not tail)
        moved = set_aside(path)
        try:
            write_atomically(path, b"".join(line + b"\n" for line in good))
        except OSError as exc:  # the next event starts a new file
            print(f"journal: cannot write {path} ({exc})", flush=True)
        what = (f"{bad} damaged line{'s' if bad != 1 else ''}"
                + (" (the last one cut short)" if torn else "") if bad
                else "its last line had no end of line")
        self.damage = (f"{path.name}: {what}; {len(good)} event{'s' if len(good) != 1 else ''} "
                       f"kept{', the damaged lines left out' if bad else ''}; {_where(moved)}")

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

    def record(self, ev: Event, now_s: float) -> None:
        """Journal ``ev``, received at wall time ``now_s``, unless it is already in."""
        if self._known(ev):
            return  # replayed from a cache after a restart
        self._remember(_identity(ev))  # written now, or counted into a summary to come
        self._write(self.gate.offer(ev, now_s))

    def tick(self, now_s: float) -> None:
        """Write the summary of a flood that has ended."""
        self._write(self.gate.flush(now_s))

    def _write(self, events: list[Event]) -> None:
        if not events:
            return
        lines = [msgspec.json.encode(ev) for ev in events]
        for ev in events:
            self._note(ev)
        if self.path is None:
            self._memory.extend(lines)
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("ab") as f:
            f.write(b"".join(line + b"\n" for line in lines))

    def lines(self) -> list[bytes]:
        """Every journalled event as its JSON text, oldest first."""
        if self.path is None:
            return list(self._memory)
        if not self.path.is_file():
            return []
        return self.path.read_bytes().splitlines()


def _where(moved: Path | None) -> str:
    return f"the file as found was moved to {moved.name}" if moved else "the file could not be moved aside"
