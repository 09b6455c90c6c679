"""The journal when the disk refuses it (issue 32, SPEC 13e), without processes: a disk that
fails ``os.write`` with ENOSPC half-way through a line, then takes writes again.

The process test (tests/reliability/test_disk_full.py) fills a real tmpfs; here the
journal's own account: no torn line left, the events held in order and answered to the
queries, a write's answer saying it is not recorded, what could not be held counted in a
``journal_gap``, everything written at the first tick that can.
"""

from __future__ import annotations

import errno
import os
import types

import msgspec
import pytest

import services.faults.journal as journal_module
from common.messages import Event
from services.faults.journal import Journal

SESSION = "20260101-000000"


class _Disk:
    """``os`` as the journal uses it, whose ``write`` fails with ENOSPC after ``room`` bytes."""

    def __init__(self) -> None:
        self.room: int | None = None  # None: no limit

    def module(self) -> types.SimpleNamespace:
        def write(fd: int, data: bytes | memoryview) -> int:
            if self.room is None:
                return os.write(fd, data)
            if self.room <= 0:
                raise OSError(errno.ENOSPC, "No space left on device")
            n = os.write(fd, bytes(data[:self.room]))
            self.room -= n
            return n
        names = {n: getattr(os, n) for n in dir(os) if not n.startswith("__")}
        return types.SimpleNamespace(**{**names, "write": write})


@pytest.fixture
def disk(monkeypatch) -> _Disk:
    d = _Disk()
    monkeypatch.setattr(journal_module, "os", d.module())
    return d


def ev(seq: int, kind: str = "input", source: str = "solar", actor: str = "instructor", **more) -> Event:
    return Event(t_s=float(seq), severity="info", source=source, kind=kind, key="lunaris/r/input/x",
                 message=f"#{seq}", source_id=source, seq=seq, actor=actor, session=SESSION, **more)


def opening() -> Event:
    return Event(t_s=0.0, severity="info", source="clock", kind="session", key="lunaris/r/control/session",
                 message="begins", params={"session": SESSION, "trainee": "Ana", "started_wall": 1.0,
                                           "start_t_s": 0.0},
                 source_id="clock", seq=1, actor="instructor", session=SESSION)


def decoded(lines: list[bytes]) -> list[Event]:
    return [msgspec.json.decode(line, type=Event) for line in lines]


def test_a_full_disk_holds_the_events_and_writes_them_when_space_returns(tmp_path, disk):
    path = tmp_path / "faults-journal-r.jsonl"
    j = Journal(path, rover="r")
    j.record(opening(), 0.0)
    j.record(ev(1), 0.0)
    whole = path.read_bytes()
    disk.room = 10  # the next line is cut short by the disk
    assert j.record(ev(2), 1.0) and j.disk_error == "No space left on device"
    assert path.read_bytes() == whole  # no torn line left
    mark = j.record(ev(1, kind="mark", source="faults"), 1.0)[0]
    assert mark.message.startswith("not recorded: the disk is full (No space left on device); #1")
    assert mark.params == {"recorded": False}
    assert [e.message for e in decoded(j.lines(SESSION))][-2:] == ["#2", mark.message]
    assert j.tick(2.0) == [] and j.disk_error is not None  # still full: still held
    disk.room = None
    assert j.tick(3.0) == [] and j.disk_error is None and not j.held
    again = Journal(path, rover="r")
    assert [e.message for e in decoded(again.lines())][2:] == ["#2", mark.message]
    assert again.session_infos()[0].trainee == "Ana" and again.damage is None


def test_what_cannot_be_held_is_counted_in_a_journal_gap(tmp_path, disk):
    path = tmp_path / "faults-journal-r.jsonl"
    j = Journal(path, rover="r", hold_max=3)
    disk.room = 0
    for seq in range(1, 8):
        j.record(ev(seq), 0.0)
    j.record(opening(), 0.0)  # a session's opening is held beyond the bound
    assert len(j.held) == 4 and sum(j.dropped.values()) == 4
    assert j.ledger.known("solar", 7)  # accounted for: never journalled twice from a cache
    disk.room = None
    gap = j.tick(1.0)
    assert [e.kind for e in gap] == ["journal_gap"]
    assert gap[0].params is not None and gap[0].params["lost"] == 4
    assert gap[0].params["by_source"] == {"solar": 4} and "the disk was full" in gap[0].message
    kinds = [e.kind for e in decoded(Journal(path, rover="r").lines())]
    assert kinds == ["input", "input", "input", "session", "journal_gap"]


def test_a_journal_that_cannot_be_rewritten_is_kept_as_found(tmp_path, disk, monkeypatch):
    """A torn last line read back on a full disk: the file stays (cut after its last whole
    line), rather than moved aside with the session's events in it."""
    path = tmp_path / "faults-journal-r.jsonl"
    good = msgspec.json.encode(opening()) + b"\n" + msgspec.json.encode(ev(1)) + b"\n"
    path.write_bytes(good + b'{"t_s": 2.0, "sev')

    def refused(*_: object, **__: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(journal_module, "write_atomically", refused)
    j = Journal(path, rover="r")
    assert path.read_bytes() == good and j.session_infos()[0].trainee == "Ana"
    assert j.damage is not None and "the file kept where it is, cut after its last whole line" in j.damage
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
