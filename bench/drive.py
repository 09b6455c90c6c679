"""The drive's cost: one model step, its block in the composed twin, and a composed run of a
MAPP rover driving for 8 simulated hours at 10 Hz (SPEC §10: at least 10,000x real time).
Run: `.venv/bin/python bench/drive.py [HOURS]`."""

from __future__ import annotations

import sys
import time
import timeit

from benchlib import ROOT, machine

from common.config import Rover, load_rover
from common.messages import DriveTraverse, TraverseWaypoint
from common.traverse import plan
from services.composed import ComposedTwin
from services.drive.model import DriveModel

REPEATS = 3


def far_traverse(rover: Rover) -> DriveTraverse:
    """Back and forth over a 10 deg ramp, longer than any run here."""
    assert rover.drive is not None
    s = rover.drive.start
    hop = 100.0
    points = [TraverseWaypoint(s.x_m + hop * (i % 2), s.y_m, s.z_m + 17.6 * (i % 2))
              for i in range(1, 2000)]
    return DriveTraverse(points, rover.drive.max_speed_m_per_s)


def main() -> None:
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 8.0
    rover = load_rover(ROOT / "config/rovers/mapp.yaml")
    assert rover.drive is not None
    print(f"drive: {rover.id} at {rover.tick_hz:g} Hz ({machine()})")
    load = next(ld for ld in rover.loads if ld.name == rover.drive.load)
    traverse = far_traverse(rover)
    start = (rover.drive.start.x_m, rover.drive.start.y_m, rover.drive.start.z_m)
    legs, problems = plan(traverse, rover.drive, start)
    assert not problems, problems

    model = DriveModel(rover.drive, load.max_w)
    model.start(legs)
    n = 200_000
    step_us = min(timeit.repeat(lambda: model.step(0.1), number=n, repeat=REPEATS)) / n * 1e6
    print(f"  DriveModel.step: {step_us:.2f} us (best of {REPEATS} x {n:,} steps, on a traverse)")

    # the drive block of the composed twin's tick, timed alone: power check, step, load power
    twin = ComposedTwin(rover, seed=0)
    drive = twin.drive
    assert drive is not None
    drive.start(legs)
    block_us = min(timeit.repeat(lambda: twin._step_drive(drive), number=n, repeat=REPEATS)) / n * 1e6
    print(f"  the drive block of a composed tick: {block_us:.2f} us")

    total = int(round(hours * 3600 * rover.tick_hz))
    walls = []
    for _ in range(REPEATS):
        twin = ComposedTwin(rover, seed=0)
        assert twin.drive is not None
        twin.drive.start(legs)
        t0 = time.perf_counter()
        for _ in range(total):
            twin.step()
        walls.append(time.perf_counter() - t0)
        assert twin.drive.status in ("driving", "power_limited"), twin.drive.status
    best = min(walls)
    print(f"  {hours:g} simulated hours driving, {total:,} ticks: best {best:.2f} s of {REPEATS} "
          f"({hours * 3600 / best:,.0f}x real time, {best / total * 1e6:.1f} us/tick); "
          f"odometer {twin.drive.odometer_m:,.0f} m, soc {twin.battery.soc:.4f}")


if __name__ == "__main__":
    main()
