"""Traverses: the traverse file format, and a traverse planned against a rover's drive.

A traverse is what ``input/drive/traverse`` carries (:class:`common.messages.DriveTraverse`);
a traverse file is the same in YAML with a name, for ``lunaris sim --traverse`` and for
planning a sortie::

    traverse: {name: Crater rim sortie, description: up the rim and back}
    speed_m_per_s: 3.0            # optional: default the rover's max_speed_m_per_s
    return_to_start: true         # optional: then back through the waypoints to the start
    waypoints:                    # site frame: x east, y north, z up [m]
      - {x_m: 500, y_m: 2000, z_m: 5}
      - {x_m: 1300, y_m: 6800, z_m: 260, speed_m_per_s: 2.0}   # the leg to here, slower

:func:`load_traverse` reads and validates a file and reports every problem with its path, as
rover files do; :func:`plan` turns a traverse into the legs the drive follows from a start
position, refusing speeds above the rover's maximum and legs steeper than its
``max_grade_deg``. Pure: no Zenoh, no clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, NamedTuple

import msgspec

from common.config import Drive, Rover
from common.datafile import ConfigError, Strict, doc, parse_yaml, read_text
from common.messages import DriveTraverse, TraverseWaypoint

__all__ = [
    "Leg",
    "TraverseError",
    "TraverseFile",
    "TraverseInfo",
    "length_and_duration",
    "load_traverse",
    "parse_traverse",
    "plan",
]

Point = tuple[float, float, float]  # x_m, y_m, z_m in the site frame


class Leg(NamedTuple):
    """One leg: the waypoint it ends at, the speed it is driven at, and that waypoint's number
    (the listed waypoints count from 0; the legs of a return count on from there)."""

    x_m: float
    y_m: float
    z_m: float
    speed_m_per_s: float
    waypoint: int


class TraverseInfo(Strict, frozen=True):
    """What the traverse is, for people."""

    name: Annotated[str, doc("a name for people")]
    description: Annotated[str, doc("what it is for")] = ""


class TraverseFile(Strict, frozen=True, kw_only=True):
    """A traverse file: waypoints in the site frame and the speed to drive them at."""

    traverse: TraverseInfo
    waypoints: Annotated[list[TraverseWaypoint], doc(
        "site frame [m]: x_m east, y_m north, z_m up; speed_m_per_s (optional) is the speed "
        "of the leg that ends there")]
    speed_m_per_s: Annotated[Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] | None, doc(
        "commanded speed [m/s]; default the rover's max_speed_m_per_s")] = None
    return_to_start: Annotated[bool, doc("then drive back through the waypoints to the "
                                         "start")] = False

    def command(self) -> DriveTraverse:
        """The traverse as ``input/drive/traverse`` carries it."""
        return DriveTraverse(waypoints=list(self.waypoints), speed_m_per_s=self.speed_m_per_s,
                             return_to_start=self.return_to_start)


class TraverseError(ConfigError):
    """A traverse file with problems; ``problems`` lists every one of them."""


def load_traverse(path: str | Path, rover: Rover | None = None) -> TraverseFile:
    """Read and validate a traverse file; with ``rover``, plan it from the rover's start too.
    Raise :class:`TraverseError` listing every problem."""
    return parse_traverse(read_text(path, TraverseError), str(path), rover)


def parse_traverse(text: str, source: str = "<traverse>", rover: Rover | None = None) -> TraverseFile:
    """Validate traverse YAML text (see :func:`load_traverse`)."""
    data, problems = parse_yaml(text, source, TraverseFile, TraverseError)
    if not problems:
        traverse = msgspec.convert(data, TraverseFile)
        if rover is not None:
            if rover.drive is None:
                problems.append(f"rover {rover.id} has no drive section: it cannot follow a traverse")
            else:
                s = rover.drive.start
                problems += plan(traverse.command(), rover.drive, (s.x_m, s.y_m, s.z_m))[1]
        if not problems:
            return traverse
    raise TraverseError(source, problems, data)


def plan(cmd: DriveTraverse, drive: Drive, start: Point) -> tuple[list[Leg], list[str]]:
    """The legs of a traverse driven from ``start``, and every reason to refuse it (then no
    legs): no waypoint, a speed above ``max_speed_m_per_s``, a leg steeper than
    ``max_grade_deg`` or vertical. A zero-length leg (a repeated waypoint) is allowed."""
    problems: list[str] = []
    if not cmd.waypoints:
        problems.append("waypoints: a traverse needs at least one waypoint")
    vmax = drive.max_speed_m_per_s
    speed = cmd.speed_m_per_s if cmd.speed_m_per_s is not None else vmax
    if speed > vmax:
        problems.append(f"speed_m_per_s: {speed:g} m/s is above the rover's max_speed_m_per_s "
                        f"({vmax:g})")
    speeds: list[float] = []
    here = start
    for i, w in enumerate(cmd.waypoints):
        v = w.speed_m_per_s if w.speed_m_per_s is not None else speed
        if w.speed_m_per_s is not None and v > vmax:
            problems.append(f"waypoints[{i}].speed_m_per_s: {v:g} m/s is above the rover's "
                            f"max_speed_m_per_s ({vmax:g})")
        speeds.append(v)
        there = (w.x_m, w.y_m, w.z_m)
        horizontal = math.hypot(there[0] - here[0], there[1] - here[1])
        rise = there[2] - here[2]
        grade = math.degrees(math.atan2(abs(rise), horizontal))
        if grade > drive.max_grade_deg:
            origin = "the rover's position" if i == 0 else f"waypoints[{i - 1}]"
            verb = "climbs" if rise > 0 else "descends"
            problems.append(f"waypoints[{i}]: the leg from {origin} {verb} {grade:.1f} deg "
                            f"({abs(rise):g} m over {horizontal:g} m), steeper than the rover's "
                            f"max_grade_deg ({drive.max_grade_deg:g})")
        here = there
    if problems:
        return [], problems
    n = len(cmd.waypoints)
    legs = [Leg(float(w.x_m), float(w.y_m), float(w.z_m), v, i)
            for i, (w, v) in enumerate(zip(cmd.waypoints, speeds, strict=True))]
    if cmd.return_to_start:
        # Back over the same legs: waypoint j to j-1 at the speed of the leg from j-1 to j.
        for k, j in enumerate(range(n - 1, -1, -1)):
            back = cmd.waypoints[j - 1] if j > 0 else None
            x, y, z = (float(back.x_m), float(back.y_m), float(back.z_m)) if back is not None else start
            legs.append(Leg(x, y, z, speeds[j], n + k))
    return legs, []


def length_and_duration(start: Point, legs: Sequence[Leg]) -> tuple[float, float]:
    """The traverse's length along the ground [m] and its duration at the commanded speeds [s]."""
    length = duration = 0.0
    here = start
    for leg in legs:
        d = math.dist(here, (leg.x_m, leg.y_m, leg.z_m))
        length += d
        duration += d / leg.speed_m_per_s
        here = (leg.x_m, leg.y_m, leg.z_m)
    return length, duration
