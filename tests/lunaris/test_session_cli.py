"""``lunaris session start|list``, ``lunaris mark``, and the tools in a trainee's session
(SPEC §12c): ``lunaris watch`` names the trainee and shows the session's events only; a
recording covers every session it saw, each event with its session."""

from __future__ import annotations

import json
import signal
import subprocess

import pytest
from mcap.reader import make_reader

from common import keys
from tests.harness import ROOT, env_without_zenoh_config, lunaris_cmd
from tests.lunaris.conftest import R, run_tool

pytestmark = pytest.mark.timeout(180)


def test_sessions_and_marks_from_the_command_line(live, tmp_path):
    p, ep = live.probe, live.endpoint
    path = tmp_path / "day.mcap"
    rec = subprocess.Popen(lunaris_cmd("record", str(path), "--rover", R, "--connect", ep),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                           env=env_without_zenoh_config(), stdin=subprocess.DEVNULL)
    try:
        assert rec.stderr is not None and rec.stderr.readline().startswith("recording lunaris/")
        done = run_tool("session", "start", R, "--trainee", "Finn", "--connect", ep)
        assert done.returncode == 0, done.stdout + done.stderr
        assert "accepted: session" in done.stdout and "of 'Finn' begins" in done.stdout
        done = run_tool("mark", R, "finn", "trips", "the", "camera", "--connect", ep)
        assert done.returncode == 0 and "mark: finn trips the camera" in done.stdout, done.stdout

        done = run_tool("session", "start", R, "--trainee", "Eve O'Neill", "--connect", ep)
        assert done.returncode == 0 and "of \"Eve O'Neill\" begins" in done.stdout, done.stdout
        eve = json.loads(run_tool("session", "list", R, "--json", "--connect", ep).stdout)[-1]["id"]
        p.wait_value(keys.clock(R), lambda c: c["session"] == eve)
        done = run_tool("mark", R, "eve isolates the rail", "--connect", ep)
        assert done.returncode == 0 and "mark: eve isolates the rail" in done.stdout, done.stdout
        p.wait_event(R, lambda e: e["kind"] == "mark" and "eve isolates" in e["message"])
    finally:
        rec.send_signal(signal.SIGINT)
        rec.communicate(timeout=20)
    assert rec.returncode == 0

    # refused before sending (exit 1), or by the twin in words (exit 1)
    bad = run_tool("session", "start", R, "--trainee", "a/b", "--connect", ep)
    assert bad.returncode == 1 and "this one has '/'" in bad.stderr, bad.stderr
    bad = run_tool("session", "start", R, "--connect", ep)
    assert bad.returncode == 1 and "needs --trainee" in bad.stderr
    bad = run_tool("session", "start", R, "--trainee", "Gus", "--from-snapshot", "not saved", "--connect", ep)
    assert bad.returncode == 1 and "has a space" in bad.stderr
    bad = run_tool("session", "start", R, "--trainee", "Gus", "--from-snapshot", "nope", "--connect", ep)
    assert bad.returncode == 1 and "not begun" in bad.stdout and "no snapshot 'nope'" in bad.stdout
    assert run_tool("mark", R, " ", "--connect", ep).returncode == 1

    # the list: Finn's ended, Eve's running
    listed = run_tool("session", "list", R, "--connect", ep)
    assert listed.returncode == 0, listed.stderr
    rows = listed.stdout.splitlines()
    finn = next(r for r in rows if "Finn" in r)
    assert "running" not in finn and "Eve O'Neill" in rows[-1] and "running" in rows[-1], listed.stdout
    gone = run_tool("session", "list", "no-such-rover", "--connect", ep, "--timeout", "1")
    assert gone.returncode == 2 and "no answer" in gone.stderr

    # lunaris watch: Eve's session, Eve's events (at 80x24 as on a wide terminal)
    for width in ("80", "160"):
        watch = run_tool("watch", "--rover", R, "--once", "--width", width, "--connect", ep)
        assert watch.returncode == 0, watch.stderr
        assert "Eve O'Neill" in watch.stdout and eve in watch.stdout, watch.stdout
        assert "finn trips" not in watch.stdout and "Finn" not in watch.stdout, watch.stdout
    wide = run_tool("watch", "--rover", R, "--once", "--width", "160", "--connect", ep)
    assert "eve isolates the rail" in wide.stdout, wide.stdout

    # the recording covers both sessions, each event (the journal's stream) with its own
    with open(path, "rb") as f:
        events = [json.loads(msg.data) for _, ch, msg in make_reader(f).iter_messages()
                  if ch.topic == keys.event(R)]
    marks = {e["message"]: e["session"] for e in events if e["kind"] == "mark"}
    assert marks["mark: eve isolates the rail"] == eve
    assert marks["mark: finn trips the camera"] not in ("", eve)
