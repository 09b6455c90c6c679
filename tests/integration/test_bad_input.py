"""Bad input never stops a service and never changes state: each is rejected with an event.

Every kind of bad payload goes to every kind of key an instructor or dashboard
may put on; each test checks the rejection event naming the key, that every
service is still alive and publishing, and that the state is what it was.
"""

from __future__ import annotations

import pytest

from common import keys
from tests.harness import ALL_SERVICES, Probe

pytestmark = pytest.mark.timeout(60)

R = "mapp-1"
P = f"lunaris/{R}"

# Keys that take parameters or an object, with payloads that are wrong only for them.
KEYS: dict[str, list[bytes]] = {
    f"{P}/fault/battery/heating": [b"-1", b"true", b""],
    f"{P}/fault/battery/capacity_loss": [b"1.5", b'{"fraction": "half"}'],
    f"{P}/fault/battery/resistance": [b"0.5"],
    f"{P}/fault/battery/disconnect": [b"5", b'{"now": true}'],
    f"{P}/fault/load/drive_motors/short": [b"0", b"-0.1"],
    f"{P}/fault/load/drive_motors/stuck": [b"-3", b""],
    f"{P}/fault/load/drive_motors/open": [b"1"],
    f"{P}/fault/rail/12V/fail": [b"1"],
    f"{P}/fault/solar/left/dust": [b"2", b"-0.5"],
    f"{P}/fault/solar/left/disconnect": [b"true"],
    f"{P}/fault/umbilical/disconnect": [b"1"],
    f"{P}/fault/radio/lander/failure": [b"0"],
    f"{P}/fault/radio/lander/degraded": [b"1.2", b"false"],
    f"{P}/input/sun_angle": [b"1000", b"true", b""],
    f"{P}/input/radio/lander/position": [b'{"distance_m": -2e9, "angle_deg": 0}', b"5",
                                          b'{"distance_m": 10}'],
    f"{P}/input/umbilical": [b"1", b'{"connected": "yes"}'],
    f"{P}/cmd/rail/12V": [b"{}", b'{"on": 1}', b'{"reset": "now"}'],
    f"{P}/clock/control": [b'{"time_scale": 0}', b'{"time_scale": -1}', b"{}",
                           b'{"paused": "yes"}'],
}
# Payloads that are wrong for every key.
EVERYWHERE = [b"{", b"NaN", b"Infinity", b"1e999", b'"text"', b"[1, 2]", b'{"bogus": 1}',
              b"\xff\xfe\x00"]
# Keys that are wrong whatever the payload.
UNKNOWN = [
    f"{P}/fault/load/no_such_load/short",
    f"{P}/fault/rail/no_such_rail/fail",
    f"{P}/fault/solar/no_such_panel/dust",
    f"{P}/fault/radio/no_such_radio/failure",
    f"{P}/fault/battery/melt",
    f"{P}/fault/wheel/flat",
    f"{P}/fault/battery/extra/heating",
    f"{P}/fault/load/short",
    f"{P}/input/radio/no_such_radio/position",
    f"{P}/input/gravity",
    f"{P}/cmd/rail/no_such_rail",
    f"{P}/cmd/rail/SOLAR",
    f"{P}/cmd/self_destruct",
    "lunaris/no-such-rover/fault/battery/heating",
    "lunaris/no-such-rover/input/sun_angle",
]

CASES = ([(k, p) for k, ps in KEYS.items() for p in ps]
         + [(k, p) for k in KEYS for p in EVERYWHERE]
         + [(k, b'{"fraction": 0.5}') for k in UNKNOWN])


def snapshot(p: Probe) -> dict:
    """Everything a bad input could have changed, as last published."""
    def v(key):
        return p.value(key) or {}
    b = v(keys.battery_state(R))
    return {
        "battery": (b.get("capacity_j"), b.get("faults"), b.get("operational")),
        "rails": {r: v(keys.rail_state(R, r)).get("state")
                  for r in ("12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2", "SOLAR")},
        "load_faults": {ld: v(keys.load_power(R, ld)).get("faults")
                        for ld in ("drive_motors", "nav_camera")},
        "solar": {s: (v(keys.solar_power(R, s)).get("dust"), v(keys.solar_power(R, s)).get("power_w"),
                      v(keys.solar_power(R, s)).get("sun_angle_deg")) for s in ("left", "right")},
        "umbilical": v(keys.umbilical_state(R)).get("connected"),
        "radio": {k: v(keys.radio_link(R, "lander")).get(k) for k in ("in_range", "x_m", "y_m",
                                                                     "faults")},
        "clock": {k: v(keys.clock(R)).get(k) for k in ("time_scale", "paused")},
    }


def fresh_tick(p: Probe) -> None:
    """Wait until every per-tick publisher has published twice more (state settled)."""
    seq = p.value(keys.clock(R))["seq"]
    p.wait_value(keys.clock(R), lambda c: c["seq"] >= seq + 2)
    t = p.value(keys.clock(R))["t_s"]
    for key in (keys.battery_state(R), keys.solar_power(R, "left"), keys.rail_state(R, "12V")):
        p.wait_value(key, lambda v, t=t: v["t_s"] >= t)


@pytest.fixture
def probe(mapp_twin):
    p, _ = mapp_twin
    return p


@pytest.mark.parametrize(("key", "payload"), CASES, ids=lambda x: x if isinstance(x, str)
                         else repr(x)[:24])
def test_bad_input_is_rejected_and_changes_nothing(probe, key, payload):
    rover = key.split("/")[1]
    fresh_tick(probe)
    before = snapshot(probe)
    seen = len(probe.events(rover))
    probe.put(key, payload)
    rejection = probe.wait_event(rover, lambda e: e["kind"] == "rejected" and e["key"] == key
                                 and probe.events(rover).index(e) >= seen)
    assert rejection["severity"] == "warning" and rejection["message"].startswith("rejected: ")
    assert len(rejection["message"]) > len("rejected: ") + 5  # a reason, in words
    fresh_tick(probe)
    assert snapshot(probe) == before
    accepted = [e for e in probe.events(rover)[seen:]
                if e["kind"] in ("fault_injected", "command", "clock")]
    assert accepted == []


def test_clearing_a_fault_that_is_not_active_is_rejected(probe):
    key = f"{P}/fault/battery/heating"
    seen = len(probe.events(R))
    probe.delete(key)
    e = probe.wait_event(R, lambda e: e["key"] == key and probe.events(R).index(e) >= seen)
    assert e["kind"] == "rejected" and "no active fault" in e["message"]


def test_every_service_is_alive_and_publishing_after_all_that(probe, mapp_twin):
    _, twin = mapp_twin
    assert all(proc.poll() is None for proc in twin.procs.values())
    probe.wait_services(R, ALL_SERVICES, timeout_s=5)
    t = probe.value(keys.battery_state(R))["t_s"]
    probe.wait_value(keys.battery_state(R), lambda b: b["t_s"] > t)
    (faults,) = probe.get_json(keys.faults(R))
    assert faults == []
    assert "internal_error" not in {e["kind"] for e in probe.events(R)}
