"""``lunaris sim FILE [--hours H] [--traverse TRAVERSE.yaml] [--csv FILE]``: accelerated runs, no Zenoh.

For the vehicle engineer checking a power budget: state of charge over the run, when rails
are shed, when (if ever) the pack is depleted. With ``--traverse`` the rover drives a
traverse file from its start (``--return``: and back) and the run answers "can this rover
do this traverse and come back with the reserve left?" plainly; the exit status is then 0
for yes and 1 for no. ``--csv FILE`` writes the run as a series too (a row every ``--every``
seconds of simulated time), for a spreadsheet or a plot.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time

from common.traverse import TraverseError, load_traverse
from lunaris.run import load_rovers
from services.composed import run_budget
from services.composed.budget import TraverseBudget, run_traverse

__all__ = ["add_arguments", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="rover definition")
    p.add_argument("--hours", type=float, default=None,
                   help="simulated hours (default 8; with --traverse: a time limit, default "
                        "three times the planned duration plus an hour)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the loads")
    p.add_argument("--traverse", metavar="TRAVERSE.yaml", help="drive this traverse file")
    p.add_argument("--return", dest="back", action="store_true",
                   help="with --traverse: then drive back through its waypoints to the start")
    p.add_argument("--reserve", type=float, default=0.2, metavar="SOC",
                   help="with --traverse: the state of charge to keep, 0..1 (default 0.2)")
    p.add_argument("--csv", metavar="FILE",
                   help="also write the run as a series, one row every --every seconds of "
                        "simulated time (battery, power, rails not on; with --traverse where "
                        "the rover is), for a spreadsheet or a plot")
    p.add_argument("--every", type=float, default=60.0, metavar="S",
                   help="with --csv: seconds of simulated time between rows (default 60)")


COLUMNS = ("t_s", "soc", "energy_j", "voltage_v", "current_a", "temperature_c", "load_power_w",
           "bus_power_w", "generation_w", "net_battery_power_w", "rails_not_on")
DRIVE_COLUMNS = ("x_m", "y_m", "odometer_m", "drive_status")


class _Series:
    """The rows of ``--csv``: the twin as it stands every ``--every`` seconds."""

    def __init__(self, path: str, drives: bool):
        self.file = open(path, "w", newline="")  # closed by close(), in main's finally
        self.out = csv.writer(self.file)
        self.drives = drives
        self.out.writerow(COLUMNS + (DRIVE_COLUMNS if drives else ()))
        self.rows = 0

    def __call__(self, twin) -> None:
        b = twin.reading()
        summary = twin.summary
        ok = twin.power.battery_ok
        states = ((name, sw.state(ok)[0]) for name, sw in twin.power.switches.items())
        off = [f"{name}:{state}" for name, state in states if state != "on"]
        row: list[object] = [round(twin.t_s, 3), round(b.soc, 6), round(b.energy_j, 1),
                             round(b.voltage_v, 4), round(b.current_a, 4), round(b.temperature_c, 3),
                             *(round(v, 3) for v in summary[:4]), " ".join(off)]
        if self.drives:
            r = twin.drive.reading()
            row += [round(r.x_m, 2), round(r.y_m, 2), round(r.odometer_m, 2), r.status]
        self.out.writerow(row)
        self.rows += 1

    def close(self) -> None:
        self.file.close()


def _series(args: argparse.Namespace, drives: bool) -> _Series | None:
    return None if args.csv is None else _Series(args.csv, drives)


def _hms(t_s: float) -> str:
    h, rem = divmod(int(round(t_s)), 3600)
    return f"{h:d}:{rem // 60:02d}:{rem % 60:02d}"


def main(args: argparse.Namespace) -> int:
    if args.hours is not None and not args.hours > 0:
        print(f"--hours must be > 0, got {args.hours}", file=sys.stderr)
        return 2
    if not args.every > 0:
        print(f"--every must be > 0 seconds, got {args.every}", file=sys.stderr)
        return 2
    if args.traverse is not None:
        return _traverse(args)
    if args.back:
        print("--return needs --traverse", file=sys.stderr)
        return 2
    hours = 8.0 if args.hours is None else args.hours
    (rover,) = load_rovers([args.file])
    print(f"{rover.id}: {hours:g} simulated hours at {rover.tick_hz:g} Hz")

    def progress(done: int, total: int, twin) -> None:
        print(f"  {done / total:5.0%}  t={_hms(twin.t_s)}  soc={twin.battery.soc:.4f}", flush=True)

    series = _series(args, False)
    t0 = time.perf_counter()
    try:
        b = run_budget(rover, hours, args.seed, progress, series, args.every)
    finally:
        if series is not None:
            series.close()
    wall = time.perf_counter() - t0
    print(f"done: {b.ticks} ticks in {wall:.2f} s ({b.simulated_s / wall:,.0f}x real time)")
    print(f"  state of charge   {b.final_soc:.4f} at the end, {b.min_soc:.4f} at the lowest")
    print(f"  energy used       {b.energy_used_j / 3600:.1f} Wh")
    print(f"  mean load         {b.mean_load_w:.1f} W, mean generation {b.mean_generation_w:.1f} W")
    print(f"  peak temperature  {b.peak_temperature_c:.1f} C")
    for rail, t in sorted(b.shed_at_s.items(), key=lambda kv: kv[1]):
        print(f"  rail {rail} shed at {_hms(t)}")
    print(f"  depleted at {_hms(b.depleted_at_s)}" if b.depleted_at_s is not None
          else "  never depleted")
    print(f"  under-voltage cut-off at {_hms(b.cutoff_at_s)}" if b.cutoff_at_s is not None
          else "  never cut off for under-voltage")
    if b.short_s > 0.0:  # the loads asked for more than the pack gave: said, not averaged away
        print(f"  demand NOT met    for {_hms(b.short_s)}: {b.unmet_j / 3600:.1f} Wh the loads asked "
              f"for and the pack could not give (its max_discharge_a {rover.battery.max_discharge_a:g} A, "
              "or a brownout)")
    if series is not None:
        print(f"  series            {series.rows} rows, one every {args.every:g} s, in {args.csv}")
    return 0


def _traverse(args: argparse.Namespace) -> int:
    if not 0.0 <= args.reserve < 1.0:
        print(f"--reserve is a state of charge, 0 to 1, got {args.reserve}", file=sys.stderr)
        return 2
    (rover,) = load_rovers([args.file])
    try:
        plan = load_traverse(args.traverse, rover)
    except TraverseError as exc:
        print(exc, file=sys.stderr)
        return 2
    cmd = plan.command()
    if args.back:
        cmd.return_to_start = True
    print(f"{rover.id}: traverse {plan.traverse.name!r} ({args.traverse})"
          f"{', and back' if cmd.return_to_start else ''}, from the rover file's start")

    def progress(twin) -> None:
        r = twin.drive.reading()
        print(f"  t={_hms(twin.t_s)}  soc={twin.battery.soc:.4f}  odometer {r.odometer_m:8.1f} m  "
              f"{r.status}", flush=True)

    series = _series(args, True)
    t0 = time.perf_counter()
    try:
        b = run_traverse(rover, cmd, args.reserve, args.hours, args.seed, progress,
                         sample=series, sample_every_s=args.every)
    except ValueError as exc:  # the rover's drive refuses it
        print(f"{args.traverse}: {exc}", file=sys.stderr)
        return 2
    finally:
        if series is not None:
            series.close()
    wall = time.perf_counter() - t0
    print(f"done: {b.simulated_s / 3600:.2f} simulated hours in {wall:.2f} s "
          f"({b.simulated_s / wall:,.0f}x real time)")
    _print_budget(b)
    if series is not None:
        print(f"  series            {series.rows} rows, one every {args.every:g} s, in {args.csv}")
    return 0 if b.ok else 1


def _print_budget(b: TraverseBudget) -> None:
    print(f"  planned           {b.waypoints} waypoint(s), {b.planned_length_m:,.0f} m, "
          f"{_hms(b.planned_duration_s)} at the commanded speeds")
    if b.arrived_at_s is not None:
        late = b.arrived_at_s - b.planned_duration_s
        print(f"  arrived           at {_hms(b.arrived_at_s)} ({late / 60:+.1f} min against the plan)")
    else:
        print(f"  did NOT arrive    {b.outcome} at {_hms(b.simulated_s)}, {b.odometer_m:,.0f} m "
              f"of {b.planned_length_m:,.0f} m driven")
    if b.power_limited_s > 0:
        print(f"  power limited     {_hms(b.power_limited_s)} (slowed by the drive load's max_w)")
    if b.unpowered_s > 0:
        print(f"  halted            {_hms(b.unpowered_s)} without power to the drive")
    print(f"  drive energy      {b.drive_energy_j / 3600:,.1f} Wh, peak {b.peak_drive_w:,.0f} W")
    print(f"  from the pack     {b.battery_energy_j / 3600:,.1f} Wh (every load, less generation)")
    print(f"  state of charge   {b.final_soc:.1%} at the end, {b.min_soc:.1%} at the lowest")
    for name, cov in b.coverage:  # the link with the crew's radios, where it drives
        w = cov.first_out
        print(f"  radio {name:<11} " + ("in range all the way" if w is None else
              f"OUT of range {_hms(cov.out_s)} in all, first at {_hms(w.t_s)}, {w.odometer_m:,.0f} m "
              f"along, at ({w.x_m:,.0f}, {w.y_m:,.0f}) m"))
    reserve = f"{b.reserve_soc:.0%}"
    c = b.below_reserve
    if c is not None:
        to = f", driving to waypoint {c.waypoint}" if c.waypoint is not None else ""
        print(f"  below {reserve}         at {_hms(c.t_s)}, {c.odometer_m:,.0f} m along, at "
              f"({c.x_m:,.0f}, {c.y_m:,.0f}) m{to}")
    if b.ok:
        print(f"answer: YES - it arrives with {b.final_soc:.1%} left, above the {reserve} reserve "
              f"(a margin of {(b.min_soc - b.reserve_soc) * 100:.1f} points at the lowest)")
    elif b.arrived_at_s is not None:
        print(f"answer: NO - it arrives, but the charge falls below the {reserve} reserve on the way")
    else:
        print(f"answer: NO - it does not arrive ({b.outcome})")
