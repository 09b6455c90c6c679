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
        b = rover.battery
        print(f"{path}: ok - {rover.id} ({rover.rover.name}): {b.capacity_j / 3.6e6:.3f} kWh, "
              f"{len(rover.rails)} rails, {len(rover.loads)} loads, "
              f"{len(rover.solar.panels)} panels, {len(rover.radios)} radios, "
              f"nominal load {sum(ld.nominal_w for ld in rover.loads):.1f} W")
        for warning in budget_warnings(rover):
            print(f"{path}: warning: {warning}")
    return status
