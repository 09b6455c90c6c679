"""The journal under a full disk (issue 32, SPEC 13e), on a real tmpfs, with real processes.

Found: the state folder on a tmpfs with ~400 KB free, a session, a fault and 3,000 marks:
the faults service died on ``OSError: [Errno 28] No space left on device`` at the journal's
append, ``lunaris up`` restarted it five times and marked it FAILED, no event told the
instructor, 422 marks were answered as recorded and none reached the disk; once space was
freed and the twin restarted, the session had lost its trainee's name and every event.

Now: the faults service stays up, says at once (a ``critical`` ``disk_full`` event) that the
journal cannot be written, answers a mark "not recorded: the disk is full", holds the
events in memory and writes them, in order, as soon as space returns (an ``info``
``disk_full`` event says so), without a restart; the session still names its trainee, also
once the faults service is restarted and reads its journal back.

The state folder is a tmpfs of 512 KB mounted for the test (root only: skipped otherwise)
and unmounted at its end, pass or fail; it is filled with a file the test deletes. The
services' logs are written elsewhere (a log on the full disk is not what is tested).
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from common import keys
from common.answers import Accepted
from common.writes import plan_write
from lunaris.client.mirror import Mirror
from lunaris.client.writer import Writer
from tests.harness import ALL_SERVICES, Probe, Twin
from tests.reliability.conftest import MAPP, R, restart

pytestmark = pytest.mark.timeout(180)

TMPFS_SIZE = "512k"


@contextlib.contextmanager
def small_disk(folder: Path) -> Iterator[Path]:
    """A tmpfs of ``TMPFS_SIZE`` mounted on ``folder``, unmounted at the end."""
    folder.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={TMPFS_SIZE}", "tmpfs", str(folder)],
                          capture_output=True, text=True, timeout=10)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {done.stderr.strip()}")
    try:
        yield folder
    finally:
        if subprocess.run(["umount", str(folder)], capture_output=True, timeout=10).returncode != 0:
            subprocess.run(["umount", "-l", str(folder)], capture_output=True, timeout=10)


def fill(folder: Path) -> Path:
    """A file that takes every byte left on the disk of ``folder``."""
    filler = folder / "filler"
    with open(filler, "wb", buffering=0) as f:
        chunk = b"\0" * 4096
        with contextlib.suppress(OSError):
            while True:
                f.write(chunk)
    with open(filler, "ab", buffering=0) as f, contextlib.suppress(OSError):
        while True:  # the last bytes, one at a time
            f.write(b"\0")
    return filler


def journal(p: Probe) -> list[dict]:
    replies = p.get_json(keys.faults_journal(R), timeout_s=10)
    return replies[0] if len(replies) == 1 else []


def mark(writer: Writer, text: str) -> Accepted:
    answer = writer.write(plan_write(R, "control/mark", json.dumps({"text": text}).encode()))
    assert isinstance(answer, Accepted), answer
    return answer


def test_a_full_disk_keeps_the_faults_service_up_and_says_what_is_not_recorded(router, probe_solo, tmp_path):
    p = probe_solo
    p.watch(keys.under(R, "event/**"))
    p.watch(keys.clock(R))
    with small_disk(tmp_path / "state") as state, \
            Twin(router, [MAPP], state, ALL_SERVICES, log_dir=tmp_path / "logs") as twin:
        try:
            _full_disk(p, twin, state)
        finally:
            twin.stop()


def _full_disk(p: Probe, twin: Twin, state: Path) -> None:
    p.wait_services(R, ALL_SERVICES)
    # a small disk: said before it is full
    low = p.wait_event(R, lambda e: e["kind"] == "disk_full" and e["severity"] == "warning",
                       timeout_s=15)
    assert "MB free" in low["message"]
    p.put(keys.control_session(R), {"trainee": "Ana"})
    opened = p.wait_event(R, lambda e: e["kind"] == "session" and e["source"] == "clock"
                          and (e.get("params") or {}).get("trainee") == "Ana", timeout_s=15)
    session = opened["session"]
    p.wait_value(keys.clock(R), lambda c: c["session"] == session)
    p.put(keys.fault(R, "battery", "heating"), {"heat_w": 5})
    p.wait_event(R, lambda e: e["kind"] == "fault_injected" and e["session"] == session, timeout_s=15)
    mirror = Mirror(R, families=("clock",), events=False).start(p.session)
    writer = Writer(p.session, mirror)
    try:
        assert writer.ready(R)
        before = mark(writer, "before the disk is full")
        assert before.recorded and not before.message.startswith("not recorded")
        filler = fill(state)
        # the disk full: the next marks are answered, not as recorded, the instructor told
        answers = [mark(writer, f"on a full disk #{i}") for i in range(20)]
        full = p.wait_event(R, lambda e: e["kind"] == "disk_full" and e["severity"] == "critical",
                            timeout_s=15)
        assert "No space left on device" in full["message"] and full["params"]["full"] is True
        assert full["actor"] == "twin" and full["message"].startswith(f"the journal of {R} cannot be written")
        unrecorded = [a for a in answers if not a.recorded]
        assert unrecorded, [a.message for a in answers]
        assert all(a.message.startswith("not recorded: the disk is full") for a in unrecorded)
        assert twin.procs["faults"].poll() is None, twin.log("faults")[-2000:]
        p.wait_services(R, ("faults",))
        # held in memory: still in the answer to the journal query
        assert any(e["kind"] == "mark" and "#19" in e["message"] for e in journal(p))
        # space returns, no restart: said, the held events written, the next mark recorded
        filler.unlink()
        back = p.wait_event(R, lambda e: e["kind"] == "disk_full" and e["severity"] == "info"
                            and (e.get("params") or {}).get("full") is False, timeout_s=15)
        assert "written again" in back["message"]
        after = mark(writer, "after space returned")
        assert after.recorded and after.message == "mark: after space returned"
        on_disk = [json.loads(line) for line in
                   (state / f"faults-journal-{R}.jsonl").read_text().splitlines()]
        texts = [(e.get("params") or {}).get("text") for e in on_disk if e["kind"] == "mark"]
        assert texts == ["before the disk is full", *(f"on a full disk #{i}" for i in range(20)),
                         "after space returned"]
        # every service rode it out (a state it could not save said, not fatal)
        assert {s: proc.poll() for s, proc in twin.procs.items()} == dict.fromkeys(ALL_SERVICES)
        p.wait_services(R, ALL_SERVICES)
    finally:
        writer.close()
        mirror.close()
    infos = p.get_json(keys.sessions(R))[0]
    mine = next(s for s in infos if s["id"] == session)
    assert mine["trainee"] == "Ana" and mine["events"] >= 23, infos
    # and after a restart of the faults service, read back from the disk
    restart(twin, p, "faults")
    again = next(s for s in p.get_json(keys.sessions(R))[0] if s["id"] == session)
    assert again["trainee"] == "Ana" and again["events"] >= mine["events"]
    assert sum(e["kind"] == "mark" for e in journal(p)) == 22
