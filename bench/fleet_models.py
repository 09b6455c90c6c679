"""The models' work per rover per tick in a fleet's loads and power services (SPEC §10), without
Zenoh: what falls as the fleet grows, side by side with what one model per rover costs.

For N MAPP-class rovers (drive left out, as in ``bench/fleet.py``), microseconds per rover per
tick of:

- the loads' draw: one ``LoadsModel.sample`` per rover (how the service drew until the fleet
  drew together) against ``LoadsFleet.sample`` (every load of every rover, 16 ticks at once);
- the loads' publication work but the put: each load's power, its ``LoadPower`` and its JSON;
- the PDM's: ``PowerModel.compute``, the rails' and the summary's messages and their JSON.

The rovers tick in turn, as a fleet's clocks do. Each figure is the best of ``REPEATS`` runs
of ``TICKS`` ticks (the least disturbed by the rest of the machine). Run:
``.venv/bin/python bench/fleet_models.py [N ...]`` (default 1 10 100 200).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from benchlib import machine

from common import keys
from common.config import Rover, load_rover
from common.messages import LoadPower, PowerSummary, RailState, encode
from services.loads.model import LoadsFleet, LoadsModel
from services.power.model import PowerModel
from tests.harness import copies_of, static_rover

TICKS = 20  # ticks of every rover per run
REPEATS = 5


def per_rover_tick_us(n: int, tick: Callable[[str], None], rovers: list[str]) -> float:
    best = float("inf")
    for _ in range(REPEATS):
        start = time.perf_counter()
        for _ in range(TICKS):
            for rover in rovers:
                tick(rover)
        best = min(best, time.perf_counter() - start)
    return best / (TICKS * n) * 1e6


def measure(rovers: list[Rover]) -> tuple[float, float, float, float]:
    """us per rover per tick: the draw (a model each, the fleet), the loads' messages, the PDM."""
    n = len(rovers)
    ids = [r.id for r in rovers]
    each = {r.id: LoadsModel(r, seed=1) for r in rovers}
    fleet = LoadsFleet(rovers, seed=1)
    draw_each = per_rover_tick_us(n, lambda rover: each[rover].sample(), ids)
    draw_fleet = per_rover_tick_us(n, fleet.sample, ids)

    load_keys = {r.id: [keys.load_power(r.id, ld.name) for ld in r.loads] for r in rovers}

    def load_messages(rover: str) -> None:
        m = fleet.models[rover]
        for key, (name, power_w, rail, on) in zip(load_keys[rover], m.powers(), strict=True):
            (key, encode(LoadPower(t_s=1.0, power_w=power_w, rail=rail, on=on,
                                   faults=m.alarms(name, power_w))))

    pdms = {r.id: PowerModel(r) for r in rovers}
    for rover, pdm in pdms.items():
        pdm.load_power_w.update((name, p) for name, p, _, _ in fleet.models[rover].powers())
    rail_keys = {rover: [keys.rail_state(rover, name) for name in m.rail_names()]
                 for rover, m in pdms.items()}

    def pdm_messages(rover: str) -> None:
        readings, summary = pdms[rover].compute()
        for key, r in zip(rail_keys[rover], readings, strict=True):
            (key, encode(RailState(1.0, *r[1:])))
        (keys.power_summary(rover), encode(PowerSummary(1.0, *summary)))

    return (draw_each, draw_fleet, per_rover_tick_us(n, load_messages, ids),
            per_rover_tick_us(n, pdm_messages, ids))


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:]] or [1, 10, 100, 200]
    mapp = load_rover(static_rover("mapp.yaml"))
    print(f"fleet models: MAPP without its drive, {len(mapp.loads)} loads and "
          f"{len(mapp.rails) + 1} rails a rover; us per rover per tick, best of {REPEATS} x "
          f"{TICKS} ticks ({machine()})")
    print(f"{'rovers':>6} | {'draw: a model each':>18} | {'draw: fleet':>11} | {'ratio':>5} | "
          f"{'loads: messages':>15} | {'PDM: compute + messages':>23}")
    for n in sizes:
        draw_each, draw_fleet, messages, pdm_us = measure(copies_of(mapp, n))
        print(f"{n:>6} | {draw_each:>18.2f} | {draw_fleet:>11.2f} | {draw_each / draw_fleet:>5.1f} | "
              f"{messages:>15.2f} | {pdm_us:>23.2f}")

if __name__ == "__main__":
    main()
