"""``lunaris reset``, ``snapshot``, ``session`` and ``mark``: the training day's controls.

``lunaris reset ROVER`` and ``lunaris snapshot save|restore|list ROVER [NAME]`` act within the
running session; ``lunaris session start ROVER --trainee NAME [--from-snapshot S]`` ends it and
begins the next trainee's (SPEC §12c: the twin reset, or the snapshot restored; every event from
there carries the new session's id), ``lunaris session list ROVER`` lists the sessions of the
rover's journal, and ``lunaris mark ROVER TEXT`` marks the timeline (a ``mark`` event).

``reset`` puts ``control/reset``: every service goes back to the rover file's initial
conditions, the injected faults are cleared and the clock is at 0. ``snapshot save NAME``
saves every service's state under NAME (kept under the services' ``--state-dir``, so it
survives a restart), ``snapshot restore NAME`` puts it back, ``snapshot list`` lists them.
Each write is confirmed by the ``session`` event of the faults service (of the clock for a
restore and a session, which checks every service's part first; a ``mark`` event for a mark),
or its rejection; exit status as ``lunaris fault``: 0 accepted, 1 rejected (or refused before
sending: a bad name), 2 not applied (``session list``: no answer).
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from common import keys
from common.messages import trainee_problem
from common.writes import snapshot_name_problem
from lunaris.client import ToolError, close_session, open_session
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["add_mark_arguments", "add_reset_arguments", "add_session_arguments",
           "add_snapshot_arguments", "main_mark", "main_reset", "main_session", "main_snapshot"]


def add_reset_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    add_common_arguments(p)


def add_snapshot_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("save", "restore", "list"))
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("name", nargs="?", help="the snapshot's name: letters, digits, '_', '-', '.'")
    add_common_arguments(p)


def add_session_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("action", choices=("start", "list"),
                   help="start: end the running session and begin a trainee's; list: the sessions")
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("--trainee", metavar="NAME",
                   help="start: who is trained (letters, digits, spaces and - _ . ' &)")
    p.add_argument("--from-snapshot", metavar="S", dest="from_snapshot",
                   help="start: begin from this snapshot (default: the rover file)")
    add_common_arguments(p)


def add_mark_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("text", nargs="+", help="the note, as the debrief will show it")
    add_common_arguments(p)


def main_session(args: argparse.Namespace) -> int:
    def run(a: argparse.Namespace) -> int:
        if a.action == "list":
            return _list_sessions(a)
        if a.trainee is None:
            raise ToolError("session start needs --trainee NAME (who is trained in it)", 1)
        problem = trainee_problem(a.trainee)
        if problem is None and a.from_snapshot is not None:
            problem = snapshot_name_problem(a.from_snapshot)
        if problem is not None:
            raise ToolError(problem, 1)
        body: dict[str, str] = {"trainee": a.trainee}
        if a.from_snapshot is not None:
            body["from_snapshot"] = a.from_snapshot
        return confirm(a, "session", plan(a.rover, "control/session", json.dumps(body).encode()))
    return tool_main("session", run, args)


def main_mark(args: argparse.Namespace) -> int:
    text = " ".join(args.text)
    return tool_main("mark", lambda a: confirm(a, "mark", plan(
        a.rover, "control/mark", json.dumps({"text": text}).encode())), args)


def main_reset(args: argparse.Namespace) -> int:
    return tool_main("reset", lambda a: confirm(a, "reset", plan(a.rover, "control/reset", b"")), args)


def main_snapshot(args: argparse.Namespace) -> int:
    def run(a: argparse.Namespace) -> int:
        if a.action == "list":
            return _list(a)
        if not a.name:
            raise ToolError(f"snapshot {a.action} needs a NAME", 1)
        problem = snapshot_name_problem(a.name)
        if problem is not None:
            raise ToolError(problem, 1)
        verb = "snapshot" if a.action == "save" else "restore"
        return confirm(a, "snapshot", plan(a.rover, f"control/{verb}/{a.name}", b""))
    return tool_main("snapshot", run, args)


def _ask(args: argparse.Namespace, key: str) -> Any:
    """The faults service's answer to ``get key`` (JSON); :class:`ToolError` (exit 2) when
    none came."""
    session = open_session(args, wait_s=args.wait)
    try:
        replies = [r.ok for r in session.get(key, timeout=args.timeout) if r.ok is not None]
    finally:
        close_session(session)
    if not replies:
        raise ToolError(f"no answer from the faults service of {args.rover!r} within "
                        f"{args.timeout:g} s (unknown rover, or the faults service is not running)", 2)
    return json.loads(replies[0].payload.to_bytes())


def _list_sessions(args: argparse.Namespace) -> int:
    sessions = _ask(args, keys.sessions(args.rover))
    if args.json:
        print(json.dumps(sessions))
        return 0
    print(f"{'session':<17}{'trainee':<24}{'sim start':>11}{'sim end':>11}  started")
    for s in sessions:
        end = "running" if s["end_t_s"] is None else f"{s['end_t_s']:9.1f} s"
        wall = "-" if s["started_wall"] is None else time.strftime(
            "%Y-%m-%d %H:%M:%S", time.localtime(s["started_wall"]))
        snapshot = f"  from snapshot {s['from_snapshot']}" if s.get("from_snapshot") else ""
        print(f"{s['id']:<17}{s['trainee'] or '(none named)':<24}{s['start_t_s']:9.1f} s"
              f"{end:>11}  {wall}{snapshot}")
    return 0


def _list(args: argparse.Namespace) -> int:
    snaps = _ask(args, keys.snapshots(args.rover))
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
