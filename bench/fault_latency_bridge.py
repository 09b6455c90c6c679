"""Fault latency to the dashboard: the bridge's outputs as end points of bench/fault_latency.py.

The same runs as ``fault_latency.py`` (a load short on mapp-1's nav_camera, cleared and the
rail reset between runs, the clock paused), with the bridge running and these end points
added to its :data:`~fault_latency.END_POINTS`, each timed to the first sample that shows the
effect, read back with the independent decoder of tests/rosmsg.py:

- ``bridge diagnostics <flavour>`` for ros2dds, rmw_zenoh and json: a DiagnosticArray,
  stamped after the put, whose ``<rover>/load/nav_camera`` status lists the ``short``;
- ``bridge PDM current ros2dds``: ``/pdm/rail_5V_CH2_current_ma`` differs from its value
  before the put (the short's current, then 0 mA once the rail trips).

SPEC §10 target: fault injected -> effect on the bridge's dashboard output, p99 under 50 ms
on a 2-core machine. Run: ``.venv/bin/python bench/fault_latency_bridge.py [N]``.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable

import fault_latency as fl
from benchlib import machine, percentiles

from services.bridge.rmw_zenoh import rmw_topic_key
from tests import rosmsg

DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
NAV_CAMERA = f"{fl.R}/load/nav_camera"


def _decode(flavour: str, payload: bytes, typename: str) -> dict:
    if flavour == "json":
        return json.loads(payload)
    msg = rosmsg.decode(typename, payload)
    if typename == DIAGNOSTICS:
        return {"header": {"stamp": {"sec": msg.header.stamp.sec,
                                     "nanosec": msg.header.stamp.nanosec}},
                "status": [{"name": s.name, "level": s.level,
                            "values": [{"key": v.key} for v in s.values]} for s in msg.status]}
    return {"data": msg.data}


def _shows_short(flavour: str) -> Callable[[bytes | None], Callable[[bytes], bool]]:
    def make_test(_before: bytes | None) -> Callable[[bytes], bool]:
        armed_ns = time.time_ns() - 1_000_000  # stamps are the bridge's wall clock, same host

        def test(payload: bytes) -> bool:
            msg = _decode(flavour, payload, DIAGNOSTICS)
            stamp = msg["header"]["stamp"]
            if stamp["sec"] * 1_000_000_000 + stamp["nanosec"] < armed_ns:
                return False  # published before this run's put
            return any(s["name"] == NAV_CAMERA and s["level"] >= 1
                       and "short" in [v["key"] for v in s["values"]] for s in msg["status"])
        return test
    return make_test


def _int_changed(before: bytes | None) -> Callable[[bytes], bool]:
    base = _decode("ros2dds", before, "std_msgs/msg/Int32")["data"] if before else None
    return lambda p: _decode("ros2dds", p, "std_msgs/msg/Int32")["data"] != base


BRIDGE_END_POINTS: list[Callable[[], fl.EndPoint]] = [
    lambda: fl.EndPoint("bridge diagnostics ros2dds", "diagnostics", _shows_short("ros2dds")),
    lambda: fl.EndPoint("bridge diagnostics rmw_zenoh",
                        rmw_topic_key(0, "/diagnostics", DIAGNOSTICS), _shows_short("rmw_zenoh")),
    lambda: fl.EndPoint("bridge diagnostics json", "json/diagnostics", _shows_short("json")),
    lambda: fl.EndPoint("bridge PDM current ros2dds", "pdm/rail_5V_CH2_current_ma", _int_changed),
]


def run(n: int = 200) -> list[fl.EndPoint]:
    """The shared runs with the bridge running and its end points added."""
    fl.END_POINTS[:] = [e for e in fl.END_POINTS if e not in BRIDGE_END_POINTS] + BRIDGE_END_POINTS
    return fl.run(n, services=(*fl.SERVICES, "bridge"))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(f"fault latency to the dashboard, {n} load shorts on {fl.R} ({machine()})")
    for e in run(n):
        print(f"  put -> {e.name:<29} {percentiles(e.latencies_ms)}")


if __name__ == "__main__":
    main()
