"""Can this rover do this traverse, and come back with the reserve left? An accelerated run.

:func:`run_traverse` drives a traverse with the composed models (:class:`services.composed.
ComposedTwin`: battery, loads, PDM, solar and the drive in one process, no Zenoh) from the
rover file's initial state and ``drive.start``, until the rover arrives, the pack is
depleted, or a time limit. It reports when the state of charge first fell below the
reserve, and where the rover was then. ``lunaris sim --traverse`` prints it.
:func:`power_profile` gives the drive load's power tick by tick along a traverse, for tools
that model the rest of the rover themselves (a prediction). Pure: no I/O, no clock.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from common.config import Rover
from common.messages import DriveTraverse
from common.traverse import length_and_duration, plan
from services.composed import ComposedTwin
from services.drive.model import DriveModel, umbilical_holds

__all__ = ["Coverage", "ReserveCrossing", "TraverseBudget", "power_profile", "run_traverse"]


class ReserveCrossing(NamedTuple):
    """Where the rover was when the state of charge first fell below the reserve."""

    t_s: float
    odometer_m: float
    x_m: float
    y_m: float
    waypoint: int | None  # the waypoint it was driving to


class Coverage(NamedTuple):
    """A radio that follows the rover along a traverse: how long the rover was outside its
    footprint (its ellipse around the radio's site; what the rover's end of the link would
    say with power), and where it first left it (None: never)."""

    out_s: float
    first_out: ReserveCrossing | None


class TraverseBudget(NamedTuple):
    planned_length_m: float
    planned_duration_s: float  # at the commanded speeds
    waypoints: int
    outcome: str  # "arrived", "depleted" or "time limit"
    simulated_s: float
    arrived_at_s: float | None
    odometer_m: float
    final_soc: float
    min_soc: float
    reserve_soc: float
    below_reserve: ReserveCrossing | None
    drive_energy_j: float  # drawn by the drive load, battery side of the drivetrain
    battery_energy_j: float  # taken from the pack in all
    power_limited_s: float  # driving slowed by the drive load's max_w
    unpowered_s: float  # halted: the drive load had no power
    peak_drive_w: float
    coverage: tuple[tuple[str, Coverage], ...] = ()  # (name, coverage) of each radio standing at a site

    @property
    def ok(self) -> bool:
        """Arrived, the state of charge never below the reserve."""
        return self.outcome == "arrived" and self.below_reserve is None


Progress = Callable[[ComposedTwin], None]


def run_traverse(rover: Rover, traverse: DriveTraverse, reserve_soc: float = 0.2,
                 max_hours: float | None = None, seed: int | None = 0,
                 progress: Progress | None = None, progress_every_s: float = 600.0,
                 sample: Progress | None = None, sample_every_s: float = 60.0) -> TraverseBudget:
    """Drive ``traverse`` from the rover file's start. ``max_hours`` defaults to three times
    the planned duration plus an hour. ``sample(twin)`` is called every ``sample_every_s`` of
    simulated time and at the end (a series: ``lunaris sim --csv``). Raises ValueError for a
    rover without a drive or a traverse the drive would refuse (the reasons in the message: a
    rover file that starts plugged in to an umbilical that does not follow the rover, too)."""
    if rover.drive is None:
        raise ValueError(f"rover {rover.id} has no drive section: it cannot follow a traverse")
    twin = ComposedTwin(rover, seed)
    drive = twin.drive
    assert drive is not None  # the rover has a drive section
    start = (drive.x_m, drive.y_m, drive.z_m)
    legs, problems = plan(traverse, drive.cfg, start)
    held = umbilical_holds(rover.umbilical, twin.solar.umbilical_plugged)
    if held is not None:
        problems.append(held)
    if problems:
        raise ValueError("; ".join(problems))
    length, duration = length_and_duration(start, legs)
    limit_s = (max_hours * 3600.0) if max_hours is not None else 3.0 * duration + 3600.0
    drive.start(legs, traverse.return_to_start)
    battery = twin.battery
    e0, e_drive0 = battery.energy_j, drive.energy_j
    min_soc = battery.soc
    crossing: ReserveCrossing | None = None
    limited_s = unpowered_s = 0.0
    peak_w = drive.power_w
    every = max(1, round(progress_every_s / twin.dt_s))
    sample_every = max(1, round(sample_every_s / twin.dt_s))
    ticks = 0
    outcome = "time limit"
    out_s = dict.fromkeys((r.name for r in twin.sited), 0.0)
    first_out: dict[str, ReserveCrossing] = {}
    while twin.t_s < limit_s - 1e-9:
        status = drive.status
        twin.step()
        ticks += 1
        for name in twin.out_of_range() if twin.sited else ():
            out_s[name] += twin.dt_s
            if name not in first_out:
                r = drive.reading()
                first_out[name] = ReserveCrossing(twin.t_s, r.odometer_m, r.x_m, r.y_m, r.waypoint)
        if status == "power_limited":
            limited_s += twin.dt_s
        elif status == "unpowered":
            unpowered_s += twin.dt_s
        peak_w = max(peak_w, drive.power_w)
        soc = battery.soc
        if soc < min_soc:
            min_soc = soc
        if crossing is None and soc < reserve_soc:
            r = drive.reading()
            crossing = ReserveCrossing(twin.t_s, r.odometer_m, r.x_m, r.y_m, r.waypoint)
        if progress is not None and ticks % every == 0:
            progress(twin)
        if sample is not None and ticks % sample_every == 0:
            sample(twin)
        if drive.status == "arrived":
            outcome = "arrived"
            break
        if battery.depleted:
            outcome = "depleted"
            break
    if sample is not None and ticks % sample_every:
        sample(twin)  # the run's end: arrived, depleted or out of time
    return TraverseBudget(length, duration, len(legs), outcome, twin.t_s,
                          twin.t_s if outcome == "arrived" else None, drive.odometer_m,
                          battery.soc, min_soc, reserve_soc, crossing, drive.energy_j - e_drive0,
                          e0 - battery.energy_j, limited_s, unpowered_s, peak_w,
                          tuple((name, Coverage(out, first_out.get(name))) for name, out in out_s.items()))


def power_profile(rover: Rover, traverse: DriveTraverse, dt_s: float | None = None) -> list[float]:
    """The drive load's power [W] for each tick of ``dt_s`` (default ``1 / tick_hz``) from the
    start until the rover arrives, its load always supplied."""
    if rover.drive is None:
        raise ValueError(f"rover {rover.id} has no drive section: it cannot follow a traverse")
    load = next(ld for ld in rover.loads if ld.name == rover.drive.load)
    drive = DriveModel(rover.drive, load.max_w)
    legs, problems = plan(traverse, rover.drive, (drive.x_m, drive.y_m, drive.z_m))
    if problems:
        raise ValueError("; ".join(problems))
    dt = dt_s if dt_s is not None else 1.0 / rover.tick_hz
    drive.start(legs)
    out = []
    while drive.active:
        out.append(drive.power_w)
        drive.step(dt)
    return out
