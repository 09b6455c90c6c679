"""``lunaris sim FILE --hours H``: an accelerated run of the composed models, no Zenoh.

For the vehicle engineer checking a power budget: state of charge over the run,
when rails are shed, when (if ever) the pack is depleted.
"""

from __future__ import annotations

import argparse
import sys
import time

from lunaris.run import load_rovers
from services.composed import run_budget

__all__ = ["add_arguments", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="rover definition")
    p.add_argument("--hours", type=float, default=8.0, help="simulated hours (default 8)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the loads")


def _hms(t_s: float) -> str:
    h, rem = divmod(int(t_s), 3600)
    return f"{h:d}:{rem // 60:02d}:{rem % 60:02d}"


def main(args: argparse.Namespace) -> int:
    if not args.hours > 0:
        print(f"--hours must be > 0, got {args.hours}", file=sys.stderr)
        return 2
    (rover,) = load_rovers([args.file])
    print(f"{rover.id}: {args.hours:g} simulated hours at {rover.tick_hz:g} Hz")

    def progress(done: int, total: int, twin) -> None:
        print(f"  {done / total:5.0%}  t={_hms(twin.t_s)}  soc={twin.battery.soc:.4f}", flush=True)

    t0 = time.perf_counter()
    b = run_budget(rover, args.hours, args.seed, progress)
    wall = time.perf_counter() - t0
    print(f"done: {b.ticks} ticks in {wall:.2f} s ({b.simulated_s / wall:,.0f}x real time)")
    print(f"  state of charge   {b.final_soc:.4f} at the end, {b.min_soc:.4f} at the lowest")
    print(f"  energy used       {b.energy_used_j / 3600:.1f} Wh")
    print(f"  mean load         {b.mean_load_w:.1f} W, mean generation {b.mean_generation_w:.1f} W")
    print(f"  peak temperature  {b.peak_temperature_c:.1f} C")
    for rail, t in sorted(b.shed_at_s.items(), key=lambda kv: kv[1]):
        print(f"  rail {rail} shed at {_hms(t)}")
    print(f"  depleted at {_hms(b.depleted_at_s)}" if b.depleted_at_s is not None
          else "  never depleted")
    print(f"  under-voltage cut-off at {_hms(b.cutoff_at_s)}" if b.cutoff_at_s is not None
          else "  never cut off for under-voltage")
    return 0
