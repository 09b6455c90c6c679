"""The journal keeps the whole session: 20,000 events, a flood of rejections, restarts.

Found: the journal silently dropped its oldest events at 10,000, and rejections filled it:
10,000 bad inputs, or 19 s of inject/clear, evicted the whole session history, its start
included. Now it is on disk, a flood of rejections is counted in summaries that say so, and
a restarted faults service reads it back.
"""

from __future__ import annotations

import json

import pytest

from common import keys
from common.connection import write
from tests.harness import wait_for
from tests.reliability.conftest import R, restart

pytestmark = pytest.mark.timeout(240)

CYCLES = 10_000  # inject + clear: 20,000 events
BAD = 10_000


def journal(p) -> list[dict]:
    (events,) = p.get_json(keys.faults_journal(R), timeout_s=30)
    return events


def test_the_journal_keeps_20000_events_a_flood_and_a_restart(whole_twin):
    p, twin = whole_twin
    key = keys.fault(R, "load/imu", "open")
    answered = []  # the loads service's answers as they go out (a get of the whole journal
    # each second cost more than the twin's work, on a loaded machine over 180 s)
    sub = p.session.declare_subscriber(keys.event_of(R, "loads"), lambda s: answered.append(
        json.loads(s.payload.to_bytes())["key"] == key))
    try:
        for _ in range(CYCLES):
            write(p.session, key, b"")
            write(p.session, key, None)
        wait_for(lambda: sum(answered) >= 2 * CYCLES, 180,
                 lambda: f"20,000 answers of the loads service ({sum(answered)})", poll_s=0.5)
    finally:
        sub.undeclare()
    def journalled() -> int:  # the faults service may still be busy journalling: no answer yet
        replies = p.get_json(keys.faults_journal(R), timeout_s=30)
        return sum(1 for e in replies[0] if e["key"] == key) if replies else 0
    wait_for(lambda: journalled() >= 2 * CYCLES, 120, "20,000 fault events in the journal", poll_s=2.0)
    for _ in range(BAD):
        write(p.session, keys.input_sun_angle(R), b'"not an angle"')
    sun = keys.input_sun_angle(R)

    def rejections() -> int:  # one by one, and those a summary counts
        return sum((e.get("params") or {}).get("summarised", 1)
                   for e in journal(p) if e["kind"] == "rejected" and e["key"] == sun)
    wait_for(lambda: rejections() >= BAD, 60, lambda: f"{BAD} rejections ({rejections()})",
             poll_s=1.0)

    def check(events: list[dict]) -> None:
        assert events[0]["kind"] == "session" and "begins" in events[0]["message"]
        faults = [e for e in events if e["key"] == key]
        assert [e["kind"] for e in faults] == ["fault_injected", "fault_cleared"] * CYCLES
        rejected = [e for e in events if e["kind"] == "rejected" and e["key"] == sun]
        assert sum((e.get("params") or {}).get("summarised", 1) for e in rejected) == BAD
        summaries = [e for e in rejected if "summarised" in (e.get("params") or {})]
        assert summaries and all("rejections summarised" in e["message"] for e in summaries)
        assert len(rejected) < BAD / 5  # counted, not stored one by one

    first = journal(p)
    check(first)
    restart(twin, p, "faults")
    again = journal(p)
    check(again)
    assert len(again) == len(first)  # read back from disk, caches not journalled twice
