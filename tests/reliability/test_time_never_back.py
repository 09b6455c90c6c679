"""Sim time never goes back within an epoch: not across kill -9 of everything, not when a
service starts before the clock is back, not when the clock's own state is damaged.

Found (issue 23.8, 23.3): after kill -9 of all nine services at once, drive, solar panels,
umbilical and radio published ``t_s`` 0.0 after 799.5; with clock and battery killed,
``battery/state`` and ``faults/active/battery`` did the same (each restarted service learnt
no time before the clock was back, and published with 0). A garbage clock state sent sim
time from 433 back to 25 s in the same epoch, and froze the battery (its pack had reached
433 s). Now each service saves the time it reached, publishes nothing stamped before a tick
has reached it again, ignores ticks from before it, and a clock that lost its state goes
on from the latest time it finds (its own saved time, or the other services').
"""

from __future__ import annotations

import random

import pytest

from common import keys
from tests.harness import ROVERS, Probe, Twin
from tests.reliability.conftest import R, kill9

pytestmark = pytest.mark.timeout(180)

EVERYTHING = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
SCALE = 20.0


def stamped(p: Probe) -> dict[str, list[float]]:
    """Every key of the rover the probe saw with a ``t_s`` (telemetry and the faults in
    effect; not events), each with its times in the order received (the tests here stay in
    one epoch: no reset, no restore)."""
    prefix = keys.rover_prefix(R) + "/"
    with p._lock:
        items = {k: list(v) for k, v in p.history.items() if k.startswith(prefix)}
    return {k: [v["t_s"] for v in vs if isinstance(v, dict) and "t_s" in v]
            for k, vs in items.items() if "/event" not in k}


def went_back(p: Probe) -> dict[str, tuple[float, float]]:
    """The keys whose t_s went back, each with the first (before, after) pair that did."""
    out = {}
    for key, times in stamped(p).items():
        for a, b in zip(times, times[1:], strict=False):
            if b < a:
                out[key] = (a, b)
                break
    return out


def run_up(p: Probe, twin: Twin, services: tuple[str, ...]) -> float:
    """A twin at x20 until t > 100 s: the latest tick's time."""
    p.wait_services(R, services, timeout_s=30)
    p.put(keys.clock_control(R), {"time_scale": SCALE})
    return p.wait_value(keys.clock(R), lambda c: c["t_s"] > 100, timeout_s=30)["t_s"]


def test_kill_9_of_every_service_at_once_never_sends_time_back(twin_factory, probe_solo):
    p = probe_solo
    p.watch(keys.under(R))
    twin = twin_factory([ROVERS / "mapp.yaml"], services=EVERYTHING)
    reached = run_up(p, twin, EVERYTHING)
    p.put(keys.fault(R, "battery", "heating"), 2)
    p.wait_value(keys.faults_active(R, "battery"), lambda a: a["faults"])
    for proc in twin.procs.values():  # at once
        proc.kill()
    for proc in twin.procs.values():
        proc.wait(10)
    others = [s for s in EVERYTHING if s != "clock"]
    for service in random.Random(3).sample(others, len(others)):  # before the clock is back
        twin.start(service)
    p.wait_services(R, tuple(others), timeout_s=30)
    twin.start("clock")
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > reached + 40, timeout_s=30)
    for key in (keys.battery_state(R), keys.drive_state(R), keys.umbilical_state(R),
                keys.solar_power(R, "left"), keys.radio_link(R, "lander")):
        p.wait_value(key, lambda v: v["t_s"] > reached + 20)
    assert not went_back(p), went_back(p)
    assert min(stamped(p)[keys.battery_state(R)][-1:]) > reached


def test_clock_and_battery_killed_the_battery_back_first(twin_factory, probe_solo):
    p = probe_solo
    p.watch(keys.under(R))
    services = ("clock", "battery", "loads", "power")
    twin = twin_factory([ROVERS / "mapp.yaml"], services=services)
    reached = run_up(p, twin, services)
    p.put(keys.fault(R, "battery", "heating"), 2)
    p.wait_value(keys.faults_active(R, "battery"), lambda a: a["faults"])
    kill9(twin, "clock")
    kill9(twin, "battery")
    twin.start("battery")
    p.wait_services(R, ("battery",))
    twin.start("clock")
    p.wait_value(keys.battery_state(R), lambda b: b["t_s"] > reached + 20, timeout_s=30)
    active = p.wait_value(keys.faults_active(R, "battery"), lambda a: a["t_s"] > reached)
    assert any(f["key"].endswith("/heating") for f in active["faults"])
    assert not went_back(p), went_back(p)


DOWN = ("clock", "battery", "loads", "power")


@pytest.mark.parametrize("case", ["the others up", "everything down",
                                  "everything down, its saved time lost too"])
def test_a_clock_with_a_damaged_state_goes_on_from_the_latest_time(twin_factory, probe_solo, case):
    """A garbage clock state: the clock goes on from the latest time it finds - the other
    services' (they are up), its own saved time (they are down too), or, both lost, the
    time the others saved, once they are back (its ticks wait for them)."""
    p = probe_solo
    p.watch(keys.under(R))
    twin = twin_factory([ROVERS / "mapp.yaml"], services=DOWN)
    run_up(p, twin, DOWN)
    epoch = p.value(keys.clock(R))["epoch"]
    killed = ("clock",) if case == "the others up" else DOWN
    for service in killed:
        kill9(twin, service)
    last = max(c["t_s"] for c in p.samples(keys.clock(R)))
    (twin.state_dir / "clock-state.json").write_bytes(b'{"mapp-1": {"state": {"t_s": "lots"')
    if case != "everything down":
        (twin.state_dir / "clock-time.json").write_text("garbage")
    ticks = len(p.samples(keys.clock(R)))
    twin.start("clock")  # the clock first: before the others are back, if they are down
    p.wait_services(R, ("clock",), timeout_s=30)
    for service in killed[1:]:
        twin.start(service)
    p.wait_services(R, DOWN, timeout_s=30)
    event = p.wait_event(R, lambda e: e["kind"] == "state_damaged" and "clock state" in e["message"])
    p.put(keys.clock_control(R), {"time_scale": SCALE})  # its speed went with its state
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > last + 20, timeout_s=30)
    after = p.samples(keys.clock(R))[ticks:]
    assert all(c["epoch"] == epoch for c in after), after[:3]
    # the battery goes on with the clock, not frozen at the time it had reached
    p.wait_value(keys.battery_state(R), lambda b: b["t_s"] > last + 20)
    if case == "everything down, its saved time lost too":
        assert "its ticks wait" in event["message"], event
        # the others saved their time once a second: no more than that is lost, never all
        assert min(c["t_s"] for c in after) >= last - SCALE * 1.5, (last, after[:3])
        p.wait_event(R, lambda e: e["kind"] == "clock" and "time resumed at" in e["message"])
    else:
        assert "time resumed at" in event["message"], event
        assert min(c["t_s"] for c in after) >= last, (last, after[:3])
        assert not went_back(p), went_back(p)
