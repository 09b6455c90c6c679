"""Fault latency to the dashboard: the bridge's outputs as end points of bench/fault_latency.py.

The same runs as ``fault_latency.py`` (a load short on mapp-1's nav_camera, cleared and the
rail reset between runs, the clock paused), with the bridge running and these end points
added to its :data:`~fault_latency.END_POINTS`, each timed to the first sample that shows the
effect, read back with the bridge's own CDR codec (rosbags, ``services/bridge/cdr.py``: the
tests check it against an independent decoder; here it only has to be read):

- ``bridge diagnostics <flavour>`` for ros2dds, rmw_zenoh and json: a DiagnosticArray,
  stamped after the put, that shows the short as the crew sees it (the shipped mapping's
  ``crew_view: symptoms``, SPEC §12b): ``<rover>/rail/5V_CH2`` at ERROR with its ``tripped``
  alarm (the figures before the crew's view timed the ``short`` on ``load/nav_camera``, which
  the crew no longer sees);
- ``bridge PDM current ros2dds``: ``/pdm/rail_5V_CH2_current_ma`` differs from its value
  before the put (the short's current, then 0 mA once the rail trips);
- ``bridge diagnostics ros2 (rclpy)``: the ``ros2`` flavour, timed at an rclpy subscriber of
  ``/diagnostics`` in this process (Fast DDS over shared memory, its own domain).

The bridge runs with every flavour enabled (the shipped mapping with json and ros2 on).

SPEC §10 target: fault injected -> effect on the bridge's dashboard output, p99 under 50 ms
on a 2-core machine. Run: ``.venv/bin/python bench/fault_latency_bridge.py [N]``.
"""

from __future__ import annotations

import json
import os
import random
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import fault_latency as fl
from benchlib import ROOT, machine, percentiles

from services.bridge.cdr import decode_cdr
from services.bridge.rmw_zenoh import rmw_topic_key

DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
RAIL_5V_CH2 = f"{fl.R}/rail/5V_CH2"  # the short's nav_camera is on it


def _decode(flavour: str, payload: bytes, typename: str) -> dict:
    return json.loads(payload) if flavour == "json" else decode_cdr(typename, payload)


def _shows_short(flavour: str) -> Callable[[bytes | None], Callable[[bytes], bool]]:
    def make_test(_before: bytes | None) -> Callable[[bytes], bool]:
        armed_ns = time.time_ns() - 1_000_000  # stamps are the bridge's wall clock, same host

        def test(payload: bytes) -> bool:
            msg = _decode(flavour, payload, DIAGNOSTICS)
            stamp = msg["header"]["stamp"]
            if stamp["sec"] * 1_000_000_000 + stamp["nanosec"] < armed_ns:
                return False  # published before this run's put
            return any(s["name"] == RAIL_5V_CH2 and s["level"] == 2
                       and "tripped" in [v["key"] for v in s["values"]] for s in msg["status"])
        return test
    return make_test


def _int_changed(before: bytes | None) -> Callable[[bytes], bool]:
    base = _decode("ros2dds", before, "std_msgs/msg/Int32")["data"] if before else None
    return lambda p: _decode("ros2dds", p, "std_msgs/msg/Int32")["data"] != base


_made: dict[str, fl.EndPoint] = {}


def _made_as(name: str, make: Callable[[], fl.EndPoint]) -> Callable[[], fl.EndPoint]:
    def factory() -> fl.EndPoint:
        _made[name] = e = make()
        return e
    return factory


def _pdm_back() -> bool:
    """The rail's current back on the dashboard after the reset (the PDM goes at 2 Hz): the
    baseline of the next run is the rail drawing, not the 0 mA of the trip."""
    e = _made.get("pdm")
    return e is None or (e.last is not None and _decode("ros2dds", e.last, "std_msgs/msg/Int32")["data"] != 0)


BRIDGE_END_POINTS: list[Callable[[], fl.EndPoint]] = [
    lambda: fl.EndPoint("bridge diagnostics ros2dds", "diagnostics", _shows_short("ros2dds")),
    lambda: fl.EndPoint("bridge diagnostics rmw_zenoh",
                        rmw_topic_key(0, "/diagnostics", DIAGNOSTICS), _shows_short("rmw_zenoh")),
    lambda: fl.EndPoint("bridge diagnostics json", "json/diagnostics", _shows_short("json")),
    _made_as("pdm", lambda: fl.EndPoint("bridge PDM current ros2dds", "pdm/rail_5V_CH2_current_ma",
                                        _int_changed)),
]


class _Rclpy:
    """An rclpy node in this process whose /diagnostics subscription feeds an end point."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        self.rclpy, self.ctx = rclpy, Context()
        rclpy.init(context=self.ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
        self.node = rclpy.create_node("latency_probe", context=self.ctx)
        self.qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        import threading
        self.spinning = threading.Thread(target=self.executor.spin, daemon=True)
        self.spinning.start()

    def end_point(self) -> fl.EndPoint:
        from diagnostic_msgs.msg import DiagnosticArray

        e = fl.EndPoint("bridge diagnostics ros2 (rclpy)", "", _shows_short("ros2dds"))
        self.node.create_subscription(DiagnosticArray, "/diagnostics",
                                      lambda raw: e.on_sample(bytes(raw)), self.qos, raw=True)
        return e

    def close(self) -> None:
        # In this order: the spinning thread left in the executor at exit aborted the process
        # now and then ("terminate called without an active exception") after the figures.
        self.executor.shutdown(timeout_sec=5.0)
        self.spinning.join(timeout=5.0)
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.ctx)


def _every_flavour(folder: Path) -> Path:
    text = (ROOT / "config/bridge/default.yaml").read_text()
    for old, new in (("json: {enabled: false,", "json: {enabled: true,"),
                     ("ros2: {enabled: false,", "ros2: {enabled: true,")):
        text = text.replace(old, new)
    path = folder / "every-flavour.yaml"
    path.write_text(text)
    return path


def run(n: int = 200) -> list[fl.EndPoint]:
    """The shared runs with the bridge running (every flavour) and its end points added."""
    # Fast DDS on shared memory only, in a domain of its own; never a UDP socket.
    os.environ.update(FASTDDS_BUILTIN_TRANSPORTS="SHM", RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
                      ROS_DOMAIN_ID=str(random.randint(101, 160)))
    node = _Rclpy()
    extra: list[Callable[[], Any]] = [node.end_point]
    # The twin's own end points but the battery current: the parked MAPP in the sun has a full
    # pack whose current a short does not move (bench/fault_latency.py times it elsewhere).
    fl.END_POINTS[:] = [fl.END_POINTS[0], *BRIDGE_END_POINTS, *extra]
    try:
        with tempfile.TemporaryDirectory(prefix="lunaris-bench-map-") as tmp:
            mapping = _every_flavour(Path(tmp))
            return fl.run(n, services=(*fl.SERVICES, "bridge"),
                          extra={"bridge": ["--bridge-config", str(mapping)]}, settled=_pdm_back)
    finally:
        node.close()


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(f"fault latency to the dashboard, {n} load shorts on {fl.R} ({machine()})")
    for e in run(n):
        print(f"  put -> {e.name:<31} {percentiles(e.latencies_ms)}")


if __name__ == "__main__":
    main()
