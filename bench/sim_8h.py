"""The models composed in one process, no Zenoh: 8 simulated hours of a MAPP rover at
10 Hz (SPEC §10 target: under 10 s). Run: `.venv/bin/python bench/sim_8h.py [HOURS]`."""

from __future__ import annotations

import sys
import time

from benchlib import ROOT, machine

from common.config import load_rover
from services.composed import run_budget


def main() -> None:
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 8.0
    rover = load_rover(ROOT / "config/rovers/mapp.yaml")
    print(f"composed models: {hours:g} simulated hours of {rover.id} at {rover.tick_hz:g} Hz "
          f"({machine()})")
    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        budget = run_budget(rover, hours, seed=0)
        walls.append(time.perf_counter() - t0)
    best, worst = min(walls), max(walls)
    print(f"  {budget.ticks} ticks: best {best:.2f} s, worst {worst:.2f} s of 3 runs "
          f"({budget.simulated_s / best:,.0f}x real time, {best / budget.ticks * 1e6:.1f} us/tick)")
    print(f"  final soc {budget.final_soc:.4f}, energy used {budget.energy_used_j / 3600:.1f} Wh")


if __name__ == "__main__":
    main()
