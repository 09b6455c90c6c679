"""The bridge's rates on a clock of the test's own: the bridge service (``serve``) with its
samples put in by hand, its batch hook and rate timer run at the times the test chooses, and
what it publishes recorded with the time it went out. No Zenoh, no waiting: every time below
is exact, up to the rate timer's own step (:data:`RATE_TIMER_S`).

What the live tests (tests/integration/test_bridge.py) leave to the real thing: that a rated
topic flows at all, and that a discrete change arrives.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import msgspec
import pytest

from common import keys
from common.config import load_rover
from common.messages import BatteryState, RailState
from common.runtime import Sample
from services.bridge.service import RATE_TIMER_S, serve
from tests.harness import ROVERS

R = "mapp-1"
MAPP = load_rover(ROVERS / "mapp.yaml")
SLOT = RATE_TIMER_S + 1e-9  # a send due at t goes out at the rate timer's next step at the latest
WALL0 = 1.7e9  # the wall clock when the bridge starts
T0 = 100.0  # the clock when the bridge starts (a monotonic clock has run since the machine started)

MAPPING = """\
bridge: {outputs: {ros2dds: {enabled: false}, rmw_zenoh: {enabled: false}, json: {enabled: true}}}
mappings:
  - {topic: /every_mv, type: std_msgs/msg/Int32, key: 'lunaris/{rover}/battery/state',
     field: voltage_v, scale: 1000}
  - {topic: /fast_mv, type: std_msgs/msg/Int32, key: 'lunaris/{rover}/battery/state',
     field: voltage_v, scale: 1000, rate_hz: 5}
  - {topic: /pdm_mv, type: std_msgs/msg/Int32, key: 'lunaris/{rover}/battery/state',
     field: voltage_v, scale: 1000, rate_hz: 2}
  - {topic: /slow_mv, type: std_msgs/msg/Int32, key: 'lunaris/{rover}/battery/state',
     field: voltage_v, scale: 1000, rate_hz: 0.5}
  - {topic: /rail_mv, type: std_msgs/msg/Int32, key: 'lunaris/{rover}/rail/12V/state',
     field: voltage_v, scale: 1000, rate_hz: 2}
"""


class Bridge:
    """The bridge service on a fake runtime and a fake clock (:attr:`now`, seconds; the test
    speaks of the time since the bridge started)."""

    def __init__(self, folder: Path):
        self.now = T0
        self.handlers: list[tuple[str, Callable[[Sample], None]]] = []
        self.timers: list[list[Any]] = []  # [next time, period, fn]
        self.hooks: list[Callable[[], None]] = []
        self.sent: dict[str, list[tuple[float, Any]]] = {}
        self.published: dict[str, list[tuple[float, Any]]] = {}  # the bridge's own keys
        self.events: list[tuple[float, str, str, str]] = []  # (time, severity, kind, message)
        self.subscribed: set[str] = set()  # the keys some Zenoh subscriber reads
        self.zenoh_session = SimpleNamespace(info=SimpleNamespace(zid=lambda: "0" * 32),
                                             declare_publisher=self._watcher)
        self.t_s = {R: 0.0}
        self.battery = BatteryState(t_s=0.0, energy_j=2.65e5, capacity_j=5.3e5, soc=0.5, ocv_v=15.4,
                                    voltage_v=15.0, current_a=3.0, power_w=45.0, temperature_c=20.0,
                                    operational=True, fault_code=0, faults=[], time_to_empty_s=1e3)
        self.rail = RailState(t_s=0.0, voltage_v=12.0, current_a=1.0, power_w=12.0,
                              current_limit_a=5.0, state="on")
        mapping = folder / "rates.yaml"
        mapping.write_text(MAPPING)
        serve(self, [MAPP], mapping_file=str(mapping), clock=lambda: self.now,  # type: ignore[arg-type]
              wall=lambda: WALL0 + self.now - T0)

    # -- what serve() asks of its runtime -------------------------------------------------------

    def subscribe(self, keyexpr: str, handler: Callable[[Sample], None], **_: Any) -> None:
        self.handlers.append((keyexpr, handler))

    def every(self, period_s: float, fn: Callable[[], None]) -> None:
        self.timers.append([self.now + period_s, period_s, fn])

    def after_batch(self, fn: Callable[[], None], linger_s: float = 0.0) -> None:
        self.hooks.append(fn)

    def urgent_first(self) -> None:
        pass

    def keep(self, _: Any) -> None:
        pass

    def publish_bytes(self, key: str, payload: bytes, *_: Any, **__: Any) -> None:
        self.sent.setdefault(key, []).append((self.now, json.loads(payload)["data"]))

    def publish(self, key: str, msg: Any, **_: Any) -> None:
        self.published.setdefault(key, []).append((self.now - T0, msg))

    def event(self, rover: str, severity: str, kind: str, key: str, message: str,
              *_: Any, **__: Any) -> None:
        self.events.append((self.now - T0, severity, kind, message))

    def _watcher(self, key: str) -> Any:
        """A Zenoh publisher that only says whether a subscriber matches its key."""
        owner = self

        class Watcher:
            @property
            def matching_status(self) -> Any:
                return SimpleNamespace(matching=key in owner.subscribed)
        return Watcher()

    # -- the test's hands ---------------------------------------------------------------------

    def run_until(self, t: float) -> None:
        """Let the clock run to ``t``, each timer firing on its own steps."""
        while (timer := min(self.timers, key=lambda tm: tm[0], default=None)) and timer[0] <= T0 + t:
            self.now = timer[0]
            timer[2]()
            timer[0] += timer[1]
        self.now = T0 + t

    def put(self, t: float, **change: Any) -> None:
        """At ``t``, a sample of the battery's state (or, with ``rail=...``, the 12V rail's)
        with ``change``; then the batch hook, as the worker runs it after each batch."""
        self.run_until(t)
        if "rail" in change:
            self.rail = msgspec.structs.replace(self.rail, t_s=t, **change["rail"])
            key, payload = keys.rail_state(R, "12V"), msgspec.json.encode(self.rail)
        else:
            self.battery = msgspec.structs.replace(self.battery, t_s=t, **change)
            key, payload = keys.battery_state(R), msgspec.json.encode(self.battery)
        _, parts = keys.split(key)
        sample = Sample(key, R, parts, payload, False)
        for keyexpr, handler in self.handlers:
            if keys_match(keyexpr, key):
                handler(sample)
        for hook in self.hooks:
            hook()

    def times(self, topic: str) -> list[float]:
        """When each message of ``topic`` went out, since the bridge started."""
        return [t - T0 for t, _ in self.sent.get(f"json/{topic}", [])]

    def values(self, topic: str) -> list[Any]:
        return [v for _, v in self.sent.get(f"json/{topic}", [])]


def keys_match(keyexpr: str, key: str) -> bool:
    want, got = keyexpr.split("/"), key.split("/")
    return len(want) == len(got) and all(w in ("*", g) for w, g in zip(want, got, strict=True))


@pytest.fixture
def bridge(tmp_path) -> Bridge:
    return Bridge(tmp_path)


def test_a_rate_holds_a_stream_to_its_period_and_sends_the_newest(bridge):
    """The battery's state ten times a second for 3 s (its voltage always moving): the topic
    without a rate sends all 30, the one at 5 Hz one every 0.2 s and the one at 2 Hz one every
    0.5 s, the first at once, each the newest sample when it went."""
    for k in range(30):
        bridge.put(0.05 + 0.1 * k, voltage_v=15.0 - 0.001 * k)
    bridge.run_until(3.0)
    assert bridge.times("every_mv") == pytest.approx([0.05 + 0.1 * k for k in range(30)])
    for topic, period in (("fast_mv", 0.2), ("pdm_mv", 0.5)):
        times = bridge.times(topic)
        assert times[0] == pytest.approx(0.05)  # the first sample at once
        # then on the grid of slots t0 + k period, each within a timer step of its slot
        late = [t - (times[0] + k * period) for k, t in enumerate(times)]
        assert all(-1e-9 <= d < SLOT for d in late), (topic, late)
        assert len(times) == 1 + int((3.0 - 0.05) / period), (topic, times)
        for t, mv in zip(times, bridge.values(topic), strict=True):  # the newest when it went
            newest = max(k for k in range(30) if 0.05 + 0.1 * k <= t + 1e-9)
            assert mv == round((15.0 - 0.001 * newest) * 1000), (topic, t)


def test_a_discrete_change_goes_at_once_and_leaves_the_grid_as_it_was(bridge):
    """The 12V rail at 2 Hz: a change of its state (it fails) goes out the moment it arrives,
    between two slots; its next sample goes out at the slot it would have had anyway."""
    for k in range(12):
        bridge.put(0.05 + 0.1 * k, rail={"voltage_v": 12.0 + 0.001 * k})
    grid = bridge.times("rail_mv")
    assert len(grid) == 3  # 0.05, 0.55, 1.05
    bridge.put(1.23, rail={"voltage_v": 0.0, "state": "failed"})
    assert bridge.times("rail_mv")[-1] == pytest.approx(1.23) and bridge.values("rail_mv")[-1] == 0
    bridge.put(1.25, rail={"voltage_v": 0.001})
    bridge.run_until(2.0)
    assert bridge.times("rail_mv")[3:] == pytest.approx([1.23, grid[-1] + 0.5], abs=SLOT)
    assert bridge.times("rail_mv")[-1] >= grid[-1] + 0.5 - 1e-9
    assert bridge.values("rail_mv")[3:] == [0, 1]


def test_after_a_silence_the_first_sample_goes_at_once_and_the_next_waits_for_its_slot(bridge):
    """At 0.5 Hz (a slot every 2 s): the first sample goes at once; one right behind it waits
    for the next slot, 2 s after the first; no sample at the slot after that (the outlet goes
    idle), and the next one, 0.5 s after that silent slot, goes at once, not at the slot 1.5 s
    later; a change of a discrete field goes at once; the grid keeps its slots throughout."""
    bridge.put(1.0, voltage_v=15.0)
    assert bridge.times("slow_mv") == pytest.approx([1.0])
    bridge.put(1.1, voltage_v=15.1)
    bridge.run_until(2.9)
    assert bridge.times("slow_mv") == pytest.approx([1.0])  # held
    bridge.run_until(3.0 + SLOT)
    assert bridge.times("slow_mv")[1] == pytest.approx(3.0, abs=SLOT)
    assert bridge.values("slow_mv") == [15000, 15100]
    bridge.run_until(5.0 + SLOT)  # the slot at 5 s: nothing new, the outlet goes idle
    assert len(bridge.times("slow_mv")) == 2
    bridge.put(5.5, voltage_v=15.2)
    assert bridge.times("slow_mv")[-1] == pytest.approx(5.5) and bridge.values("slow_mv")[-1] == 15200
    bridge.put(5.6, voltage_v=15.3, operational=False)
    assert bridge.times("slow_mv")[-1] == pytest.approx(5.6) and bridge.values("slow_mv")[-1] == 15300
    bridge.put(5.7, voltage_v=15.4)  # not discrete: held to the grid's next slot (1 + 2k s)
    bridge.run_until(6.9)
    assert bridge.times("slow_mv")[-1] == pytest.approx(5.6)
    bridge.run_until(7.0 + SLOT)
    assert bridge.times("slow_mv")[-1] == pytest.approx(7.0, abs=SLOT)


def test_a_late_timer_starts_the_grid_again_from_when_it_ran(bridge):
    """A timer that runs late (the worker was busy) does not send a burst to catch up: the
    held sample goes when the timer runs, and the next slot is a period after that."""
    bridge.put(0.0, voltage_v=15.0)
    bridge.put(0.1, voltage_v=15.1)
    for timer in bridge.timers:  # the worker busy for 1.3 s: no timer runs before 1.3
        timer[0] = max(timer[0], T0 + 1.3)
    bridge.put(0.6, voltage_v=15.2)
    bridge.run_until(1.3)
    for topic in ("fast_mv", "pdm_mv"):
        assert bridge.times(topic) == pytest.approx([0.0, 1.3]), topic
        assert bridge.values(topic) == [15000, 15200], topic
    bridge.put(1.4, voltage_v=15.3)
    bridge.run_until(2.0)
    assert bridge.times("pdm_mv")[2:] == pytest.approx([1.8], abs=SLOT)


def test_the_delivery_record_counts_the_sends_and_says_when_the_dashboard_stops_reading(bridge):
    """SPEC §13d: once a second the rover's ``bridge/delivery`` (the json flavour here): the
    messages sent and the last send; receiving while a subscriber reads the rover's watched
    topic, silent since the moment none does, and "not discovered" in the log's event after
    3 s of that; receiving again, and said so, when one is back."""
    bridge.subscribed.add("json/every_mv")  # the rover's first topic (no /diagnostics here)
    for k in range(30):
        bridge.put(0.05 + 0.1 * k, voltage_v=15.0 - 0.001 * k)
    bridge.run_until(3.0)
    records = bridge.published[keys.BRIDGE_DELIVERY.key(R)]
    assert [round(t, 6) for t, _ in records] == [1.0, 2.0, 3.0]
    last = records[-1][1]
    (flavour,) = last.flavours
    assert flavour.flavour == "json" and flavour.readers == 1 and last.receiving
    assert flavour.sent == sum(len(v) for v in bridge.sent.values())
    assert flavour.last_send_wall_s == pytest.approx(WALL0 + 2.95)
    bridge.subscribed.clear()  # the dashboard goes away
    bridge.run_until(4.0)
    last = bridge.published[keys.BRIDGE_DELIVERY.key(R)][-1][1]
    assert not last.receiving and last.silent_since_wall_s == pytest.approx(WALL0 + 4.0)
    assert bridge.events == []
    bridge.run_until(7.0)
    assert [(t, sev, kind) for t, sev, kind, _ in bridge.events] == [(pytest.approx(7.0), "warning",
                                                                       "delivery")]
    assert "not discovered" in bridge.events[0][3]
    bridge.subscribed.add("json/every_mv")
    bridge.run_until(8.0)
    last = bridge.published[keys.BRIDGE_DELIVERY.key(R)][-1][1]
    assert last.receiving and last.silent_since_wall_s is None
    assert bridge.events[-1][1:3] == ("info", "delivery")
