"""``lunaris reset ROVER`` and ``lunaris snapshot save|restore|list ROVER [NAME]``.

``reset`` puts ``control/reset``: every service goes back to the rover file's initial
conditions, the injected faults are cleared and the clock is at 0. ``snapshot save NAME``
saves every service's state under NAME (kept under the services' ``--state-dir``, so it
survives a restart), ``snapshot restore NAME`` puts it back, ``snapshot list`` lists them.
Each write is confirmed by the ``session`` event of the faults service, or its rejection;
exit status as ``lunaris fault``: 0 accepted, 1 rejected, 2 not applied.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from common import keys
from common.session import SNAPSHOT_NAME
from lunaris.client import ToolError, close_session, open_session
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["add_reset_arguments", "add_snapshot_arguments", "main_reset", "main_snapshot"]


def add_reset_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    add_common_arguments(p)


def add_snapshot_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("save", "restore", "list"))
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("name", nargs="?", help="the snapshot's name: letters, digits, '_', '-', '.'")
    add_common_arguments(p)


def main_reset(args: argparse.Namespace) -> int:
    return tool_main("reset", lambda a: confirm(a, "reset", plan(a.rover, "control/reset", b"")), args)


def main_snapshot(args: argparse.Namespace) -> int:
    def run(a: argparse.Namespace) -> int:
        if a.action == "list":
            return _list(a)
        if not a.name:
            raise ToolError(f"snapshot {a.action} needs a NAME", 1)
        if not SNAPSHOT_NAME.match(a.name):
            raise ToolError(f"bad snapshot name {a.name!r}: letters, digits, '_', '-' and '.', "
                            "at most 64", 1)
        verb = "snapshot" if a.action == "save" else "restore"
        return confirm(a, "snapshot", plan(a.rover, f"control/{verb}/{a.name}", b""))
    return tool_main("snapshot", run, args)


def _list(args: argparse.Namespace) -> int:
    session = open_session(args, wait_s=args.wait)
    try:
        replies = [r.ok for r in session.get(keys.snapshots(args.rover), timeout=args.timeout)
                   if r.ok is not None]
    finally:
        close_session(session)
    if not replies:
        print(f"no answer from the faults service of {args.rover!r} within {args.timeout:g} s "
              "(unknown rover, or the faults service is not running)", file=sys.stderr)
        return 2
    snaps = json.loads(replies[0].payload.to_bytes())
    if args.json:
        print(json.dumps(snaps))
        return 0
    if not snaps:
        print(f"{args.rover}: no snapshots")
    for s in snaps:
        saved = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(s["saved_at"]))
        print(f"{s['name']:<24} sim t {s['t_s']:10.1f} s   saved {saved}   "
              f"({len(s['services'])} services)")
    return 0
