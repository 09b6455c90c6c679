"""The journal accounts for every event by its (source_id, seq): journalled, summarised, or
counted lost when it never comes back (issue 23.7). Pure: no Zenoh, the wall time given."""

from __future__ import annotations

from common.messages import Event
from services.faults.journal import Journal
from services.faults.ledger import Gap, Ledger

R = "mapp-1"


def ev(seq: int, source_id: str = "solar-1", kind: str = "rejected", source: str = "solar") -> Event:
    return Event(t_s=float(seq), severity="warning", source=source, kind=kind,
                 key=f"lunaris/{R}/input/sun_angle", message=f"rejected: #{seq}",
                 source_id=source_id, seq=seq)


def accounted(journal: Journal, source_id: str = "solar-1") -> int:
    """Events of a source journalled one by one, summarised or counted lost."""
    import msgspec
    total = 0
    for line in journal.lines():
        e = msgspec.json.decode(line, type=Event)
        params = e.params or {}
        if e.source_id == source_id:
            total += 1
        elif "summarised" in params:
            lo, hi = params["seq"].get(source_id, (1, 0))
            total += hi - lo + 1
        elif e.kind == "journal_gap" and params["source_id"] == source_id:
            total += params["lost"]
    return total


def test_the_ledger_finds_a_hole_and_counts_it_once_it_has_waited():
    led = Ledger(wait_s=5.0)
    for seq in (1, 2, 3, 7, 8):
        led.account("a", "solar", seq, seq, now_s=10.0)
    assert led.gaps(14.0) == []  # a replayed cache may still fill it
    led.account("a", "solar", 4, 4, now_s=14.5)  # it did, in part
    assert led.gaps(15.1) == [Gap("a", "solar", 5, 6)]
    assert led.gaps(30.0) == []  # said once
    assert led.known("a", 5) and led.known("a", 8) and not led.known("a", 9)


def test_a_new_source_starts_at_1_and_a_range_accounts_for_a_summary():
    led = Ledger(wait_s=1.0)
    led.account("b", "battery", 300, 300, 0.0)  # 1..299 were never seen
    led.account("b", "battery", 301, 400, 0.0)
    assert led.gaps(2.0) == [Gap("b", "battery", 1, 299)]
    assert led.known("b", 350)


def test_800_events_of_which_the_journal_saw_the_last_256_are_all_accounted_for(tmp_path):
    """The outage of issue 23.7: the service's cache gave back its last 256 events."""
    journal = Journal(tmp_path / "j.jsonl", rover=R)
    for seq in range(1, 11):
        journal.record(ev(seq), now_s=0.0)
    # the faults service down while 800 more are published; back, it gets the last 256
    for seq in range(11 + 800 - 256, 11 + 800):
        journal.record(ev(seq), now_s=100.0)
    journal.tick(101.0, flood_over=True)
    assert accounted(journal) < 810  # the hole is still waiting for a cache to fill it
    written = journal.tick(106.0)
    assert [e.kind for e in written] == ["journal_gap"]
    gap = written[0]
    assert gap.params == {"lost": 544, "source": "solar", "source_id": "solar-1", "from_seq": 11,
                          "to_seq": 554}
    assert gap.key == f"lunaris/{R}/event/solar" and "544 events of the solar service" in gap.message
    assert accounted(journal) == 810
    assert journal.lost == 544


def test_a_restart_reads_back_what_was_accounted_for_and_journals_only_the_rest(tmp_path):
    path = tmp_path / "j.jsonl"
    first = Journal(path, rover=R)
    for seq in range(1, 3001):  # a flood: 50 one by one a second, the rest summarised
        first.record(ev(seq), now_s=0.0 + seq * 1e-4)
    first.tick(2.0, flood_over=True)
    assert accounted(first) == 3000
    # kill -9 and back: every event replayed from the publisher's cache, plus new ones
    again = Journal(path, rover=R)
    before = len(again.lines())
    for seq in range(1, 3011):
        again.record(ev(seq), now_s=50.0)
    again.tick(60.0, flood_over=True)
    assert len(again.lines()) - before == 10  # the new ones, none twice
    assert accounted(again) == 3010 and again.lost == 0


def test_events_held_for_a_summary_and_lost_with_the_process_are_journalled_when_replayed(tmp_path):
    """kill -9 0.3 s after a flood: the held rejections were never written."""
    path = tmp_path / "j.jsonl"
    first = Journal(path, rover=R)
    for seq in range(1, 3001):
        first.record(ev(seq), now_s=0.0)  # 50 written, 2,950 held for the summary; then killed
    again = Journal(path, rover=R)
    assert accounted(again) == 50
    for seq in range(1, 3001):  # the publisher's cache replayed
        again.record(ev(seq), now_s=10.0)
    again.tick(20.0, flood_over=True)
    assert accounted(again) == 3000 and again.lost == 0


def test_gaps_read_back_are_not_counted_twice(tmp_path):
    path = tmp_path / "j.jsonl"
    first = Journal(path, rover=R)
    first.record(ev(1, kind="input"), now_s=0.0)
    first.record(ev(5, kind="input"), now_s=0.0)
    first.tick(10.0)
    assert first.lost == 3
    again = Journal(path, rover=R)
    assert again.lost == 3 and again.ledger.known("solar-1", 3)
    again.record(ev(3, kind="input"), now_s=20.0)  # late: already counted, not written
    again.tick(40.0)
    assert len(again.lines()) == len(first.lines())
