"""``lunaris scenario run|check FILE``: play or validate a scripted training scenario.

The format is :mod:`common.scenario`, the player's logic :mod:`common.scenario_player`, and the
run against the twin :class:`lunaris.client.runner.Runner` (the console plays scenarios with
the same runner); this prints what the run says as it plays: each step as it fires and the
twin's answer to it (accepted, rejected and why, not applied and why), each expectation of the
crew as it is met or missed, what it waits for at least every 10 s, and at the end a summary.
Exit status: 0 when every step fired and was accepted (a missed expectation is the crew's score,
not the run's), 1 otherwise, 2 when it could not start.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import msgspec

from common.config import ConfigError, Rover, load_rover
from common.connection import add_connection_args
from common.scenario import Scenario, ScenarioError, load_scenario, rover_id_of
from lunaris.client import ANSWER_S, ToolError, close_session, describe_endpoint, open_session
from lunaris.client.runner import Runner

__all__ = ["add_arguments", "find_rover", "load", "main"]

REPO_ROVERS = Path(__file__).resolve().parent.parent / "config" / "rovers"


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    rover_help = "rover definition to check names against (default: the config/rovers file of its id)"

    run = sub.add_parser("run", help="play a scenario against the running twin")
    run.add_argument("file", metavar="FILE")
    run.add_argument("--rover-file", metavar="FILE", help=rover_help)
    run.add_argument("--time-scale", type=float, metavar="X",
                     help="clock speed while the scenario plays (overrides the scenario's time_scale)")
    run.add_argument("--timeout", type=float, default=ANSWER_S, metavar="S",
                     help=f"how long to wait for the twin's answer to each write (default {ANSWER_S:g} s)")
    run.add_argument("--wait", type=float, default=10.0, metavar="S",
                     help="how long to wait for the router and the rover's clock (default 10 s)")
    run.add_argument("--clear-at-end", action="store_true",
                     help="clear the faults this scenario injected that are still active at the end")
    run.add_argument("--json-summary", metavar="FILE", help="also write the summary as JSON")
    add_connection_args(run)

    check = sub.add_parser("check", help="validate scenarios and print every problem")
    check.add_argument("files", nargs="+", metavar="FILE")
    check.add_argument("--rover-file", metavar="FILE", help=rover_help)


def find_rover(rover_id: str | None, explicit: str | None) -> tuple[Rover | None, str]:
    """The rover definition to check names against, and a note saying where it came from."""
    if explicit:
        try:
            return load_rover(explicit), f"names checked against {explicit}"
        except ConfigError as exc:
            raise ToolError(str(exc)) from None
    folders = [Path("config/rovers"), REPO_ROVERS]
    for folder in dict.fromkeys(f.resolve() for f in folders if f.is_dir()):
        for path in sorted(folder.glob("*.yaml")):
            try:
                rover = load_rover(path)
            except ConfigError:
                continue
            if rover.id == rover_id:
                return rover, f"names checked against {path}"
    return None, f"names not checked: no rover definition with id {rover_id!r} found (give --rover-file)"


def load(path: str, rover_file: str | None) -> tuple[Scenario, str]:
    """Load and validate; names are checked against the rover's definition when one is found."""
    try:
        rover_id = rover_id_of(Path(path).read_text())
    except OSError:
        rover_id = None  # load_scenario says what is wrong with the file
    rover, note = find_rover(rover_id, rover_file) if rover_id or rover_file else (None, "")
    try:
        return load_scenario(path, rover), note
    except ScenarioError as exc:
        raise ToolError(str(exc), 1) from None


def main(args: argparse.Namespace) -> int:
    try:
        if args.action == "check":
            return _check_files(args.files, args.rover_file)
        return _run(args)
    except ToolError as exc:
        print(f"lunaris scenario: {exc}", file=sys.stderr)
        return exc.code if args.action == "run" else 1


def _check_files(files: Iterable[str], rover_file: str | None) -> int:
    status = 0
    for path in files:
        try:
            sc, note = load(path, rover_file)
        except ToolError as exc:
            print(exc, file=sys.stderr)
            status = 1
            continue
        span = f", runs {sc.duration_s:g} s" if sc.duration_s else ""
        scale = f", clock x{sc.time_scale:g}" if sc.time_scale else ""
        print(f"{path}: ok - {sc.scenario.name!r} for {sc.rover}: {len(sc.steps)} steps{span}{scale} "
              f"({note})")
    return status


# -- playing --------------------------------------------------------------------------------


def _run(args: argparse.Namespace) -> int:
    scenario, note = load(args.file, args.rover_file)
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        f"waiting for the Zenoh router at {describe_endpoint(args)} ...", flush=True))
    runner = Runner(session, scenario, time_scale=args.time_scale, timeout_s=args.timeout,
                    wait_s=args.wait, clear_at_end=args.clear_at_end, note=note)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: runner.stop())
    try:
        for progress in runner.run():
            print(progress.line(), flush=True)
    finally:
        close_session(session)
    return _summary(args, runner)


def _summary(args: argparse.Namespace, runner: Runner) -> int:
    status = runner.status()
    print()
    print(f"summary of {status.scenario!r} on {status.rover}: {status.end_reason} at {status.t_rel_s:.1f} s "
          f"of sim time ({time.monotonic() - runner.started_wall:.1f} s of wall time)")
    print(f"  {'#':>2}  {'fired at':>9}  {'status':<10} {'outcome':<11} step")
    for r in status.steps:
        fired = f"{r.fired_t_s:8.1f}s" if r.fired_t_s is not None else f"{'-':>9}"
        print(f"  {r.index + 1:>2}  {fired}  {r.status:<10} {r.outcome or '-':<11} {r.label}"
              + (f"  ({r.detail})" if r.detail and r.outcome != "accepted" else ""))
    expected = [r for r in status.steps if r.expect is not None]
    if expected:
        met = sum(1 for r in expected if r.expect is not None and r.expect.met)
        print(f"expectations of the crew: {met} of {len(expected)} met")
        for r in expected:
            assert r.expect is not None
            when = (f"met at {r.expect.met_t_s:.1f} s" if r.expect.met and r.expect.met_t_s is not None
                    else "MISSED")
            print(f"  {r.index + 1:>2}  {when:<16} {r.label} (within {r.expect.within_s:g} s: "
                  f"{r.expect.condition})")
    if args.json_summary:
        Path(args.json_summary).write_text(json.dumps({
            "scenario": status.scenario, "rover": status.rover, "start_t_s": runner.player.t0,
            "end_reason": status.end_reason, "ok": bool(status.ok),
            "steps": [msgspec.to_builtins(r) for r in status.steps],
            "expectations": [{"label": r.label, "met": bool(r.expect.met), "within_s": r.expect.within_s,
                              "met_t_s": r.expect.met_t_s, "condition": r.expect.condition}
                             for r in expected if r.expect is not None]}, indent=2))
    verdict = "every step fired and was accepted" if status.ok else "NOT every step played as planned"
    print(f"result: {verdict}" + (" (expectations are the crew's score, not the run's)" if expected else ""))
    return runner.code if runner.code is not None else 1
