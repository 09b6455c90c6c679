"""The journal of a rover's session on disk: every event, in order, bounded only by the disk.

One JSON line per event in ``<state-dir>/faults-journal-<rover>.jsonl``, appended as events
come and read back when the faults service restarts, so the whole session's history
survives restarts of any service. A damaged journal (a last line cut short by a kill
mid-write, a line that is not an event, a folder in place of the file) never keeps the
service down: the intact lines are kept, the file as found is moved aside
(``.damaged-<time>``), a new one holds the intact lines, and :attr:`Journal.damage` says
what was found, for the service to say in a ``critical`` event. A flood of rejections is
summarised, and so is a flood of the crew's accepted commands (two
:class:`~services.faults.model.FloodGate`). Every event is accounted for by its
``(source_id, seq)`` (:class:`~services.faults.ledger.Ledger`): events replayed from the
publishers' caches after a restart are recognised and not written twice, and those that
never come back (beyond what a cache kept) are counted and said in a ``journal_gap`` event:
every event journalled one by one, summarised, or counted lost. Without a state directory
the journal is kept in memory for the life of the service.

A disk that refuses a line (full: ``ENOSPC``, or any other ``OSError``) never stops the
service: the append is cut back to the last whole line (no torn line is left for the next
start to set aside), the events are held in memory (``HOLD_MAX`` of them; a session's
opening and closing events beyond that too) and written, in order, at the first
:meth:`Journal.tick` that can write them; those that could not be held are counted, by
source, in a ``journal_gap`` event written with them. :attr:`Journal.disk_error` says, in
words, why the journal is not being written (None while it is). The events held are
answered to the queries as if written. An answer of the faults service to a write (a mark)
that is held says so: "not recorded: the disk is full (...)", ``params.recorded`` false.

The journal is in segments, one per trainee session (:class:`~services.faults.sessions.SessionIndex`):
:meth:`Journal.lines` gives one session's events, :meth:`Journal.session_infos` the sessions.
"""

from __future__ import annotations

import os
from collections import Counter, deque
from pathlib import Path

import msgspec

from common import keys
from common.messages import Event, SessionInfo
from common.state_store import fsync_folder, set_aside, write_atomically
from services.faults.ledger import Gap, Ledger
from services.faults.model import FloodGate, crew_commands
from services.faults.sessions import SessionIndex

__all__ = ["Journal"]

_RECENT = 4096  # identities of the latest events, to recognise a replayed cache
HOLD_MAX = 20_000  # events held in memory while the disk refuses them (~0.4 kB each: ~8 MB)
_ANSWERS = ("mark", "session", "scenario")  # this service's answers to writes (a rejection aside)
_KEPT = ("session",)  # held beyond HOLD_MAX (a session's trainee must survive), up to twice it


def _answers_a_write(ev: Event) -> bool:
    """Whether ``ev`` is this service's answer to someone's write (a mark, a session control, a
    scenario's mark): the writer takes it as "recorded"."""
    return ev.source == "faults" and ev.actor not in ("", "twin") and ev.kind in _ANSWERS


def _identity(ev: Event) -> tuple:
    return (ev.source_id, ev.seq) if ev.source_id else (ev.t_s, ev.source, ev.kind, ev.key, ev.message)


class Journal:
    def __init__(self, path: Path | None = None, gate: FloodGate | None = None, rover: str = "",
                 ledger: Ledger | None = None, crew_gate: FloodGate | None = None,
                 hold_max: int = HOLD_MAX):
        self.path = path
        self.rover = rover
        self.gate = gate or FloodGate()
        self.crew_gate = crew_gate or crew_commands()
        self.ledger = ledger or Ledger()
        self.hold_max = hold_max
        self.held: list[bytes] = []  # lines the disk refused, in order, to write when it takes them
        self.disk_error: str | None = None  # why the journal is not written now (None: it is)
        self.dropped: Counter[str] = Counter()  # per source, events that could not be held
        self._dropped_t_s: list[float] = []  # the sim time of the first and last dropped
        self._memory: list[bytes] = []
        self._recent: deque[tuple] = deque(maxlen=_RECENT)  # events without a source_id
        self._recent_set: set[tuple] = set()
        self._last_t_s = 0.0
        self.sessions = SessionIndex()
        self.count = 0
        self.summarised = 0
        self.lost = 0  # events counted lost in journal_gap events
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
            self._note(ev, 0.0)
            good.append(line)
        if not bad and not tail.strip():
            return
        torn = bool(tail.strip()) and (not good or good[-1] is not tail)
        moved = set_aside(path)
        where = None
        try:
            write_atomically(path, b"".join(line + b"\n" for line in good))
        except OSError as exc:
            # a full disk: the file as found goes back, cut after its last whole line (a
            # truncate needs no space), rather than the session's events left aside
            print(f"journal: cannot write {path} ({exc}): the file is kept as found", flush=True)
            if moved is not None:
                os.replace(moved, path)
                if torn:
                    os.truncate(path, len(raw) - len(tail))
                moved = None
            where = (f"the file kept where it is{', cut after its last whole line' if torn else ''}: "
                     f"the disk refused a new one ({exc.strerror or exc})")
        what = (f"{bad} damaged line{'s' if bad != 1 else ''}"
                + (" (the last one cut short)" if torn else "") if bad
                else "its last line had no end of line")
        self.damage = (f"{path.name}: {what}; {len(good)} event{'s' if len(good) != 1 else ''} "
                       f"kept{', the damaged lines left out' if bad else ''}; {where or _where(moved)}")

    def _note(self, ev: Event, now_s: float) -> None:
        """A written event, accounted for (and what a summary or a gap counts)."""
        self._account(ev, now_s)
        self.count += 1
        self.sessions.note(ev)
        self._last_t_s = max(self._last_t_s, ev.t_s)
        params = ev.params or {}
        if ev.kind in ("rejected", "command") and "summarised" in params:
            self.summarised += int(params["summarised"])
            for source_id, (lo, hi) in (params.get("seq") or {}).items():
                self.ledger.account(source_id, ev.source, int(lo), int(hi), now_s)
        elif ev.kind == "journal_gap":
            self.lost += int(params.get("lost", 0))
            if params.get("source_id"):  # (one of the disk's counts many sources, accounted)
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
        gate = self.crew_gate if self.crew_gate.folds(ev) else self.gate
        other = self.gate if gate is self.crew_gate else self.crew_gate
        return self._write(other.flush(now_s) + gate.offer(ev, now_s), now_s)

    def tick(self, now_s: float, flood_over: bool = False) -> list[Event]:
        """Write what the disk refused, if it takes it now; the summary of a flood that has
        ended (``flood_over``: any flood held) and count the events that have not come back
        within the ledger's wait; the events written (the held ones not again)."""
        written = self._write_held()
        written += self.gate.flush(now_s, force=flood_over)
        written += self.crew_gate.flush(now_s, force=flood_over)
        written += [self._gap_event(gap) for gap in self.ledger.gaps(now_s)]
        return self._write(written, now_s)

    def _write_held(self) -> list[Event]:
        """The held lines written, if the disk takes them now (the journal_gap of those that
        could not be held, to write after them)."""
        if not self.held or self.path is None:
            return []
        try:
            self._append(self.held)
        except OSError as exc:
            self.disk_error = _said(exc)
            return []
        self.held, self.disk_error = [], None
        if not self.dropped:
            return []
        n = sum(self.dropped.values())
        first_t, last_t = self._dropped_t_s
        by = ", ".join(f"{src or '?'} {k}" for src, k in self.dropped.most_common())
        gap = Event(
            t_s=self._last_t_s, severity="warning", source="faults", kind="journal_gap",
            key=keys.faults_journal(self.rover or "?"),
            message=f"{n} event{'s' if n > 1 else ''} (sim t {first_t:.1f} to {last_t:.1f} s; "
                    f"{by}) never reached the journal: the disk was full and the faults service "
                    f"held {self.hold_max} events in memory at most; counted here, not listed",
            params={"lost": n, "source": "", "by_source": dict(self.dropped), "reason": "disk_full",
                    "from_t_s": first_t, "to_t_s": last_t}, session=self.sessions.running)
        self.dropped, self._dropped_t_s = Counter(), []
        return [gap]

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
                    "from_seq": gap.first, "to_seq": gap.last}, session=self.sessions.running)

    def _write(self, events: list[Event], now_s: float) -> list[Event]:
        """Write ``events`` (or hold them: see the module); those written or held."""
        if not events:
            return events
        if self.path is None:
            for ev in events:
                self._note(ev, now_s)
            self._memory.extend(msgspec.json.encode(ev) for ev in events)
            return events
        if self.disk_error is None:
            lines = [msgspec.json.encode(ev) for ev in events]
            try:  # an answer to a write is on the disk before it is answered (SPEC 13e)
                self._append(lines, sync=any(_answers_a_write(ev) for ev in events))
            except OSError as exc:
                self.disk_error = _said(exc)
            else:
                for ev in events:
                    self._note(ev, now_s)
                return events
        kept = []
        for ev in map(self._unrecorded, events):
            if len(self.held) < self.hold_max or (ev.kind in _KEPT and len(self.held) < 2 * self.hold_max):
                self._note(ev, now_s)
                self.held.append(msgspec.json.encode(ev))
                kept.append(ev)
            else:  # accounted for (never journalled again from a cache), counted lost
                self.dropped[ev.source] += 1
                self._dropped_t_s = [self._dropped_t_s[0] if self._dropped_t_s else ev.t_s, ev.t_s]
        return kept

    def _unrecorded(self, ev: Event) -> Event:
        """An answer of this service to a write (a mark, a session control), held: it says,
        to whoever wrote, that it is not recorded (SPEC 13e), and keeps saying so in the
        journal once written."""
        if not _answers_a_write(ev):
            return ev
        return msgspec.structs.replace(
            ev, message=f"not recorded: the disk is full ({self.disk_error}); {ev.message}; held "
                        "in memory, written to the journal when space returns",
            params={**(ev.params or {}), "recorded": False})

    def _append(self, lines: list[bytes], sync: bool = True) -> None:
        """Append whole lines to the file; on an OSError (a full disk) the file is cut back to
        what it was, so that no torn line is left, and the error raised. With ``sync`` the
        lines are on the disk when it returns (``fsync``; the folder's entry too when the file
        is new): a power cut loses nothing answered (tests/reliability/test_power_cut.py)."""
        assert self.path is not None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not os.path.lexists(self.path)
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            size = os.fstat(fd).st_size
            view = memoryview(b"".join(line + b"\n" for line in lines))
            try:
                while view:
                    view = view[os.write(fd, view):]
                if sync or new:
                    os.fsync(fd)
            except OSError:
                os.ftruncate(fd, size)
                raise
        finally:
            os.close(fd)
        if new:
            fsync_folder(self.path.parent)

    def lines(self, session: str | None = None) -> list[bytes]:
        """Every journalled event as its JSON text, oldest first; of one session only when
        ``session`` is given."""
        if self.path is None:
            lines = list(self._memory)
        elif not self.path.is_file():
            lines = list(self.held)
        else:
            lines = self.path.read_bytes().splitlines() + self.held
        if session is None:
            return lines
        placed = self.sessions.of_line
        if len(placed) != len(lines):  # the file changed under the journal: read each line
            placed = [_session_of(line) for line in lines]
        return [line for line, sid in zip(lines, placed, strict=True) if sid == session]

    def session_infos(self, running: str = "") -> list[SessionInfo]:
        """The sessions of the journal (:class:`~common.messages.SessionInfo`), oldest first."""
        return self.sessions.infos(running)


class _SessionOnly(msgspec.Struct):
    session: str = ""


def _session_of(line: bytes) -> str:
    try:
        return msgspec.json.decode(line, type=_SessionOnly).session
    except (msgspec.DecodeError, msgspec.ValidationError):
        return ""


def _said(exc: OSError) -> str:
    """Why the disk refused, in words: "No space left on device" (ENOSPC)."""
    return exc.strerror or str(exc)


def _where(moved: Path | None) -> str:
    return f"the file as found was moved to {moved.name}" if moved else "the file could not be moved aside"
