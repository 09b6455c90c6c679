"""A write names exactly one key: a put or delete on a key expression holding a wildcard is
refused once, in words, and never starts a storm (SPEC §10: events per second back under 50
within 3 s).

Found: a put on ``lunaris/**`` was rejected with an event on ``lunaris/**/event``, which the
faults service heard as new input and rejected again, forever (~5,000-6,000 events a
second, the faults service 33 MB -> 260 MB in 7 s); ``lunaris/<rover>/input/** = 30`` was
taken as a sun angle and ``lunaris/<rover>/clock/*`` paused the clock. Now every service
drops such a sample (common.runtime), the faults service refuses it once on each rover it
reaches, and no event is ever published on a key holding a wildcard.
"""

from __future__ import annotations

import threading
import time

import pytest

from common import keys
from tests.harness import Probe, wait_for
from tests.reliability.conftest import R, events

pytestmark = pytest.mark.timeout(240)

STORM_RATE = 50  # events per second: SPEC §10's "no storm"
SETTLE_S = 3.0  # ... back under it within this long of the put

# (key expression, payload; None: a delete)
CASES = [
    ("lunaris/**", b"30"),
    (f"lunaris/{R}/input/**", b"30"),
    (f"lunaris/{R}/clock/*", b'{"paused": true}'),
    (f"lunaris/{R}/input/sun$*", b"30"),
    ("lunaris/*/input/sun_angle", b"30"),
    (f"lunaris/{R}/fault/battery/*", b"30"),
    (f"lunaris/{R}/fault/**", None),  # would clear every fault
    (f"lunaris/{R}/**", b'{"paused": true}'),
    ("lunaris/*/event", b'{"t_s": 0}'),
    ("**", b"30"),
]


class EventRate:
    """Every event sample of any rover (on any key holding ``event``), with its arrival time."""

    def __init__(self, p: Probe):
        self.times: list[float] = []
        self._lock = threading.Lock()

        def on_sample(s) -> None:
            if "/event" in str(s.key_expr) or str(s.key_expr).endswith("event"):
                with self._lock:
                    self.times.append(time.monotonic())
        self.sub = p.session.declare_subscriber("**", on_sample)

    def between(self, t0: float, t1: float) -> int:
        with self._lock:
            return sum(1 for t in self.times if t0 <= t < t1)


def state(p: Probe) -> tuple:
    clock = p.value(keys.clock(R))
    return (clock["paused"], clock["time_scale"], p.value(keys.solar_power(R, "left"))["sun_angle_deg"],
            tuple(sorted(f["key"] for f in p.get_json(keys.faults(R))[0])))


def test_a_wildcard_write_is_refused_once_and_starts_no_storm(whole_twin):
    p, twin = whole_twin
    p.put(keys.fault(R, "battery", "heating"), 5)
    p.put(keys.input_sun_angle(R), 12)
    p.wait_value(keys.solar_power(R, "left"), lambda v: v["sun_angle_deg"] == 12)
    wait_for(lambda: keys.fault(R, "battery", "heating") in state(p)[3], 10, "the heating listed")
    before = state(p)
    rate = EventRate(p)
    try:
        for key, payload in CASES:
            t0 = time.monotonic()
            if payload is None:
                p.session.delete(key)
            else:
                p.session.put(key, payload)
            time.sleep(max(0.0, t0 + SETTLE_S - time.monotonic()))  # a window measured, not a wait
            last_second = rate.between(t0 + SETTLE_S - 1.0, t0 + SETTLE_S)
            assert last_second < STORM_RATE, f"{key}: {last_second} events in the third second"
            refused = events(p, "rejected", key)
            assert len(refused) == 1, (key, refused)
            assert refused[0]["source"] == "faults" and "names many keys" in refused[0]["message"]
            assert state(p) == before, key
            assert all(proc.poll() is None for proc in twin.procs.values())
        answered = [e for e in events(p) if e["kind"] in ("input", "clock", "fault_injected",
                                                          "fault_cleared", "command")
                    and keys.has_wildcard(e["key"])]
        assert not answered, answered  # nothing was taken as input
    finally:
        rate.sub.undeclare()


def test_keys_with_wildcards_are_recognised():
    for key in ("lunaris/**", "lunaris/*/x", "**", "lunaris/m/sun$*", "lunaris/m/$*", "a/b$*c"):
        assert keys.has_wildcard(key), key
    for key in ("lunaris/mapp-1/input/sun_angle", "lunaris/m/x$y", "lunaris/m/@adv/x"):
        assert not keys.has_wildcard(key), key
