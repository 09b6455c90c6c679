"""A fleet (issue 14): from ``POLL_FROM_ROVERS`` rovers every service drains its tick-rate
telemetry from Zenoh channels instead of one Python callback per sample. The twin must
behave the same: every tick of every rover stepped and published once, a fault on one rover
tripping its rail and showing on its dashboard at once, the other rovers untouched."""

from __future__ import annotations

import subprocess
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

import msgspec
import pytest
import zenoh

from common import keys
from common.runtime import POLL_FROM_ROVERS
from services.bridge.rmw_zenoh import rmw_topic_key
from tests import rosmsg
from tests.harness import ROOT, free_endpoint, lunaris_cmd, mapp_fleet, stop_process, wait_for

pytestmark = pytest.mark.timeout(180)

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "faults", "bridge")
WATCHED = ("mapp-01", "mapp-10", f"mapp-{POLL_FROM_ROVERS:02d}")


@pytest.fixture
def fleet(twin_factory, tmp_path):
    files = mapp_fleet(tmp_path, POLL_FROM_ROVERS)
    return lambda: twin_factory(files, services=SERVICES)


def test_a_fleet_drains_its_telemetry_and_loses_or_doubles_nothing(fleet, probe):
    seen: dict[tuple[str, str], list[float]] = defaultdict(list)  # (rover, key tail) -> t_s
    lock = threading.Lock()

    def on_sample(s) -> None:
        rover, parts = keys.split(str(s.key_expr))
        t = msgspec.json.decode(s.payload.to_bytes())["t_s"]
        with lock:
            seen[rover, "/".join(parts)].append(round(t, 3))

    subs = [probe.session.declare_subscriber(k, on_sample) for r in WATCHED
            for k in (keys.battery_state(r), keys.rail_state(r, "5V_CH2"), keys.power_summary(r))]
    twin = fleet()
    for r in WATCHED:
        probe.wait_services(r, SERVICES, timeout_s=60)
    for service in SERVICES:  # the path under test is the one taken
        wait_for(lambda s=service: f"{POLL_FROM_ROVERS} rovers:" in twin.log(s), 10,
                 f"{service} to drain its telemetry from channels")

    # 30 ticks of the three watched rovers, once they are all running
    def last_t(rover: str) -> float:
        with lock:
            return max(seen[rover, "battery/state"], default=0.0)
    wait_for(lambda: min(last_t(r) for r in WATCHED) > 2.0, 60, "every watched rover's battery")
    start = min(last_t(r) for r in WATCHED)
    wait_for(lambda: min(last_t(r) for r in WATCHED) > start + 3.2, 30, "30 more ticks")
    ticks = [round(start + 0.1 * k, 3) for k in range(1, 31)]
    with lock:
        counts = {key: Counter(ts) for key, ts in seen.items()}
    for r in WATCHED:
        for tail in ("battery/state", "rail/5V_CH2/state", "power/summary"):
            per_tick = counts[r, tail]
            lost = [t for t in ticks if per_tick[t] == 0]
            doubled = [t for t in ticks if per_tick[t] > 1]
            assert not lost, f"{r} {tail}: no sample for ticks {lost}"
            # a tick's second sample is the PDM re-solving when a burst of its loads was split
            # over two batches; never more than a few in 30 ticks
            assert len(doubled) <= 3, f"{r} {tail}: {len(doubled)} ticks doubled: {per_tick}"
        assert not [t for t in ticks if counts[r, "battery/state"][t] > 1], \
            f"{r}: two battery states for one tick: {counts[r, 'battery/state']}"
    for sub in subs:
        sub.undeclare()

    # a fault on the last rover: its rail trips and its dashboard says so at once
    victim = WATCHED[-1]
    diag: list[float] = []
    armed = [0.0]

    def on_diag(s) -> None:
        msg = rosmsg.decode("diagnostic_msgs/msg/DiagnosticArray", s.payload.to_bytes())
        # the crew's view: the short is the rail's over-current trip (SPEC §12b)
        if armed[0] and any(st.name == f"{victim}/rail/5V_CH2" and
                            "tripped" in [v.key for v in st.values] for st in msg.status):
            diag.append(time.monotonic() - armed[0])
    probe.watch(f"lunaris/{victim}/rail/**")
    probe.watch("lunaris/mapp-01/rail/**")
    sub = probe.session.declare_subscriber(f"{victim.replace('-', '_')}/diagnostics", on_diag)
    armed[0] = time.monotonic()
    probe.put(keys.fault(victim, "load/nav_camera", "short"))
    probe.wait_value(keys.rail_state(victim, "5V_CH2"), lambda v: v["state"] == "tripped")
    wait_for(lambda: diag, 5, f"the trip on {victim}'s /diagnostics")
    assert diag[0] < 1.0, f"the trip reached the dashboard after {diag[0]:.3f} s"
    assert probe.wait_value(keys.rail_state("mapp-01", "5V_CH2"))["state"] == "on"
    probe.delete(keys.fault(victim, "load/nav_camera", "short"))
    probe.put(keys.cmd_rail(victim, "5V_CH2"), {"reset": True})
    probe.wait_value(keys.rail_state(victim, "5V_CH2"), lambda v: v["state"] == "on")
    sub.undeclare()


def test_a_fleet_service_declares_each_key_it_hears_once_and_no_forged_ones_past_a_bound(
        router, probe, tmp_path):
    """Zenoh matches the key of a sample it does not know against every key expression the
    session declared (a fleet service's ~1,000 publishers: most of its receive thread's CPU);
    a declared key is looked up. So a fleet's service declares each telemetry key it hears,
    once, and a flood of forged names for a served rover stops at the runtime's bound."""
    from common.connection import make_config
    from common.runtime import Runtime

    rovers = [f"r-{i:02d}" for i in range(1, POLL_FROM_ROVERS + 1)]
    heard: list[str] = []
    with Runtime("probe-service", rovers, make_config(connect=[router]), tmp_path) as rt:
        assert rt.polled
        rt.subscribe(keys.load_power("*", "*"), lambda s: heard.append(s.key), telemetry=True)
        real = [keys.load_power(r, load) for r in rovers for load in ("heater", "camera")]

        def every_key_heard() -> bool:  # each round sends every key again
            for key in real:
                probe.session.put(key, b'{"power_w": 1.0}')
            rt.worker.drain(time.monotonic() + 0.5)
            return set(heard) == set(real)
        wait_for(every_key_heard, 10, "every served rover's keys")
        assert set(rt._heard) == set(real)  # each key once, whatever the number of samples
        heard.clear()
        for i in range(150 * len(rovers)):
            probe.session.put(keys.load_power("r-01", f"ghost-{i}"), b'{"power_w": 1.0}',
                              congestion_control=zenoh.CongestionControl.BLOCK)
        probe.session.put(real[-1], b'{"power_w": 1.0}')  # after the flood, on the same path

        def flood_drained() -> bool:
            rt.worker.drain(time.monotonic() + 0.5)
            return real[-1] in heard
        wait_for(flood_drained, 20, "the forged samples and the one after them")
        # the forged names were declared up to the bound, not past it
        assert len(real) < len(rt._heard) <= 100 * len(rovers)
        assert set(real) <= set(rt._heard)


def test_a_fault_goes_ahead_of_a_fleets_telemetry_and_a_command_after_what_came_before_it(
        router, probe, tmp_path, monkeypatch):
    """A fault is what the crew is trained on: the worker handles it ahead of the telemetry
    waiting in its channels, breaking off a burst for it. A command (a rail reset) is judged
    on the telemetry heard before it: that goes first."""
    from common.connection import make_config
    from common.runtime import Runtime

    # The order within one batch; a batch ends after 20 ms of work (the hooks and timers then
    # run), which a loaded machine could reach here while the second fault is on its way.
    monkeypatch.setattr("common.worker.MAX_BATCH_S", 10.0)

    rovers = [f"r-{i:02d}" for i in range(1, POLL_FROM_ROVERS + 1)]
    order: list[str] = []
    fault, command = keys.fault("r-01", "load/heater", "short"), keys.cmd_rail("r-01", "5V")
    second_fault = keys.fault("r-02", "load/heater", "short")

    def on_telemetry(s) -> None:
        order.append(s.key)
        if len(order) == 11:  # a fault comes in the middle of a burst
            probe.session.put(second_fault, b"")
            wait_for(lambda: rt.worker._urgent, 5, "the second fault queued")

    with Runtime("probe-service", rovers, make_config(connect=[router]), tmp_path) as rt:
        rt.subscribe(keys.load_power("*", "*"), on_telemetry, telemetry=True)
        rt.subscribe(keys.cmd_rail("*", "*"), lambda s: order.append(s.key))
        rt.subscribe(keys.fault_prefix("*", "load"), lambda s: order.append(s.key), urgent=True)
        burst = [keys.load_power(r, "heater") for r in rovers] * 2
        # one session's publishers, one link, in this order: the burst, the command, the fault;
        # each written once the router has this runtime's subscriber for it (else it is lost)
        pubs = {key: probe.session.declare_publisher(
                    key, congestion_control=zenoh.CongestionControl.BLOCK)
                for key in (*dict.fromkeys(burst), command, fault)}
        wait_for(lambda: all(p.matching_status.matching for p in pubs.values()), 10,
                 "the runtime's subscribers known to the router")
        for key in burst:
            pubs[key].put(b'{"power_w": 1.0}')
        pubs[command].put(b'{"reset": true}')
        pubs[fault].put(b"")
        wait_for(lambda: rt.worker._urgent and not rt.worker._queue.empty(), 10,
                 "the command and the fault queued")
        worker = threading.Thread(target=rt.worker.run, daemon=True)
        worker.start()
        try:
            wait_for(lambda: len(order) == len(burst) + 3, 10, lambda: f"all handled: {order}")
        finally:
            rt.stop()
            worker.join(5)
    assert order[0] == fault  # ahead of the burst waiting when it came
    assert order[11] == second_fault  # the burst broken off for it
    assert order[-1] == command  # after the whole burst that came before it
    assert sorted(o for o in order if o in burst) == sorted(burst)  # nothing lost or doubled


def test_a_fleets_bridge_hears_each_inbound_topic_once_for_all_its_rovers(
        twin_factory, probe, tmp_path):
    """The dashboard's inbound topics of the rovers a bridge shard serves: one subscription
    per topic and flavour (each with a thread of its own), not one per rover; a message on a
    served rover's topic reaches its input once, in each flavour, and one on another shard's
    rover is not this shard's to write."""
    n = 2 * POLL_FROM_ROVERS  # the first of two shards serves every other rover: a fleet's worth
    files = mapp_fleet(tmp_path, n)
    written: list[str] = []
    sub = probe.session.declare_subscriber(keys.input_radio_position("*", "*"),
                                           lambda s: written.append(str(s.key_expr)))
    twin = twin_factory(files, services=("bridge",), extra={"bridge": ["--shard", "1/2"]})
    probe.wait_services("mapp-01", ("bridge",), timeout_s=60)
    probe.wait_services(f"mapp-{n - 1:02d}", ("bridge",), timeout_s=60)
    threads = len(list(Path(f"/proc/{twin.procs['bridge'].pid}/task").iterdir()))
    # Zenoh's own, the worker, one per callback subscription: 19 when written. Per rover it
    # was 11 more (5 inbound topics in 2 flavours, the faults in effect): 209 here. The crew's
    # controls add a fixed 16 whatever the rovers: the answers and the owners' liveliness (2),
    # a queryable per service and flavour (set_enabled, reset: 4), the rails' Bool enable
    # topics (5 rails of the MAPP in 2 flavours: 10). 35 when written; per rover, 20 more.
    assert threads < 40, f"the bridge shard of {n // 2} rovers runs {threads} threads"

    cdr = rosmsg.encode("std_msgs/msg/Float64MultiArray",
                        {"layout": {"dim": [], "data_offset": 0}, "data": [100.0, 30.0]})

    def topic_keys(rover: str, place: int) -> dict[str, str]:
        """The rover's inbound position topic: ros2dds in its namespace, rmw_zenoh in its
        ROS 2 domain (its place in the fleet)."""
        return {"ros2dds": f"{rover.replace('-', '_')}/curr_to_receiving_radio_m",
                "rmw_zenoh": rmw_topic_key(place, "/curr_to_receiving_radio_m",
                                           "std_msgs/msg/Float64MultiArray")}

    served, target = topic_keys("mapp-05", 4), keys.input_radio_position("mapp-05", "lander")
    for flavour, key in served.items():
        written.clear()
        # until the bridge's subscription has it (declared as the bridge starts)
        wait_for(lambda k=key: probe.session.put(k, cdr) or target in written, 10, flavour)
        time.sleep(0.3)  # a window for a second writer to show (absence), not a synchronisation
        before = len(written)
        probe.session.put(key, cdr)
        wait_for(lambda b=before: len(written) > b, 5, f"the {flavour} position written")
        time.sleep(0.3)
        assert written[before:] == [target], f"{flavour}: {written[before:]}"
    written.clear()
    for key in topic_keys("mapp-06", 5).values():  # the other shard's rover
        probe.session.put(key, cdr)
    time.sleep(0.5)
    assert written == []
    sub.undeclare()


def test_lunaris_up_shares_a_large_fleet_among_bridges_by_default(tmp_path):
    """Without ``--bridges``, ``lunaris up`` starts one bridge process per 50 rovers."""
    from lunaris.up import ROVERS_PER_BRIDGE, default_bridges

    assert [default_bridges(n) for n in (1, ROVERS_PER_BRIDGE, ROVERS_PER_BRIDGE + 1, 100, 101)] \
        == [1, 1, 2, 2, 3]
    args = [a for f in mapp_fleet(tmp_path, ROVERS_PER_BRIDGE + 1) for a in ("--rover", str(f))]
    up = subprocess.Popen(lunaris_cmd("up", *args, "--listen", free_endpoint(), "--services", "bridge",
                                      "--no-status", "--state-dir", str(tmp_path / "state")),
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(up.stdout.readline, "")), daemon=True)
    reader.start()
    try:
        wait_for(lambda: any("[up] bridge" in x and "started" in x for x in lines), 60,
                 lambda: f"a bridge started: {lines[-5:]}")
        wait_for(lambda: sum("started" in x and "[up] bridge-" in x for x in lines) >= 2, 10,
                 lambda: f"two bridges started: {lines[-5:]}")
        assert not any("[up] bridge-3" in x or "[up] bridge started" in x for x in lines), lines
    finally:
        stop_process(up, timeout_s=20)
        reader.join(timeout=5)
