"""The journal's trainee sessions (SPEC §12c): which session each journalled event belongs to,
and what ``get lunaris/<rover>/sessions`` lists. The logic, without files or Zenoh.

Every event carries the session its service was in (``Event.session``, from the clock's
ticks). The clock opens each session with a ``session`` event whose ``params`` say it
(``session``, ``trainee``, ``from_snapshot``, ``started_wall``, ``start_t_s``), and closes the
one that ends with another (``params``: ``session``, ``trainee``, ``end_t_s``).
:class:`SessionIndex` reads the events in the journal's order:

- an event names its session; a session id not seen before is a new segment, the running
  one from then on when it is later than the running one (ids are the UTC time each began,
  ``YYYYMMDD-HHMMSS``, growing: a late event of an ended session never makes it run again);
- an event without a session (a service that had heard no tick yet, a journal written before
  sessions) belongs to the session running when it was journalled, or, before any session is
  known, to the first one that comes;
- a session's trainee, start and wall time come from the event that opened it, its end from
  the event that closed it; without them (the journal lost them), its first and last
  events' sim times stand in.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from common.events import session_opened
from common.messages import Event, SessionInfo

__all__ = ["SessionIndex"]


@dataclass
class _Segment:
    id: str
    trainee: str = ""
    start_t_s: float | None = None  # from the event that opened it
    end_t_s: float | None = None  # from the event that closed it
    first_t_s: float = 0.0  # sim time of its first and last events journalled
    last_t_s: float = 0.0
    started_wall: float | None = None
    from_snapshot: str | None = None
    events: int = 0


class SessionIndex:
    """The sessions of one rover's journal, and the session of each of its lines, in order."""

    def __init__(self) -> None:
        self._segments: dict[str, _Segment] = {}  # in the order they were first seen
        self.running = ""  # the latest session seen ("" before any)
        self.of_line: list[str] = []  # the session of each journal line ("": not known yet)
        self._unplaced: list[Event] = []  # events journalled before any session was known

    def note(self, ev: Event) -> str:
        """Place the next journal line's event; its session ("" until one is known)."""
        sid = ev.session or self.running
        if not sid:
            self.of_line.append("")
            self._unplaced.append(ev)
            return ""
        seg = self._segments.get(sid)
        if seg is None:
            seg = self._segments[sid] = _Segment(sid, first_t_s=ev.t_s)
            if not self.running or sid > self.running:
                self.running = sid
            if self._unplaced:  # the events before the first session known are its own
                self.of_line = [s or sid for s in self.of_line]
                for early in self._unplaced:
                    self._count(seg, early)
                seg.first_t_s = self._unplaced[0].t_s
                self._unplaced.clear()
        self.of_line.append(sid)
        self._count(seg, ev)
        opened = session_opened(ev)  # the one rule the tools and the response read it by
        if opened is not None and opened[0] == sid:
            self._opened(seg, opened[1], ev.params or {})
        elif (end := _ends(ev, sid)) is not None:
            seg.end_t_s = end
        return sid

    def _count(self, seg: _Segment, ev: Event) -> None:
        seg.events += 1
        seg.last_t_s = ev.t_s

    def _opened(self, seg: _Segment, trainee: str, p: dict[str, Any]) -> None:
        seg.trainee = trainee
        seg.start_t_s = _number(p.get("start_t_s"))
        seg.started_wall = _number(p.get("started_wall"))
        snapshot = p.get("from_snapshot")
        seg.from_snapshot = str(snapshot) if snapshot else None

    def known(self, sid: str) -> bool:
        return sid in self._segments

    def ids(self) -> list[str]:
        return list(self._segments)

    def infos(self, running: str = "") -> list[SessionInfo]:
        """Every session, oldest first; ``running`` (default: the latest seen) has no end.
        A running session the journal has no event of yet (the clock's ticks said it first)
        is listed last, with what is known."""
        running = running or self.running
        out = []
        for seg in self._segments.values():
            start = seg.start_t_s if seg.start_t_s is not None else seg.first_t_s
            end = None if seg.id == running else (
                seg.end_t_s if seg.end_t_s is not None else seg.last_t_s)
            out.append(SessionInfo(id=seg.id, trainee=seg.trainee, start_t_s=start, end_t_s=end,
                                   started_wall=seg.started_wall, from_snapshot=seg.from_snapshot,
                                   events=seg.events))
        if running and running not in self._segments:
            out.append(SessionInfo(id=running, trainee="", start_t_s=0.0, end_t_s=None,
                                   started_wall=None))
        return out


def _ends(ev: Event, sid: str) -> float | None:
    """The end (sim time) of session ``sid`` if ``ev`` is the clock's event that closes it."""
    p = ev.params
    if ev.kind == "session" and ev.source == "clock" and isinstance(p, dict) and p.get(
            "session") == sid and "started_wall" not in p:
        return _number(p.get("end_t_s"))
    return None


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None
