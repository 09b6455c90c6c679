"""The faults in effect survive restarts of every service, in every order that matters.

Found: after a restart of the faults service or the bridge, both rebuilt the active faults
from the owners' 256-event caches, which are empty after the owner itself restarted and are
flushed by 256 rejections: `get faults` lost battery/heating while it still heated the
pack, and /diagnostics showed 1 of 3 active faults. Now each owner keeps the record of its
own faults (persisted, re-applied on restart, published on faults/active/<service> with a
cache of its own), and the faults service and the bridge only read it.
"""

from __future__ import annotations

import random

import pytest

from common import keys
from tests.harness import Probe, wait_for
from tests.reliability.conftest import WITH_BRIDGE, R, restart

pytestmark = pytest.mark.timeout(240)

INJECTED = {("battery", "heating"): 5, ("load/imu", "stuck"): 1.5, ("load/nav_camera", "short"): "",
            ("solar/left", "dust"): 0.3, ("radio/lander", "failure"): ""}
EXPECTED = {keys.fault(R, c, k) for c, k in INJECTED} | {keys.derived_fault(R, "rail/5V_CH2", "tripped")}
EXPECTED_DIAG = {("battery", "heating"), ("load/imu", "stuck"), ("load/nav_camera", "short"),
                 ("solar/left", "dust"), ("radio/lander", "failure"), ("rail/5V_CH2", "tripped")}
ORDERS = [["battery", "faults"], ["faults", "battery"], ["loads", "bridge"], ["bridge", "loads"],
          ["power", "solar", "radio", "faults", "bridge"],
          random.Random(7).sample(list(WITH_BRIDGE), len(WITH_BRIDGE))]


def listed(p: Probe) -> set[str]:
    replies = p.get_json(keys.faults(R))
    return {f["key"] for f in replies[0]} if len(replies) == 1 else set()


def diagnosed(p: Probe) -> set[tuple[str, str]]:
    diag = p.value("json/diagnostics") or {"status": []}
    return {(st["name"].removeprefix(f"{R}/"), kv["key"]) for st in diag["status"]
            for kv in st["values"]}


def test_faults_and_diagnostics_survive_restarts_in_every_order(whole_twin):
    p, twin = whole_twin
    p.watch("json/diagnostics")
    for (component, kind), value in INJECTED.items():
        p.put(keys.fault(R, component, kind), value if value != "" else b"")
    wait_for(lambda: listed(p) == EXPECTED, 10, lambda: f"the faults listed ({listed(p)})")
    wait_for(lambda: diagnosed(p) == EXPECTED_DIAG, 10, lambda: f"/diagnostics ({diagnosed(p)})")
    for _ in range(300):  # enough rejections to flush every 256-event cache
        p.put(keys.input_sun_angle(R), b'"not an angle"')
    for order in ORDERS:
        for service in order:
            restart(twin, p, service)
        wait_for(lambda: listed(p) == EXPECTED, 15,
                 lambda o=order: f"the faults listed after restarting {o}: {listed(p)}")
        wait_for(lambda: diagnosed(p) == EXPECTED_DIAG, 15,
                 lambda o=order: f"/diagnostics after restarting {o}: {diagnosed(p)}")
    # Still in effect, not only listed: the pack still heats, the rail is still tripped.
    assert p.wait_value(keys.rail_state(R, "5V_CH2"))["state"] == "tripped"
