"""``lunaris check FILE``: validate rover definitions, print every problem."""

from __future__ import annotations

import argparse
import sys

from common.config import ConfigError, budget_warnings, load_rover

__all__ = ["add_arguments", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", metavar="FILE")


def main(args: argparse.Namespace) -> int:
    status = 0
    for path in args.files:
        try:
            rover = load_rover(path)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            status = 1
            continue
        b, d = rover.battery, rover.drive
        # the drive load draws what the drive sets: idle_w when parked
        nominal = sum(d.idle_w if d is not None and ld.name == d.load else ld.nominal_w
                      for ld in rover.loads)
        print(f"{path}: ok - {rover.id} ({rover.rover.name}): {b.capacity_j / 3.6e6:.3f} kWh, "
              f"{len(rover.rails)} rails, {len(rover.loads)} loads, "
              f"{len(rover.solar.panels)} panels, {len(rover.radios)} radios, "
              f"nominal load {nominal:.1f} W{' parked' if d is not None else ''}")
        if d is not None:
            flat_w = (d.mass_kg * d.gravity_m_per_s2 * d.rolling_resistance * d.max_speed_m_per_s
                      / d.drivetrain_efficiency + d.idle_w)
            following = [r.name for r in rover.radios if r.site is not None]
            print(f"{path}: drive - {d.mass_kg:g} kg, up to {d.max_speed_m_per_s:g} m/s and "
                  f"{d.max_grade_deg:g} deg; {d.load} draws {d.idle_w:g} W parked, {flat_w:.1f} W on "
                  f"the flat at full speed; radios following it: {', '.join(following) or 'none'}")
        for warning in budget_warnings(rover):
            print(f"{path}: warning: {warning}")
    return status
