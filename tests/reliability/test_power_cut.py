"""A power cut at any moment loses nothing answered (SPEC 13e), tested the way storage engines
test theirs (SQLite's crash-test file system, LazyFS): a disk that keeps what was written but
not synced only until the power goes.

:class:`PowerCutDisk` stands between the state store and the journal and the operating system
(their module's ``os``): every call goes through to the real files, and beside them it keeps
what a power cut would leave, as POSIX promises it and no more: a file's data once it is
``fsync``-ed, a name in a folder (a new file, a rename) once the folder is ``fsync``-ed; data
written and not synced is kept only as a random part of it (a torn write). The power goes off
at a chosen call of a workload (a write cut short at a random byte); what the disk holds then
is laid out in a folder of its own and read back as a restarted service reads it.

What must hold, for each of the cut points: every state saved and answered is found again (or
a later one), every journal line answered (an instructor's mark) is found again, and every
state and journal file opens (the journal sets a torn last line aside and keeps the rest)."""

from __future__ import annotations

import os
import random
from pathlib import Path
from typing import Any

import msgspec
import pytest

import common.state_store as state_store
import services.faults.journal as journal_module
from common.messages import Event
from common.state_store import StateStore
from services.faults.journal import Journal

pytestmark = [pytest.mark.unit, pytest.mark.timeout(120)]

R = "mapp-1"
CUTS = 60  # cut points tried per workload, spread over its calls


class Crash(Exception):
    """The power went off."""


class PowerCutDisk:
    """``os`` for the modules under test, with what a power cut would leave kept beside."""

    COUNTED = ("write", "fsync", "replace", "ftruncate")

    def __init__(self, root: Path, cut_at: int | None, rng: random.Random):
        self.root, self.cut_at, self.rng = root, cut_at, rng
        self.calls = 0
        self.data: dict[int, bytes] = {}  # inode -> its content as last synced
        self.names: dict[str, int] = {}  # path -> inode, as last synced in its folder

    def __getattr__(self, name: str) -> Any:
        return getattr(os, name)

    def _count(self, name: str) -> None:
        self.calls += 1
        if self.cut_at is not None and self.calls >= self.cut_at:
            raise Crash(f"power cut at call {self.calls} ({name})")

    def write(self, fd: int, data: Any) -> int:
        if self.cut_at is not None and self.calls + 1 >= self.cut_at:
            torn = bytes(data)[:self.rng.randrange(len(data) + 1)]
            os.write(fd, torn)  # part of it reached the page cache
        self._count("write")
        return os.write(fd, data)

    def ftruncate(self, fd: int, size: int) -> None:
        self._count("ftruncate")
        os.ftruncate(fd, size)

    def replace(self, src: Any, dst: Any) -> None:
        self._count("replace")
        os.replace(src, dst)

    def fsync(self, fd: int) -> None:
        self._count("fsync")
        os.fsync(fd)
        target = Path(os.readlink(f"/proc/self/fd/{fd}"))
        if target.is_dir():  # the folder's names as they are now
            for name in [p for p in self.names if Path(p).parent == target]:
                del self.names[name]
            for entry in target.iterdir():
                self.names[str(entry)] = entry.stat().st_ino
        else:
            self.data[os.fstat(fd).st_ino] = Path(f"/proc/self/fd/{fd}").read_bytes()

    def after_the_cut(self, into: Path) -> None:
        """Lay out in ``into`` what the disk holds after the power came back: each name synced
        in its folder, with its data synced and a random part of what was written after."""
        for name, ino in self.names.items():
            rel = Path(name).relative_to(self.root)
            kept = self.data.get(ino, b"")
            path = Path(name)
            if path.is_file() and path.stat().st_ino == ino:
                now = path.read_bytes()
                if now.startswith(kept):  # appended since: some of it may have reached the disk
                    kept += now[len(kept):len(kept) + self.rng.randrange(len(now) - len(kept) + 1)]
            (into / rel).parent.mkdir(parents=True, exist_ok=True)
            (into / rel).write_bytes(kept)


@pytest.fixture
def disk(monkeypatch):
    """Put a :class:`PowerCutDisk` under the state store and the journal; yields a function
    making one for a root folder and a cut point."""
    def make(root: Path, cut_at: int | None, seed: int) -> PowerCutDisk:
        d = PowerCutDisk(root, cut_at, random.Random(seed))
        monkeypatch.setattr(state_store, "os", d)
        monkeypatch.setattr(journal_module, "os", d)
        return d
    return make


def _states(folder: Path, answered: list[int]) -> None:
    store = StateStore(folder, "battery")
    for n in range(1, 13):
        store.save("state", {"n": n, "soc": 1.0 - n / 100}, durable=True)
        answered.append(n)  # saved: the service goes on as if it is on the disk
        store.save("time", {"t_s": n * 0.1}, durable=False)  # the clock's time: not synced on purpose


def _journal(folder: Path, answered: list[str]) -> None:
    j = Journal(folder / f"faults-journal-{R}.jsonl", rover=R)
    for i in range(1, 13):
        alarm = Event(t_s=i, severity="warning", source="power", kind="fault_raised",
                      key=f"lunaris/{R}/rail/5V/tripped", message="tripped", source_id="p", seq=i,
                      actor="twin")
        j.record(alarm, float(i))  # the twin's own: not an answer to anyone
        mark = Event(t_s=i + 0.5, severity="info", source="faults", kind="mark",
                     key=f"lunaris/{R}/control/mark", message=f"mark {i}", source_id="f", seq=i,
                     actor="instructor")
        j.record(mark, float(i))
        answered.append(f"mark {i}")  # the service answers the instructor once record returns


@pytest.mark.parametrize("workload", ["states", "journal"])
def test_a_power_cut_at_any_moment_loses_nothing_answered_and_every_file_opens(tmp_path, disk, workload):
    run = _states if workload == "states" else _journal
    whole = disk(tmp_path / "count", None, 0)
    run(tmp_path / "count", [])
    calls = whole.calls
    assert calls > 20, calls
    cuts = sorted({round(1 + k * (calls - 1) / (CUTS - 1)) for k in range(CUTS)})
    for cut in cuts:
        root, after = tmp_path / f"run-{cut}", tmp_path / f"after-{cut}"
        root.mkdir()
        after.mkdir()
        d = disk(root, cut, cut)
        answered: list[Any] = []
        with pytest.raises(Crash):
            run(root, answered)
        d.cut_at = None  # the power is back: the files are read as a restarted service reads them
        d.after_the_cut(after)
        where = f"cut at call {cut} of {calls}, {len(answered)} answered"
        if workload == "states":
            found = StateStore(after, "battery").load("state")
            if answered:
                assert found is not None and found["n"] >= answered[-1], (where, found)
        else:
            back = Journal(after / f"faults-journal-{R}.jsonl", rover=R)
            texts = [msgspec.json.decode(line)["message"] for line in back.lines()]
            lost = [a for a in answered if a not in texts]
            assert not lost, (where, lost, back.damage)


def test_the_disk_loses_what_was_not_synced(tmp_path, disk):
    """The disk itself: a line appended and not synced is gone or torn after the cut, a file
    renamed in a folder not synced since is the old one: the test above can fail."""
    root = tmp_path / "root"
    root.mkdir()
    d = disk(root, None, 1)
    path = root / "f"
    state_store.write_atomically(path, b"old", durable=True)
    fd = os.open(root / "log", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    d.write(fd, b"synced\n")
    d.fsync(fd)
    state_store.fsync_folder(root)
    d.write(fd, b"lost\n")
    os.close(fd)
    state_store.write_atomically(path, b"new", durable=False)
    after = tmp_path / "after"
    after.mkdir()
    d.after_the_cut(after)
    assert (after / "f").read_bytes() == b"old"
    log = (after / "log").read_bytes()
    assert log.startswith(b"synced\n") and len(log) <= len(b"synced\nlost\n")
    assert not (after / ".f.tmp").exists()
