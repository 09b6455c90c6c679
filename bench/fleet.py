"""Fleet: one process per model kind serving 25 MAPP-class rovers at 10 Hz (SPEC §10).

Runs the services for N copies of mapp.yaml (ids mapp-01 ...) for a while and
reports, per second of wall time: clock ticks, battery states, power summaries and
the bridge's BatteryState messages received per rover (at least 10 each when keeping
up; the battery and PDM also republish at once when an input changes), how far the battery's
and the PDM's sim time trail the clock, and each service process's CPU use.
Run: `.venv/bin/python bench/fleet.py [ROVERS] [SECONDS]`.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

import msgspec
from benchlib import ROOT, machine, running_twin

from common import keys
from common.messages import BatteryState, Clock, PowerSummary

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "faults", "bridge")


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 25
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
    base = (ROOT / "config/rovers/mapp.yaml").read_text()
    with tempfile.TemporaryDirectory(prefix="lunaris-fleet-") as tmp:
        files = []
        for i in range(1, n + 1):
            f = Path(tmp) / f"mapp-{i:02d}.yaml"
            f.write_text(base.replace("id: mapp-1", f"id: mapp-{i:02d}"))
            files.append(f)
        print(f"fleet: {n} MAPP rovers at 10 Hz, {seconds:g} s ({machine()})")
        counts: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
        latest_t: dict[tuple[str, str], float] = {}
        lags: dict[str, list[float]] = defaultdict(list)
        lock = threading.Lock()
        decoders = {"clock": msgspec.json.Decoder(Clock),
                    "battery": msgspec.json.Decoder(BatteryState),
                    "power": msgspec.json.Decoder(PowerSummary)}

        def on(kind: str):
            def cb(s) -> None:
                rover, _ = keys.split(str(s.key_expr))
                t = decoders[kind].decode(s.payload.to_bytes()).t_s
                with lock:
                    counts[kind][rover] += 1
                    latest_t[(kind, rover)] = t
                    if kind != "clock":
                        lags[kind].append(latest_t.get(("clock", rover), t) - t)
            return cb

        with running_twin(files, SERVICES) as (probe, twin, _):
            for r in (f"mapp-{i:02d}" for i in (1, n)):
                probe.wait_services(r, SERVICES, timeout_s=60)
            subs = [probe.session.declare_subscriber(f"lunaris/*/{k}", on(kind)) for kind, k in
                    (("clock", "clock"), ("battery", "battery/state"), ("power", "power/summary"))]

            def on_bridge(s) -> None:  # ros2dds key of the fleet topic /mapp_NN/battery_state
                rover = str(s.key_expr).split("/")[0].replace("_", "-")
                with lock:
                    counts["bridge"][rover] += 1
            subs.append(probe.session.declare_subscriber("*/battery_state", on_bridge))
            time.sleep(2.0)  # let start-up transients pass before measuring
            with lock:
                counts.clear()
                lags.clear()
                t_clock0 = {r: latest_t.get(("clock", r), 0.0) for r in (f"mapp-{i:02d}" for i in
                                                                          range(1, n + 1))}
            cpu0 = {s: cpu_s(p.pid) for s, p in twin.procs.items()}
            w0 = time.monotonic()
            time.sleep(seconds)
            wall = time.monotonic() - w0
            cpu1 = {s: cpu_s(p.pid) for s, p in twin.procs.items()}
            with lock:
                snap = {k: dict(v) for k, v in counts.items()}
                sim_advance = [latest_t.get(("clock", r), 0.0) - t0 for r, t0 in t_clock0.items()]
                lag = {k: sorted(v) for k, v in lags.items()}
            del subs
    for kind in ("clock", "battery", "power", "bridge"):
        per = [snap.get(kind, {}).get(f"mapp-{i:02d}", 0) / wall for i in range(1, n + 1)]
        print(f"  {kind:<8} samples per rover per second: min {min(per):.2f}  "
              f"mean {sum(per) / n:.2f}  (>= 10.00 when keeping up)")
    print(f"  sim time advanced per wall second: min {min(sim_advance) / wall:.3f}  "
          f"max {max(sim_advance) / wall:.3f}")
    for kind, v in lag.items():
        if v:
            print(f"  {kind:<8} sim-time lag behind the clock: p50 {v[len(v) // 2] * 1e3:.0f} ms  "
                  f"p99 {v[int(0.99 * (len(v) - 1))] * 1e3:.0f} ms  max {v[-1] * 1e3:.0f} ms")
    total = 0.0
    for s in SERVICES:
        used = (cpu1[s] - cpu0[s]) / wall * 100
        total += used
        print(f"  cpu {s:<8} {used:5.1f} %")
    print(f"  cpu total    {total:5.1f} % of one core ({total / (os.cpu_count() or 1):.1f} % of the machine)")


if __name__ == "__main__":
    main()
