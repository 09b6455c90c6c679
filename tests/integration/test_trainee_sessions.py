"""Trainee sessions over real processes (SPEC §12c, issue 25 item 3).

``put control/session {"trainee", "from_snapshot"?}`` ends the running session and begins a
new one: the twin reset (or the snapshot restored), every later event carries the new
session's id, the journal starts a new segment (``faults/journal`` is the running session's,
``?session=<id>`` another's), ``get sessions`` lists them; ``control/mark`` marks the
timeline. Two trainees in a row never mix: the second's journal, the client's mirror (what
``lunaris watch`` and the console show) and its plots' history hold nothing of the first's.
"""

from __future__ import annotations

import time

import pytest

from common import keys
from lunaris.client import Mirror, Session
from tests.harness import ALL_SERVICES, static_rover, wait_for

pytestmark = pytest.mark.timeout(150)

R = "mapp-1"
MAPP = static_rover("mapp.yaml")

# One write per service of the twin, and the event kind that answers it: every service's
# events, after a session begins, must carry its id.
POKES = {
    "clock": (keys.clock_control(R), {"time_scale": 1}, "clock"),
    "battery": (keys.fault(R, "battery", "heating"), 5, "fault_injected"),
    "loads": (keys.fault(R, "load/nav_camera", "stuck"), {"power_w": 1.0}, "fault_injected"),
    "power": (keys.cmd_rail(R, "3V3_CH2"), {"on": False}, "command"),
    "solar": (keys.fault(R, "solar/left", "dust"), 0.2, "fault_injected"),
    "radio": (keys.fault(R, "radio/lander", "degraded"), 0.5, "fault_injected"),
    "faults": (keys.control_mark(R), {"text": "every service"}, "mark"),
}


@pytest.fixture
def twin(twin_factory, probe_solo):
    probe_solo.watch("lunaris/**")
    t = twin_factory([MAPP])
    probe_solo.wait_services(R, ALL_SERVICES)
    probe_solo.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
    return probe_solo, t


def begin(p, trainee: str, **more) -> str:
    """Begin ``trainee``'s session; its id, from the clock's answer."""
    p.put(keys.control_session(R), {"trainee": trainee, **more})
    ev = p.wait_event(R, lambda e: e["kind"] == "session" and e["source"] == "clock"
                      and (e["params"] or {}).get("trainee") == trainee, timeout_s=15)
    assert ev["session"] == ev["params"]["session"] and ev["actor"] == "instructor"
    return ev["session"]


def journal(p, query: str = "") -> list[dict]:
    (events,) = p.get_json(keys.faults_journal(R) + query)
    return events


def sessions(p) -> list[dict]:
    (listed,) = p.get_json(keys.sessions(R))
    return listed


def poke_every_service(p, session: str) -> None:
    """A write for every service; each one's answer carries ``session``."""
    for key, payload, _ in POKES.values():
        p.put(key, payload)
    for service, (key, _, kind) in POKES.items():
        ev = p.wait_event(R, lambda e, s=service, k=key, kd=kind: e["source"] == s and e["key"] == k
                          and e["kind"] == kd and e["session"] == session, timeout_s=15)
        assert ev["session"] == session


def test_two_trainees_in_a_row_never_mix(twin):
    p, _ = twin
    first = p.wait_value(keys.clock(R), lambda c: c["session"])["session"]  # the twin's first session
    mirror = Mirror(R, history={"battery/state": 600}, history_every_s=0.2).start(p.session)
    try:
        ana = begin(p, "Ana")
        assert ana > first
        p.wait_value(keys.clock(R), lambda c: c["session"] == ana)
        p.put(keys.clock_control(R), {"time_scale": 50})
        p.put(keys.fault(R, "load/nav_camera", "short"), b"")
        p.put(keys.control_mark(R), {"text": "ana isolates the camera"})
        p.wait_event(R, lambda e: e["kind"] == "mark" and "ana isolates" in e["message"])
        p.wait_value(keys.rail_state(R, "5V_CH2"), lambda r: r["state"] == "tripped")
        wait_for(lambda: len(mirror.history(keys.battery_state(R))) >= 3, 10, "Ana's plots")
        ana_t = p.wait_value(keys.clock(R), lambda c: c["t_s"] > 30)["t_s"]

        ben = begin(p, "Ben")
        assert ben > ana
        p.wait_value(keys.clock(R), lambda c: c["session"] == ben and c["t_s"] < 5)
        poke_every_service(p, ben)  # every service is in Ben's session
        p.put(keys.control_mark(R), {"text": "ben starts"})
        p.wait_event(R, lambda e: e["kind"] == "mark" and e["message"] == "mark: ben starts")

        # Ben's journal: his events only, from the clock's event that opened his session
        wait_for(lambda: any(e["kind"] == "mark" and "ben starts" in e["message"] for e in journal(p)),
                 10, "Ben's mark in the journal")
        mine = journal(p)
        assert mine[0]["kind"] == "session" and mine[0]["params"]["trainee"] == "Ben"
        assert {e["session"] for e in mine} == {ben}, mine
        said = " ".join(e["message"] for e in mine)
        assert "ana isolates" not in said and "nav_camera/short" not in said and "Ana" not in said
        # what ended with Ana's session is hers: her short cleared, the trip resolved
        assert not [e for e in mine if e["kind"] in ("fault_cleared", "fault_resolved")], mine
        assert journal(p, f"?session={ben}") == journal(p)
        assert len(journal(p, "?last=2")) == 2
        # Ana's: hers, from her session's opening to the clearing of her faults as it ended
        hers = journal(p, f"?session={ana}")
        assert {e["session"] for e in hers} == {ana}
        kinds = {(e["kind"], e["key"].rsplit("/", 2)[-2] if e["kind"].startswith("fault") else "")
                 for e in hers}
        assert ("fault_injected", "nav_camera") in kinds and ("fault_cleared", "nav_camera") in kinds
        assert any(e["kind"] == "fault_resolved" and "5V_CH2" in e["key"] for e in hers)
        assert any(e["kind"] == "mark" for e in hers)
        everything = journal(p, "?session=all")
        assert len(everything) >= len(hers) + len(mine)
        assert {first, ana, ben} <= {e["session"] for e in everything}
        # the sessions, with their times
        listed = sessions(p)
        assert [s["id"] for s in listed] == [first, ana, ben]
        assert [s["trainee"] for s in listed] == ["", "Ana", "Ben"]
        assert listed[1]["start_t_s"] == 0.0 and listed[1]["end_t_s"] >= ana_t
        assert listed[2]["end_t_s"] is None and listed[2]["start_t_s"] == 0.0
        walls = [s["started_wall"] for s in listed]
        assert walls == sorted(walls) and walls[-1] <= time.time()
        # the client's mirror (lunaris watch, the console): Ben's events and plots only
        wait_for(lambda: mirror.session_of(R) == Session(ben, "Ben"), 5, "the mirror in Ben's session")
        seen = mirror.events(R)
        assert seen and {ev.session for _, ev, _ in seen} == {ben}
        history = mirror.history(keys.battery_state(R))
        assert history and all(v.value.t_s < 60 for v in history), [v.value.t_s for v in history]
        # an unknown session, a malformed one: said
        replies = list(p.session.get(keys.faults_journal(R) + "?session=20000101-000000", timeout=5))
        assert replies and replies[0].err is not None
        assert b"no session 20000101-000000" in replies[0].err.payload.to_bytes()
    finally:
        mirror.close()


def test_a_session_from_a_snapshot_and_one_that_cannot_begin(twin):
    p, _ = twin
    p.put(keys.fault(R, "solar/left", "dust"), 0.4)
    p.wait_event(R, lambda e: e["kind"] == "fault_injected" and "dust" in e["key"])
    p.put(keys.control_snapshot(R, "dusty"), b"")
    p.wait_event(R, lambda e: e["kind"] == "session" and "'dusty' saved" in e["message"])
    p.delete(keys.fault(R, "solar/left", "dust"))
    p.wait_event(R, lambda e: e["kind"] == "fault_cleared" and "dust" in e["key"])
    before = p.wait_value(keys.clock(R), lambda c: c["session"])["session"]

    # refused, in words, and nothing changes: the running session goes on
    p.put(keys.control_session(R), {"trainee": "Cleo", "from_snapshot": "never-saved"})
    no = p.wait_event(R, lambda e: e["kind"] == "rejected" and e["key"] == keys.control_session(R))
    assert "not begun" in no["message"] and "no snapshot 'never-saved'" in no["message"]
    assert "goes on" in no["message"] and no["session"] == before
    p.put(keys.control_session(R), {"trainee": "<Cleo>"})
    bad = p.wait_event(R, lambda e: e["kind"] == "rejected" and "'<'" in e["message"])
    assert "a trainee's name is letters" in bad["message"] and bad["source"] == "clock"
    assert p.value(keys.clock(R))["session"] == before

    cleo = begin(p, "Cleo", from_snapshot="dusty")
    tick = p.wait_value(keys.clock(R), lambda c: c["session"] == cleo)
    assert tick["cause"] == "restore:dusty"
    # the snapshot's fault is in effect again, re-injected in Cleo's session
    again = p.wait_event(R, lambda e: e["kind"] == "fault_injected" and "dust" in e["key"]
                         and e["session"] == cleo)
    assert again["source"] == "solar"
    wait_for(lambda: any(e["kind"] == "fault_injected" and e["session"] == cleo for e in journal(p)),
             10, "the re-injected fault in Cleo's journal")
    listed = sessions(p)
    assert listed[-1]["id"] == cleo and listed[-1]["from_snapshot"] == "dusty"
    assert listed[-1]["trainee"] == "Cleo"


def test_restarts_of_the_faults_service_and_of_the_clock_keep_the_session(twin):
    p, t = twin
    dana = begin(p, "Dana")
    p.put(keys.control_mark(R), {"text": "before the restarts"})
    p.wait_event(R, lambda e: e["kind"] == "mark" and e["session"] == dana)
    # seen on event/faults, the mark is in the journal already: the kill -9 cannot lose it
    # (tests/services/test_faults_own_events.py)
    for service in ("faults", "clock"):
        proc = t.procs[service]
        proc.kill()
        proc.wait(10)
        t.start(service)
        p.wait_services(R, (service,))
    p.wait_value(keys.clock(R), lambda c: c["session"] == dana and c["t_s"] > 0)
    p.put(keys.control_mark(R), {"text": "after the restarts"})
    after = p.wait_event(R, lambda e: e["kind"] == "mark" and "after the restarts" in e["message"])
    assert after["session"] == dana
    # no session begun by the restarts; Dana's journal has what came before them
    wait_for(lambda: any("after the restarts" in e["message"] for e in journal(p)), 10, "the mark")
    mine = journal(p)
    assert {e["session"] for e in mine} == {dana}
    assert any("before the restarts" in e["message"] for e in mine)
    listed = sessions(p)
    assert listed[-1]["id"] == dana and listed[-1]["trainee"] == "Dana" and listed[-1]["end_t_s"] is None
    opened = [e for e in p.events(R) if e["kind"] == "session" and e["source"] == "clock"
              and "started_wall" in (e["params"] or {})]
    assert opened[-1]["session"] == dana


def test_a_clock_that_lost_its_state_learns_the_session_back_from_the_services(twin):
    """Its saved state and time gone (a new state folder, a disk replaced): the services say
    where the twin was, the session included (``faults/active/<service>`` carries it)."""
    p, t = twin
    ana = begin(p, "Ana")
    reached = p.wait_value(keys.clock(R), lambda c: c["session"] == ana and c["t_s"] > 2)["t_s"]
    proc = t.procs["clock"]
    proc.kill()
    proc.wait(10)
    lost = list(t.state_dir.glob("clock-*.json"))
    assert lost
    for f in lost:
        f.unlink()
    t.start("clock")
    p.wait_services(R, ("clock",))
    p.wait_value(keys.clock(R), lambda c: c["session"] == ana and c["t_s"] >= reached, timeout_s=15)
    listed = sessions(p)
    assert listed[-1]["id"] == ana and listed[-1]["trainee"] == "Ana"
    opened = [e for e in p.events(R) if e["kind"] == "session" and e["source"] == "clock"
              and "started_wall" in (e["params"] or {})]
    assert opened[-1]["session"] == ana  # no session begun by the restart
