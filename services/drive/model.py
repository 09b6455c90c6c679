"""Drive: the rover follows a traverse; grade, tractive force, wheel torque and power (SPEC §4).

The rover drives leg by leg through the waypoints of a traverse (site frame: x east, y
north, z up) at the commanded speed ``v`` [m/s] along the ground. On a leg of grade
``theta = atan(dz / horizontal distance)``:

- tractive force ``F = m g (c_rr cos(theta) + sin(theta)) + m a`` [N]. Each leg is driven at
  a steady speed, so ``a = 0``: a change of speed takes one tick, and the kinetic energy
  involved is negligible next to a leg's (a tonne at 3 m/s holds 4.5 kJ; the same LTV
  climbing 100 m takes 240 kJ);
- wheel torque ``F r`` [N m], shared by the wheels;
- the drive load draws ``P = max(0, F v) / eta + idle_w`` [W] (``eta`` the drivetrain
  efficiency). When ``F v`` is negative (a descent steeper than ``atan(c_rr)``), it draws
  ``idle_w``, less ``|F v| * regen_efficiency`` when the rover file asks for regeneration;
- ``P`` is clipped to the drive load's ``max_w``: the rover then slows to
  ``v = (max_w - idle_w) * eta / F``;
- at a standstill (parked, arrived, or halted because the drive load has no power) it draws
  ``idle_w``.

A leg's energy is therefore ``F d / eta + idle_w t`` (``t = d / v``). Position, odometer and
energy are integrated exactly within a step, across the waypoints it passes; the reading
(speed, force, power ...) is that of the leg the rover is on at the end of the step, which
is what it draws over the next. Pure: no I/O, no clock, no Zenoh.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

from common.config import Drive, Umbilical
from common.messages import DriveStatus
from common.traverse import Leg

__all__ = [
    "DriveModel",
    "DriveReading",
    "capped_speed",
    "drive_power_w",
    "leg_energy_j",
    "tractive_force_n",
    "umbilical_holds",
]

_EPS_M = 1e-9  # legs shorter than this are arrived at at once


def tractive_force_n(mass_kg: float, gravity_m_per_s2: float, rolling_resistance: float,
                     grade_rad: float, accel_m_per_s2: float = 0.0) -> float:
    """``F = m g (c_rr cos(theta) + sin(theta)) + m a`` [N]; negative down a steep slope."""
    return mass_kg * (gravity_m_per_s2 * (rolling_resistance * math.cos(grade_rad)
                                          + math.sin(grade_rad)) + accel_m_per_s2)


def drive_power_w(force_n: float, speed_m_per_s: float, efficiency: float, idle_w: float,
                  regen_efficiency: float = 0.0) -> float:
    """Battery-side power of the drive [W]: ``F v / eta + idle_w`` when ``F v >= 0``, else
    ``idle_w + F v * regen_efficiency`` (only ``idle_w`` without regeneration)."""
    wheel_w = force_n * speed_m_per_s
    if wheel_w >= 0.0:
        return wheel_w / efficiency + idle_w
    return idle_w + wheel_w * regen_efficiency


def capped_speed(force_n: float, speed_m_per_s: float, efficiency: float, idle_w: float,
                 max_w: float) -> float:
    """The speed the drive holds: the commanded one, or ``(max_w - idle_w) eta / F`` when the
    commanded one would draw more than ``max_w``."""
    if force_n <= 0.0:
        return speed_m_per_s
    return min(speed_m_per_s, max(0.0, max_w - idle_w) * efficiency / force_n)


def leg_energy_j(force_n: float, distance_m: float, speed_m_per_s: float, efficiency: float,
                 idle_w: float, regen_efficiency: float = 0.0) -> float:
    """Energy drawn over a leg driven at a steady speed [J]: ``F d / eta + idle_w d / v``."""
    duration_s = distance_m / speed_m_per_s
    return drive_power_w(force_n, speed_m_per_s, efficiency, idle_w, regen_efficiency) * duration_s


def umbilical_holds(umbilical: Umbilical, plugged: bool) -> str | None:
    """Why a traverse cannot start now, or None: while the umbilical is plugged in the rover
    stays put, unless its cable follows the rover (SPEC §12e)."""
    if not plugged or umbilical.follows_rover:
        return None
    reach = ("it has no slack" if umbilical.cable_m is None
             else f"its {umbilical.cable_m:g} m cable does not follow the rover")
    return ("the umbilical is plugged in and " + reach + ": unplug it first "
            "(input/umbilical false)")


class DriveReading(NamedTuple):
    """What ``drive/state`` publishes (without ``t_s``)."""

    x_m: float
    y_m: float
    z_m: float
    speed_m_per_s: float
    heading_deg: float
    grade_deg: float
    tractive_force_n: float
    wheel_torque_nm: float
    power_w: float
    odometer_m: float
    waypoint: int | None
    moving: bool
    status: DriveStatus
    waypoints: int
    remaining_m: float
    energy_j: float


class DriveModel:
    """One rover's drive. ``max_w`` is the drive load's ``max_w``."""

    def __init__(self, cfg: Drive, max_w: float):
        self.cfg = cfg
        self.max_w = max_w
        self.powered = True
        self.reset()

    # -- the session's state ------------------------------------------------------------------

    def reset(self) -> None:
        """At ``drive.start``, parked, no traverse, odometer and energy at 0."""
        s = self.cfg.start
        self.x_m, self.y_m, self.z_m = s.x_m, s.y_m, s.z_m
        self.heading_deg = s.heading_deg % 360.0
        self.grade_deg = 0.0
        self.odometer_m = 0.0
        self.energy_j = 0.0
        self.legs: list[Leg] = []
        self.leg = 0
        self.status: DriveStatus = "parked"
        self._suffix: list[float] = [0.0]
        self._idle()

    def state(self) -> dict[str, Any]:
        return {"x_m": self.x_m, "y_m": self.y_m, "z_m": self.z_m, "heading_deg": self.heading_deg,
                "grade_deg": self.grade_deg, "odometer_m": self.odometer_m, "energy_j": self.energy_j,
                "legs": [list(leg) for leg in self.legs], "leg": self.leg,
                "arrived": self.status == "arrived"}

    def set_state(self, state: dict[str, Any]) -> None:
        self.reset()
        self.x_m = float(state.get("x_m", self.x_m))
        self.y_m = float(state.get("y_m", self.y_m))
        self.z_m = float(state.get("z_m", self.z_m))
        self.heading_deg = float(state.get("heading_deg", self.heading_deg))
        self.grade_deg = float(state.get("grade_deg", 0.0))
        self.odometer_m = float(state.get("odometer_m", 0.0))
        self.energy_j = float(state.get("energy_j", 0.0))
        legs = [Leg(float(x), float(y), float(z), float(v), int(wp))
                for x, y, z, v, wp in state.get("legs", [])]
        leg = int(state.get("leg", 0))
        if state.get("arrived") and legs:
            self.legs, self.leg, self.status = legs, len(legs), "arrived"
        elif legs and 0 <= leg < len(legs):
            self._follow(legs, leg)

    # -- commands -----------------------------------------------------------------------------

    def start(self, legs: Sequence[Leg]) -> None:
        """Follow these legs from where the rover is (a traverse already being driven is
        replaced)."""
        self._follow(list(legs), 0)

    def stop(self) -> bool:
        """Stop where it is and forget the traverse; False when there was none to stop."""
        if not self.active:
            return False
        self.legs, self.leg, self.status = [], 0, "parked"
        self._suffix = [0.0]
        self._idle()
        return True

    def set_powered(self, powered: bool) -> bool:
        """The drive load supplies the motors or not (see
        :func:`common.faults.supplies_device`); True when that changed. Without power the
        rover halts where it is and resumes when it returns."""
        if powered == self.powered:
            return False
        self.powered = powered
        if self.active:
            self._begin_leg()
        return True

    @property
    def active(self) -> bool:
        """On a traverse that is not finished (moving, or halted for want of power)."""
        return self.leg < len(self.legs)

    # -- stepping -----------------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance ``dt_s`` seconds: move along the legs, passing waypoints within the step."""
        if dt_s <= 0.0:
            return
        if not (self.powered and self.active):
            if self.powered:  # parked or arrived: the controllers draw idle_w
                self.energy_j += self._power_w * dt_s
            return
        remaining_s = dt_s
        while True:
            travel_m = self._speed * remaining_s
            if travel_m + _EPS_M < self._to_go:  # stays on this leg (a nanometre short arrives)
                self.x_m += self._ux * travel_m
                self.y_m += self._uy * travel_m
                self.z_m += self._uz * travel_m
                self._to_go -= travel_m
                self.odometer_m += travel_m
                self.energy_j += self._power_w * remaining_s
                return
            reach_s = min(remaining_s, self._to_go / self._speed)
            self.odometer_m += self._to_go
            self.energy_j += self._power_w * reach_s
            remaining_s -= reach_s
            target = self.legs[self.leg]
            self.x_m, self.y_m, self.z_m = target.x_m, target.y_m, target.z_m
            self.leg += 1
            self._begin_leg()
            if not self.active:  # arrived: idle for the rest of the step
                self.energy_j += self._power_w * remaining_s
                return

    # -- what it reads --------------------------------------------------------------------------

    @property
    def power_w(self) -> float:
        """What the drive load draws now [W]."""
        return self._power_w

    def reading(self) -> DriveReading:
        moving = self.status in ("driving", "power_limited")
        force = self._force if moving else 0.0
        return DriveReading(
            self.x_m, self.y_m, self.z_m, self._speed if moving else 0.0, self.heading_deg,
            self.grade_deg, force, force * self.cfg.wheel_radius_m, self._power_w, self.odometer_m,
            self.legs[self.leg].waypoint if self.active else None, moving, self.status,
            len(self.legs), self._to_go + self._suffix[min(self.leg + 1, len(self._suffix) - 1)]
            if self.active else 0.0, self.energy_j)

    # -- inside ---------------------------------------------------------------------------------

    def _idle(self) -> None:
        self._speed = self._force = self._to_go = 0.0
        self._ux = self._uy = self._uz = 0.0
        self._power_w = self.cfg.idle_w

    def _follow(self, legs: list[Leg], leg: int) -> None:
        self.legs, self.leg = legs, leg
        # _suffix[k]: the length of legs k.. of the traverse, each from the waypoint before it
        # (leg k's own length only counts from k >= leg + 1: the current leg is _to_go).
        lengths = [0.0] + [math.dist(legs[k - 1][:3], legs[k][:3]) for k in range(1, len(legs))]
        self._suffix = [0.0] * (len(legs) + 1)
        for k in range(len(legs) - 1, -1, -1):
            self._suffix[k] = self._suffix[k + 1] + lengths[k]
        self._begin_leg()

    def _begin_leg(self) -> None:
        """Aim at the current leg's waypoint (skipping those already reached) and work out its
        grade, force, speed and power; or arrive."""
        c = self.cfg
        while self.leg < len(self.legs):
            target = self.legs[self.leg]
            dx, dy, dz = target.x_m - self.x_m, target.y_m - self.y_m, target.z_m - self.z_m
            distance = math.sqrt(dx * dx + dy * dy + dz * dz)
            if distance > _EPS_M:
                break
            self.x_m, self.y_m, self.z_m = target.x_m, target.y_m, target.z_m
            self.leg += 1
        else:
            self.status = "arrived" if self.legs else "parked"
            self._idle()
            return
        horizontal = math.hypot(dx, dy)
        grade = math.atan2(dz, horizontal)
        if horizontal > _EPS_M:
            self.heading_deg = math.degrees(math.atan2(dx, dy)) % 360.0
        self.grade_deg = math.degrees(grade)
        self._ux, self._uy, self._uz = dx / distance, dy / distance, dz / distance
        self._to_go = distance
        self._force = tractive_force_n(c.mass_kg, c.gravity_m_per_s2, c.rolling_resistance, grade)
        if not self.powered:
            self.status = "unpowered"
            self._speed = 0.0
            self._power_w = c.idle_w
            return
        commanded = target.speed_m_per_s
        self._speed = capped_speed(self._force, commanded, c.drivetrain_efficiency, c.idle_w,
                                   self.max_w)
        self.status = "power_limited" if self._speed < commanded * (1.0 - 1e-12) else "driving"
        power = drive_power_w(self._force, self._speed, c.drivetrain_efficiency, c.idle_w,
                              c.regen_efficiency)
        self._power_w = min(self.max_w, max(-self.max_w, power))
