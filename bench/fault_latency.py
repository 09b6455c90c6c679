"""Fault latency: from the instructor's `put` to its effect on the twin's keys.

A load short is injected on mapp-1's nav_camera, many times. For each injection
we time, on the wall clock of this process (which is also the injector), the
first sample at each end point that shows the effect:

- ``rail tripped``: ``rail/5V_CH2/state`` with state ``tripped``;
- ``battery current``: ``battery/state`` whose current differs from before the
  put (the clock is paused during the run, so only the fault moves it);
- further end points can be added to :data:`END_POINTS` (the bridge adds its own).

Each run then clears the short, resets the rail and waits until it is back on.
SPEC §10 target: p99 under 50 ms on a 2-core machine.
Run: `make bench` or `.venv/bin/python bench/fault_latency.py [N]`.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from benchlib import ROOT, machine, percentiles, running_twin

from common import keys

R = "mapp-1"
SHORT = keys.fault(R, "load/nav_camera", "short")
RAIL = keys.rail_state(R, "5V_CH2")


@dataclass
class EndPoint:
    """A key and a test, built from the value before the put, that says the effect arrived.
    ``needs_quiet``: the test compares with the value before, so it is only measured while
    the clock is paused (the tick's noise would look like an effect)."""

    name: str
    key: str
    make_test: Callable[[bytes | None], Callable[[bytes], bool]]
    needs_quiet: bool = False
    latencies_ms: list[float] = field(default_factory=list)
    last: bytes | None = None
    _test: Callable[[bytes], bool] | None = None
    _t0: float = 0.0
    done: threading.Event = field(default_factory=threading.Event)

    def arm(self, t0: float) -> None:
        self.done.clear()
        self._t0, self._test = t0, self.make_test(self.last)

    def on_sample(self, payload: bytes) -> None:
        t = time.perf_counter()
        self.last = payload
        test = self._test
        if test is not None and test(payload):
            self._test = None
            self.latencies_ms.append((t - self._t0) * 1e3)
            self.done.set()


def _state_is(state: str) -> Callable[[bytes | None], Callable[[bytes], bool]]:
    return lambda _before: lambda p: json.loads(p)["state"] == state


def _current_changed(before: bytes | None) -> Callable[[bytes], bool]:
    base = json.loads(before)["current_a"] if before else None
    return lambda p: json.loads(p)["current_a"] != base


END_POINTS: list[Callable[[], EndPoint]] = [
    lambda: EndPoint("rail tripped", RAIL, _state_is("tripped")),
    lambda: EndPoint("battery current", keys.battery_state(R), _current_changed, needs_quiet=True),
]
SERVICES = ("clock", "battery", "loads", "power", "solar", "faults")


def run(n: int = 200, services=SERVICES, extra=None, paused: bool = True,
        settled: Callable[[], bool] | None = None) -> list[EndPoint]:
    """``paused``: hold the clock so the fault is the only change; otherwise the twin runs
    at 10 Hz underneath (and only the end points that need no quiet baseline are timed).
    ``settled``: also waited for before each put (an end point's baseline is back)."""
    ends = [e for e in (make() for make in END_POINTS) if paused or not e.needs_quiet]
    with running_twin([ROOT / "config/rovers/mapp.yaml"], services, extra) as (probe, _, _):
        probe.watch(f"lunaris/{R}/**")
        subs = [probe.session.declare_subscriber(  # an end point without a key feeds itself
            e.key, lambda s, e=e: e.on_sample(s.payload.to_bytes())) for e in ends if e.key]
        probe.wait_services(R, services)
        probe.put(keys.clock_control(R), {"paused": paused})
        probe.wait_value(keys.clock(R), lambda c: c["paused"] == paused)
        probe.wait_value(RAIL, lambda v: v["state"] == "on")
        for i in range(n):
            t0 = time.perf_counter()
            for e in ends:
                e.arm(t0)
            probe.session.put(SHORT, b"")
            for e in ends:
                if not e.done.wait(5.0):
                    raise SystemExit(f"run {i}: no effect on {e.name} within 5 s")
            probe.session.delete(SHORT)
            probe.wait_event(R, lambda ev: ev["kind"] == "fault_cleared" and ev["key"] == SHORT)
            probe.history.clear()
            probe.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})
            probe.wait_value(RAIL, lambda v: v["state"] == "on")
            # let the battery settle on the restored demand before the next put
            probe.wait_value(keys.battery_state(R), lambda b: True)
            deadline = time.monotonic() + 5.0
            while settled is not None and not settled() and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.02)
        del subs
    return ends


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(f"fault latency, {n} load shorts on mapp-1 ({machine()})")
    for paused in (True, False):
        print("clock paused (the fault is the only change):" if paused
              else "clock running at 10 Hz underneath:")
        for e in run(n, paused=paused):
            print(f"  put -> {e.name:<24} {percentiles(e.latencies_ms)}")


if __name__ == "__main__":
    main()
