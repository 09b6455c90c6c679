"""The twin under faults, bursts and attack, in one run: figures, not assertions.

    python bench/reliability.py [--fuzz 10000] [--burst 5000]

- fuzz: bad payloads (testbed/fuzz.py) on every writable key of MAPP: rejections,
  internal errors, services lost, and the time it took;
- burst: injections written as fast as possible, with Zenoh's default congestion control
  (drop) and with Lunaris' (block): how many were answered;
- unknown rover ids: RSS growth of the router, the faults service and the bridge;
- journal: 20,000 fault events, then the size and read-back time of the journal;
- restarts: kill -9 of each service under `lunaris up`, time until its token is back and
  its telemetry flows again; a router restart, time until every service is back.
"""

from __future__ import annotations

import argparse
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import ROOT, machine

from common import keys
from common.config import load_rover
from common.connection import write
from testbed.fuzz import bad_payloads, writable_keys
from testbed.procfs import rss_kib
from testbed.twin import (
    ALL_SERVICES,
    Probe,
    Twin,
    free_endpoint,
    lunaris_cmd,
    open_router,
    static_rover,
    wait_for,
)

R = "mapp-1"
MAPP = static_rover("mapp.yaml")
WITH_BRIDGE = (*ALL_SERVICES, "bridge")


def count(p: Probe, kind: str, key: str | None = None) -> int:
    return sum(1 for e in p.samples(keys.event(R)) if e["kind"] == kind
               and (key is None or e["key"] == key))


def fuzz(p: Probe, twin: Twin, n: int) -> None:
    rng = random.Random(1)
    targets = writable_keys(load_rover(MAPP))
    p.history.clear()
    t0 = time.perf_counter()
    for _ in range(n):
        key = rng.choice(targets)
        write(p.session, key, bad_payloads(key, rng))
    try:
        wait_for(lambda: count(p, "rejected") >= n, 300, "every rejection", poll_s=0.2)
    except AssertionError:
        pass
    took = time.perf_counter() - t0
    lost = sum(1 for proc in twin.procs.values() if proc.poll() is not None)
    print(f"fuzz: {n} bad payloads on {len(targets)} keys: {count(p, 'rejected')} rejections, "
          f"{count(p, 'internal_error')} internal errors, {lost} services lost, "
          f"{count(p, 'fault_injected') + count(p, 'command')} accepted; {took:.1f} s "
          f"({n / took:,.0f} per second)")


def burst(p: Probe, n: int) -> None:
    import zenoh
    key = keys.fault(R, "load/imu", "stuck")
    for name, cc in (("drop (Zenoh's default)", zenoh.CongestionControl.DROP),
                     ("block (Lunaris' tools)", zenoh.CongestionControl.BLOCK)):
        p.history.clear()
        t0 = time.perf_counter()
        for i in range(n):
            p.session.put(key, f"{1 + i * 1e-5:.5f}", congestion_control=cc)
        try:
            wait_for(lambda: count(p, "fault_injected", key) >= n, 60, "the answers", poll_s=0.1)
        except AssertionError:
            pass
        print(f"burst with {name}: {count(p, 'fault_injected', key)} of {n} answered "
              f"in {time.perf_counter() - t0:.1f} s")


def unknown_ids(tmp: Path, n: int = 3000) -> None:
    endpoint = free_endpoint()
    log = (tmp / "router.log").open("wb")
    router = subprocess.Popen(lunaris_cmd("router", "--listen", endpoint), cwd=ROOT, stdout=log,
                              stderr=subprocess.STDOUT)
    try:
        with Twin(endpoint, [MAPP], tmp / "ids", services=WITH_BRIDGE) as twin, Probe(endpoint) as p:
            p.wait_services(R, WITH_BRIDGE)
            pids = {"router": router.pid, "faults": twin.procs["faults"].pid,
                    "bridge": twin.procs["bridge"].pid}
            seen: set[str] = set()
            sub = p.session.declare_subscriber(keys.event("*"), lambda s: seen.add(str(s.key_expr)))
            for i in range(300):
                write(p.session, keys.input_sun_angle(f"warm-{i}"), "1")
            wait_for(lambda: len(seen) >= 300, 60, "warm-up")
            before = {k: rss_kib(v) for k, v in pids.items()}
            for i in range(n):
                write(p.session, keys.input_sun_angle(f"ghost-{i}"), "1")
            wait_for(lambda: len(seen) >= 300 + n, 120, "the rejections")
            after = {k: rss_kib(v) for k, v in pids.items()}
            sub.undeclare()
            print(f"unknown rover ids: RSS growth over {n} ids: " + ", ".join(
                f"{k} {(after[k] - before[k]) / 1024:+.1f} MiB ({(after[k] - before[k]) * 1024 / n:.0f} "
                f"bytes per id)" for k in pids))
    finally:
        router.send_signal(signal.SIGINT)
        router.wait(10)
        log.close()


def journal(p: Probe, cycles: int = 10_000) -> None:
    key = keys.fault(R, "load/imu", "open")
    t0 = time.perf_counter()
    for _ in range(cycles):
        write(p.session, key, b"")
        write(p.session, key, None)
    wait_for(lambda: count(p, "fault_cleared", key) >= cycles, 300, "the cycles", poll_s=0.5)
    took = time.perf_counter() - t0
    t1 = time.perf_counter()
    (events,) = p.get_json(keys.faults_journal(R), timeout_s=60)
    read = time.perf_counter() - t1
    print(f"journal: {2 * cycles} fault events in {took:.1f} s; the journal holds {len(events)} "
          f"events, read back in {read * 1000:.0f} ms")


def restarts(tmp: Path) -> None:
    endpoint = free_endpoint()
    up = subprocess.Popen(lunaris_cmd("up", "--rover", str(MAPP), "--listen", endpoint, "--state-dir",
                                      str(tmp / "up"), "--no-status",
                                      "--services", ",".join(WITH_BRIDGE)),
                          cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        with Probe(endpoint) as p:
            p.watch(keys.under(R))
            p.wait_services(R, WITH_BRIDGE, timeout_s=60)
            children = {}
            for stat in Path("/proc").glob("[0-9]*/cmdline"):
                try:
                    args = stat.read_bytes().split(b"\0")
                    if b"run" in args and str(tmp / "up").encode() in args:
                        children[args[args.index(b"run") + 1].decode()] = int(stat.parent.name)
                except (FileNotFoundError, ValueError, IndexError):
                    continue
            times = []
            for service in WITH_BRIDGE:
                t0 = time.perf_counter()
                subprocess.run(["kill", "-9", str(children[service])], check=True)
                wait_for(lambda s=service: s not in live(p), 10, "the token to go")
                p.wait_services(R, (service,), timeout_s=30)
                times.append(f"{service} {time.perf_counter() - t0:.2f} s")
            print("kill -9 under lunaris up, until the token is back: " + ", ".join(times))
    finally:
        up.send_signal(signal.SIGINT)
        up.wait(30)


def live(p: Probe) -> set[str]:
    return {str(r.ok.key_expr).rsplit("/", 1)[1]
            for r in p.session.liveliness().get(keys.service(R, "*"), timeout=2) if r.ok is not None}


def router_restart(tmp: Path) -> None:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    with Twin(endpoint, [MAPP], tmp / "rr", services=WITH_BRIDGE), Probe(endpoint) as p:
        p.watch(keys.battery_state(R))
        p.wait_services(R, WITH_BRIDGE)
        results = []
        for _ in range(3):
            router.close()
            time.sleep(1.0)  # the outage
            t0 = time.perf_counter()
            router = open_router(endpoint)
            n = len(p.samples(keys.battery_state(R)))
            wait_for(lambda: live(p) >= set(WITH_BRIDGE), 60, "every service back", poll_s=0.05)
            back = time.perf_counter() - t0
            wait_for(lambda n=n: len(p.samples(keys.battery_state(R))) > n + 2, 30, "telemetry")
            results.append(f"{back:.2f} s (telemetry {time.perf_counter() - t0:.2f} s)")
        print("router restart, until every service's token is back: " + ", ".join(results))
    router.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--fuzz", type=int, default=10_000)
    ap.add_argument("--burst", type=int, default=5_000)
    args = ap.parse_args()
    print(f"machine: {machine()}")
    tmp = Path(tempfile.mkdtemp(prefix="lunaris-rel-"))
    endpoint = free_endpoint()
    router = open_router(endpoint)
    try:
        with Twin(endpoint, [MAPP], tmp / "twin", services=WITH_BRIDGE) as twin, Probe(endpoint) as p:
            p.watch(keys.event(R))
            p.wait_services(R, WITH_BRIDGE)
            p.put(keys.clock_control(R), {"paused": True})
            fuzz(p, twin, args.fuzz)
            burst(p, args.burst)
            journal(p)
    finally:
        router.close()
    unknown_ids(tmp)
    restarts(tmp)
    router_restart(tmp)
    print(f"counts by kind are from the probe's own event subscription; state in {tmp}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
