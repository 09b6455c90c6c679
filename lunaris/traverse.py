"""``lunaris traverse ROVER FILE | --to X Y Z | --stop``: drive a rover without Zenoh code.

Sends ``input/drive/traverse`` (a traverse file, or one waypoint given on the command line)
or deletes it (``--stop``: the rover stops where it is), then prints the twin's answer, as
``lunaris fault`` does: the drive accepts a traverse with an ``input`` event saying its
length and duration, or rejects it with the reason (a speed above the rover's maximum, a
leg too steep, a rover without a drive ...).

Exit status: 0 accepted; 1 rejected (or a file with problems); 2 not applied.
"""

from __future__ import annotations

import argparse

import msgspec

from common.connection import add_connection_args
from common.messages import DriveTraverse, TraverseWaypoint
from common.traverse import TraverseError, load_traverse
from lunaris.client import ANSWER_S, ToolError
from lunaris.confirm import confirm, plan, tool_main

__all__ = ["add_arguments", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("file", nargs="?", metavar="FILE", help="a traverse file (YAML)")
    what.add_argument("--to", nargs=3, type=float, metavar=("X", "Y", "Z"),
                      help="drive straight to this point of the site frame [m]")
    what.add_argument("--stop", action="store_true", help="stop the rover where it is")
    p.add_argument("--speed", type=float, metavar="M_PER_S",
                   help="with --to: the speed (default the rover's max_speed_m_per_s)")
    p.add_argument("--return", dest="back", action="store_true",
                   help="then drive back to where the traverse began")
    p.add_argument("--timeout", type=float, default=ANSWER_S, metavar="S",
                   help=f"how long to wait for the twin's answer (default {ANSWER_S:g} s)")
    p.add_argument("--wait", type=float, default=10.0, metavar="S",
                   help="how long to wait for a router that does not answer (default 10 s)")
    p.add_argument("--json", action="store_true", help="print the answer as JSON")
    add_connection_args(p)


def _payload(args: argparse.Namespace) -> bytes | None:
    if args.stop:
        return None
    if args.to is not None:
        x, y, z = args.to
        cmd = DriveTraverse([TraverseWaypoint(x, y, z)], args.speed, args.back)
    else:
        try:
            cmd = load_traverse(args.file).command()
        except TraverseError as exc:
            raise ToolError(str(exc), 1) from None
        if args.speed is not None or args.back:
            cmd = DriveTraverse(cmd.waypoints, args.speed or cmd.speed_m_per_s,
                                args.back or cmd.return_to_start)
    return msgspec.json.encode(cmd)


def main(args: argparse.Namespace) -> int:
    return tool_main("traverse", lambda a: confirm(a, "traverse", plan(a.rover, "input/drive/traverse",
                                                                         _payload(a))), args)
