"""Radio link: the rover is in range inside an offset ellipse around the radio.

The rover's position relative to the radio arrives as a distance ``d`` [m] and
an angle [deg]: ``x = d cos(angle)``, ``y = d sin(angle)``. It is in range when
``((x - offset_x) / a)^2 + ((y - offset_y) / b)^2 <= 1``; a ``degraded`` fault
scales both axes, a ``failure`` means never in range. The model is given the faults in
effect on its radio (:meth:`RadioModel.set_faults`) and keeps what they do, never a record of
them. A radio needs power: while the load that powers it (``radios[].load``) has none, it is
out of range, and its one alarm is ``unpowered``.

A radio with a ``site`` on a rover that drives takes the distance and angle from its site
to the rover's site position instead (:func:`relative_to_site`): the same convention, so
``x`` and ``y`` are the rover's offsets east and north of the radio.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

from common.config import Radio
from common.faults import Degraded, Failure, FaultParams, kind_of

__all__ = ["Link", "RadioModel", "in_range", "position_xy", "relative_to_site"]


class Link(NamedTuple):
    in_range: bool
    x_m: float
    y_m: float


def position_xy(distance_m: float, angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return distance_m * math.cos(a), distance_m * math.sin(a)


def relative_to_site(site_x_m: float, site_y_m: float, x_m: float, y_m: float) -> tuple[float, float]:
    """Distance [m] and angle [deg, counter-clockwise from east] from a radio's site to a
    site position: the inverse of :func:`position_xy`."""
    dx, dy = x_m - site_x_m, y_m - site_y_m
    return math.hypot(dx, dy), math.degrees(math.atan2(dy, dx))


def in_range(x_m: float, y_m: float, a_m: float, b_m: float,
             offset_x_m: float = 0.0, offset_y_m: float = 0.0) -> bool:
    """Inside or on the ellipse; an ellipse with a zero axis contains nothing."""
    if a_m <= 0.0 or b_m <= 0.0:
        return False
    return ((x_m - offset_x_m) / a_m) ** 2 + ((y_m - offset_y_m) / b_m) ** 2 <= 1.0


class RadioModel:
    def __init__(self, cfg: Radio):
        self.cfg = cfg
        self.distance_m = 0.0
        self.angle_deg = 0.0
        self.failed = False
        self.range_scale = 1.0
        self.powered = True  # its load has power (a radio without one always has)

    def state(self) -> dict[str, float]:
        return {"distance_m": self.distance_m, "angle_deg": self.angle_deg}

    def set_state(self, state: dict) -> None:
        self.set_position(float(state.get("distance_m", 0.0)), float(state.get("angle_deg", 0.0)))

    def set_position(self, distance_m: float, angle_deg: float) -> None:
        """The rover's position relative to this radio [m, deg]."""
        self.distance_m, self.angle_deg = distance_m, angle_deg

    def set_faults(self, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on this radio, all of them. A kind that is not
        a radio's raises ValueError, and nothing changes."""
        failed, scale = False, 1.0
        for fault in faults:
            match fault:
                case Failure():
                    failed = True
                case Degraded(range_scale=s):
                    scale = s
                case _:
                    raise ValueError(f"a radio has no fault kind {kind_of(fault)!r}")
        self.failed, self.range_scale = failed, scale

    def set_powered(self, powered: bool) -> bool:
        """Whether the radio's load has power; True when that changed."""
        changed = powered != self.powered
        self.powered = powered
        return changed

    def alarms(self) -> list[str]:
        """The radio's own alarms: ``unpowered`` while its load has no power."""
        return [] if self.powered else ["unpowered"]

    def link(self) -> Link:
        x, y = position_xy(self.distance_m, self.angle_deg)
        c, s = self.cfg, self.range_scale
        ok = self.powered and not self.failed and in_range(x, y, c.a_m * s, c.b_m * s,
                                                           c.offset_x_m, c.offset_y_m)
        return Link(ok, x, y)
