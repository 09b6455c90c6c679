"""One dashboard cannot flood the journal (issue 32): the crew's accepted commands are folded
beyond a rate, as rejections are, every call still answered and counted.

Found: 1,000 crew calls a second (a rail's set_enabled through the bridge, journalled as
``command`` events with actor crew, ~320 bytes each) were all journalled: 1.1 GB of journal
an hour. Now the journal takes ``CREW_BURST`` of them a second one by one and one summary
for the rest ("N more crew commands summarised ..."), which counts them.

10,000 commands at up to 1,000 a second, written as the bridge writes them (a put on
``cmd/rail/<rail>`` with the attachment ``actor=crew``), on loopback; bounded in count and
time.
"""

from __future__ import annotations

import time

import pytest

from common import keys
from common.connection import write
from services.faults.model import CREW_BURST
from tests.harness import ALL_SERVICES, Probe, wait_for
from tests.reliability.conftest import MAPP, R

pytestmark = pytest.mark.timeout(240)

N = 10_000
RATE_PER_S = 1000
RAIL = "5V_CH2"


def answers(p: Probe) -> list[dict]:
    """The power service's answers to the crew's commands on the rail (its own key)."""
    key = keys.cmd_rail(R, RAIL)
    return [e for e in p.samples(keys.event_of(R, "power"))
            if e.get("kind") == "command" and e.get("key") == key and e.get("actor") == "crew"]


def journalled(p: Probe) -> dict[str, int]:
    """The crew's commands on the rail the journal holds one by one, and counts in summaries."""
    key = keys.cmd_rail(R, RAIL)
    out = {"one by one": 0, "summarised": 0, "summaries": 0}
    replies = p.get_json(keys.faults_journal(R), timeout_s=30)
    for e in replies[0] if len(replies) == 1 else []:
        params = e.get("params") or {}
        if e["kind"] != "command" or e.get("actor") != "crew":
            continue
        if "summarised" in params:
            out["summarised"] += params["keys"].get(key, 0)
            out["summaries"] += 1
        elif e["key"] == key:
            out["one by one"] += 1
    return out


def test_a_thousand_crew_calls_a_second_are_answered_and_folded_in_the_journal(twin_factory, probe_solo):
    p = probe_solo
    p.watch(keys.event_of(R, "power"))
    twin = twin_factory([MAPP], services=ALL_SERVICES)
    p.wait_services(R, ALL_SERVICES)
    path = twin.state_dir / f"faults-journal-{R}.jsonl"
    wait_for(path.is_file, 15, "the journal's first line")
    size_before = path.stat().st_size
    key = keys.cmd_rail(R, RAIL)
    t0 = time.monotonic()
    for i in range(N):
        ahead = t0 + i / RATE_PER_S - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)  # a pace, not a wait on a condition: at most RATE_PER_S a second
        write(p.session, key, b'{"on": true}', actor="crew")
    sent_s = time.monotonic() - t0
    wait_for(lambda: len(answers(p)) >= N, 120, lambda: f"{N} answers (have {len(answers(p))})",
             poll_s=0.5)
    got: dict[str, int] = {}

    def counted() -> bool:
        got.update(journalled(p))
        return got["one by one"] + got["summarised"] >= N
    wait_for(counted, 60, lambda: f"{N} crew commands in the journal ({got})", poll_s=1.0)
    grown = path.stat().st_size - size_before
    print(f"{N} crew commands sent in {sent_s:.1f} s, all answered; journal: {got}, "
          f"+{grown / 1e3:.0f} kB")
    assert len(answers(p)) == N and got["one by one"] + got["summarised"] == N
    assert got["summarised"] and got["one by one"] <= CREW_BURST * (sent_s + 60)
    assert grown < 1_000_000
