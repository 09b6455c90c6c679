"""A write that could not reach its owner in time is never applied late, and `get faults` names
the owners that did not answer (issue 22, SPEC §12f, D3).

Found across a partition: a fault injected during a 5 s cut took effect at the restore, one
sent during a 10 s cut was lost without a record, and `lunaris fault list` said "no active
faults" while two were in effect behind the cut. Now every owner refuses a write whose Zenoh
timestamp is more than WRITE_MAX_AGE_S old when it arrives (a rejection in words: nothing
changes), and the faults service adds an error reply per expected owner that did not answer.
The late writes here are sent with an old timestamp (what a write held back by a cut link
carries), on loopback.
"""

from __future__ import annotations

import datetime

import pytest
import zenoh

from common import keys
from common.connection import WRITE_MAX_AGE_S
from tests.harness import ALL_SERVICES, Probe, wait_for

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
HEATING = keys.fault(R, "battery", "heating")


@pytest.fixture
def twin(twin_factory, probe_solo, mapp_file):
    p = probe_solo
    p.watch("lunaris/**")
    twin = twin_factory([mapp_file])
    p.wait_services(R, ALL_SERVICES)
    p.wait_value(keys.solar_power(R, "left"))
    return p, twin


def sent_ago(p: Probe, seconds: float) -> zenoh.Timestamp:
    now = datetime.datetime.now(datetime.UTC)
    return zenoh.Timestamp(now - datetime.timedelta(seconds=seconds), p.session.new_timestamp().get_id())


def late_put(p: Probe, key: str, payload: bytes, seconds: float) -> dict:
    """Put with a timestamp ``seconds`` old; the events of the rover answering it."""
    seen = len(p.events(R))
    p.session.put(key, payload, timestamp=sent_ago(p, seconds))
    return p.wait_event(R, lambda e: e["key"] == key and p.events(R).index(e) >= seen)


def listed(p: Probe) -> set[str]:
    (faults,) = p.get_json(keys.faults(R))
    return {f["key"] for f in faults}


def test_a_write_sent_too_long_ago_is_refused_and_changes_nothing(twin):
    p, _ = twin
    clock = p.wait_value(keys.clock(R))
    sun = p.value(keys.solar_power(R, "left"))["sun_angle_deg"]
    for key, payload in [(HEATING, b"25"), (keys.input_sun_angle(R), b"12"),
                         (keys.cmd_rail(R, "5V_CH2"), b'{"on": false}'),
                         (keys.clock_control(R), b'{"paused": true}'),
                         (keys.control_reset(R), b""),
                         (keys.control_snapshot(R, "late"), b"")]:
        e = late_put(p, key, payload, WRITE_MAX_AGE_S + 5.0)
        assert e["kind"] == "rejected", (key, e)
        assert "not applied: sent at" in e["message"] and "arrived 7." in e["message"], e
        assert "nothing changed, send it again" in e["message"]
        assert len([x for x in p.events(R) if x["key"] == key]) == 1, key  # refused once
    assert HEATING not in listed(p)
    assert p.value(keys.solar_power(R, "left"))["sun_angle_deg"] == sun
    assert p.value(keys.rail_state(R, "5V_CH2"))["state"] == "on"
    later = p.wait_value(keys.clock(R), lambda c: c["seq"] > clock["seq"] + 5)
    assert not later["paused"] and later["epoch"] == clock["epoch"] and later["t_s"] > clock["t_s"]
    assert "late" not in {s["name"] for s in p.get_json(keys.snapshots(R))[0]}
    # a write a second old is in time: applied
    e = late_put(p, HEATING, b"25", 1.0)
    assert e["kind"] == "fault_injected", e
    assert HEATING in listed(p)


def test_get_faults_names_the_owner_that_did_not_answer(twin):
    p, twin_ = twin
    p.put(HEATING, 5)
    p.put(keys.fault(R, "load/imu", "stuck"), 1.5)
    wait_for(lambda: {HEATING, keys.fault(R, "load/imu", "stuck")} <= listed(p), 10, "both listed")
    twin_.procs["battery"].kill()
    twin_.procs["battery"].wait(10)
    replies = list(p.session.get(keys.faults(R), timeout=10))
    oks = [r.ok for r in replies if r.ok is not None]
    errs = [r.err.payload.to_string() for r in replies if r.err is not None]
    assert len(oks) == 1 and keys.fault(R, "load/imu", "stuck") in oks[0].payload.to_string()
    assert errs == [f"the battery service of {R} did not answer within 2 s: its faults are not listed"]
