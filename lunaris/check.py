"""``lunaris check FILE... [--bridge MAPPING]``: validate rover definitions, print every problem.

With ``--bridge`` each rover is also checked against a bridge mapping (the shipped one is
``config/bridge/default.yaml``): the mapping itself, then every component a mapping names
that the rover lacks, every topic two bindings would share; each rover's dashboard topics
are counted (in the fleet of every file given, as the deployment runs them)."""

from __future__ import annotations

import argparse
import sys

from common.budget import budget_warnings
from common.config import ConfigError, Rover, load_rover

__all__ = ["add_arguments", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", metavar="FILE")
    p.add_argument("--bridge", metavar="MAPPING", default=None,
                   help="also check the rovers against this bridge mapping "
                        "(config/bridge/default.yaml is the shipped one)")


def _check_bridge(mapping: str, rovers: list[tuple[str, Rover]]) -> int:
    # The bridge's modules are imported only when asked for: lunaris check stays light.
    from services.bridge import expand, load_mapping, resolve_mapping, rover_names

    path = resolve_mapping(mapping)
    try:
        mf = load_mapping(path)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 1
    status = 0
    fleet = [r.id for _, r in rovers]
    for file, rover in rovers:
        try:
            bindings = expand(mf, [rover_names(rover)], source=f"{path} for {file}", fleet=fleet)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            status = 1
            continue
        out = sum(1 for b in bindings if b.mapping.direction == "out")
        print(f"{file}: bridge ok - {path}: {out} topics out, {len(bindings) - out} in")
    return status


def main(args: argparse.Namespace) -> int:
    status = 0
    loaded: list[tuple[str, Rover]] = []
    for path in args.files:
        try:
            rover = load_rover(path)
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            status = 1
            continue
        loaded.append((path, rover))
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
    if args.bridge is not None and loaded:
        status = max(status, _check_bridge(args.bridge, loaded))
    return status
