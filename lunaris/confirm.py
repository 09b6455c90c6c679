"""What every instructor command shares: send one write, print the twin's answer, exit.

``lunaris rail``, ``clock``, ``input``, ``reset`` and ``snapshot`` each make one write on a key
of the twin and wait for the event that answers it, as ``lunaris fault`` does
(:func:`lunaris.fault.send_fault`): the accepting event (``command``, ``clock``, ``input``,
``session``) or ``rejected``, with the reason.

Exit status: 0 accepted; 1 rejected (by the twin, or refused before sending because it
cannot be valid); 2 no answer (no router, an unknown rover, nothing answered in time).
"""

from __future__ import annotations

import argparse
import sys

import msgspec

from common.connection import add_connection_args
from lunaris.fault import format_event, send_fault
from lunaris.tooling import ToolError, open_session, require_rover

__all__ = ["add_common_arguments", "confirm", "tool_main"]


def add_common_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=3.0, metavar="S",
                   help="how long to wait for the twin's answer (default 3 s)")
    p.add_argument("--wait", type=float, default=10.0, metavar="S",
                   help="how long to wait for the router (default 10 s)")
    p.add_argument("--json", action="store_true", help="print the answer as JSON")
    add_connection_args(p)


def confirm(args: argparse.Namespace, rover: str, key: str, payload: bytes | None,
            accepted: str) -> int:
    """Write ``payload`` on ``key`` (None: delete it), print the answer, return the exit status."""
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    try:
        require_rover(session, rover)
        ev = send_fault(session, rover, key, payload, args.timeout, accepted=accepted)
    finally:
        session.close()
    if ev is None:
        print(f"no answer within {args.timeout:g} s on {key}: is the service that owns it running?",
              file=sys.stderr)
        return 2
    print(msgspec.json.encode(ev).decode() if args.json else format_event(ev))
    return 1 if ev.kind == "rejected" else 0


def tool_main(name: str, run: object, args: argparse.Namespace) -> int:
    """Run ``run(args)`` and turn a :class:`ToolError` into its message and exit status."""
    try:
        return int(run(args))  # type: ignore[operator]
    except ToolError as exc:
        print(f"lunaris {name}: {exc}", file=sys.stderr)
        return exc.code
