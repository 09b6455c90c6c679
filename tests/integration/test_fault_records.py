"""One record of every fault (issue 24, SPEC §12b, §12e), over real processes.

For every kind of the catalogue, with a parameter that changes nothing where the kind has one
(heating 0 W, dust 0, resistance x1, capacity_loss 0, stuck at 0 W, range x1) and with one
that does: the fault is listed identically - key, parameters, since, origin - by its owner's
fault book (``faults/active/<service>`` as published, and as answered to a query) and by
``get faults``; and no telemetry payload names it: the ``faults`` fields carry the twin's own
alarms only and ``fault_code`` only their codes.
"""

from __future__ import annotations

import re

import pytest

from common import keys
from common.faults import CATALOGUE, DERIVED, FAULT_CODES
from tests.harness import Probe, wait_for

pytestmark = pytest.mark.timeout(240)

R = "mapp-1"
OWNER = {"battery": "battery", "load": "loads", "rail": "power", "solar": "solar",
         "umbilical": "solar", "radio": "radio"}
CASES = [  # (component, kind, payload, the parameters listed)
    ("battery", "capacity_loss", b"0", {"fraction": 0.0}),
    ("battery", "capacity_loss", b"0.3", {"fraction": 0.3}),
    ("battery", "resistance", b"1", {"factor": 1.0}),
    ("battery", "resistance", b"2", {"factor": 2.0}),
    ("battery", "heating", b"0", {"heat_w": 0.0}),
    ("battery", "heating", b"5", {"heat_w": 5.0}),
    ("battery", "disconnect", b"", {}),
    ("load/imu", "short", b"100", {"resistance_ohm": 100.0}),  # 0.1 W on 3.3 V: no trip
    ("load/imu", "open", b"", {}),
    ("load/imu", "stuck", b"0", {"power_w": 0.0}),
    ("load/imu", "stuck", b"1.5", {"power_w": 1.5}),
    ("rail/3V3_CH2", "fail", b"", {}),
    ("solar/left", "dust", b"0", {"fraction": 0.0}),
    ("solar/left", "dust", b"0.3", {"fraction": 0.3}),
    ("solar/left", "disconnect", b"", {}),
    ("umbilical", "disconnect", b"", {}),
    ("radio/lander", "failure", b"", {}),
    ("radio/lander", "degraded", b"1", {"range_scale": 1.0}),
    ("radio/lander", "degraded", b"0.5", {"range_scale": 0.5}),
]
ALARMS = {name for alarms in DERIVED.values() for name in alarms}
CODES = {code for _, code, _ in FAULT_CODES} | {0}
KINDS = {kind for kinds in CATALOGUE.values() for kind in kinds}
# the payloads with a faults field: battery/state, load/<load>/power, solar/<panel>/power,
# radio/<radio>/link
TELEMETRY = re.compile(rf"lunaris/{R}/(battery/state|(load|solar)/[^/]+/power|radio/[^/]+/link)")


def test_the_cases_cover_every_kind_of_the_catalogue():
    covered = {(c.split("/")[0], k) for c, k, _, _ in CASES}
    assert covered == {(c, k) for c, kinds in CATALOGUE.items() for k in kinds}


def book(p: Probe, service: str, key: str) -> dict | None:
    """The fault as the owner's book answers a query for its faults in effect."""
    (answer,) = p.get_json(keys.faults_active(R, service))
    return next((f for f in answer["faults"] if f["key"] == key), None)


def published(p: Probe, service: str, key: str) -> dict | None:
    """The fault as the owner last published its faults in effect."""
    answer = p.value(keys.faults_active(R, service))
    return None if answer is None else next((f for f in answer["faults"] if f["key"] == key), None)


def journal(p: Probe, key: str) -> dict | None:
    replies = p.get_json(keys.faults(R))
    return next((f for f in replies[0] if f["key"] == key), None) if len(replies) == 1 else None


def crew_readable(p: Probe, since: int) -> list[tuple[str, dict]]:
    """Every telemetry sample with a ``faults`` field received after the probe's mark."""
    with p._lock:
        return [(k, v) for k, vs in p.history.items() if TELEMETRY.fullmatch(k)
                for v in vs[since:] if isinstance(v, dict) and "faults" in v]


@pytest.mark.parametrize(("component", "kind", "payload", "params"), CASES,
                         ids=[f"{c}/{k}={p.decode() or '-'}" for c, k, p, _ in CASES])
def test_a_fault_is_listed_identically_everywhere_and_named_by_no_telemetry(
        mapp_twin, component, kind, payload, params):
    p, _ = mapp_twin
    service = OWNER[component.split("/")[0]]
    key = keys.fault(R, component, kind)
    p.clear_history()
    p.put(key, payload)
    injected = p.wait_event(R, lambda e: e["key"] == key and e["kind"] in ("fault_injected",
                                                                             "rejected"))
    assert injected["kind"] == "fault_injected", injected
    try:
        listed = wait_for(lambda: (lambda f: (f,) if f else None)(published(p, service, key)),
                          5, f"{key} published in faults/active/{service}")[0]
        assert (listed["params"], listed["origin"]) == (params, "injected")
        assert listed["since_t_s"] == injected["t_s"]
        assert book(p, service, key) == listed  # the book's answer to a query
        assert wait_for(lambda: (lambda f: (f,) if f else None)(journal(p, key)), 5,
                        f"{key} in get faults")[0] == listed
        # a second of telemetry under the fault: the crew reads its effects, never its name
        t0 = p.wait_value(keys.battery_state(R))["t_s"]
        p.wait_value(keys.battery_state(R), lambda b: b["t_s"] >= t0 + 1.0)
        p.wait_value(keys.radio_link(R, "lander"), lambda v: v["t_s"] >= t0 + 0.5)
        seen = crew_readable(p, 0)
        assert any(k.endswith("battery/state") for k, _ in seen)
        for k, v in seen:
            assert set(v["faults"]) <= ALARMS and not set(v["faults"]) & KINDS - ALARMS, (k, v)
            assert v.get("fault_code", 0) in CODES, (k, v)
    finally:
        p.delete(key)
        p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_cleared")
    wait_for(lambda: published(p, service, key) is None and journal(p, key) is None, 5,
             f"{key} gone from every list")
    if component == "battery" and kind == "disconnect":  # the rails come back with the pack
        p.wait_value(keys.rail_state(R, "12V"), lambda v: v["state"] == "on")
        p.wait_value(keys.radio_link(R, "lander"), lambda v: not v["faults"])
