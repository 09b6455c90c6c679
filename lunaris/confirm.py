"""What every instructor command shares: one write, the twin's answer printed, an exit status.

``lunaris fault``, ``rail``, ``clock``, ``input``, ``reset``, ``snapshot`` and ``traverse``
each plan one write (:func:`common.writes.plan_write`), send it through the client
(:class:`lunaris.client.Writer`, as the ``instructor``) and print the answer: the accepting
event (``fault_injected``, ``command``, ``clock``, ``input``, ``session``), the rejection with
its reason, or why it was not applied.

Exit status: 0 accepted; 1 rejected (by the twin, or refused before sending because it cannot
be valid); 2 not applied (no router, an unknown rover, the owner unreachable, no answer in time).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator

import msgspec

from common.connection import add_connection_args
from common.messages import BadInput, Event
from common.writes import Write, plan_write
from lunaris.client import (
    ANSWER_S,
    Accepted,
    Answer,
    Mirror,
    NotApplied,
    Rejected,
    ToolError,
    Writer,
    close_session,
    humane,
    live_rovers,
    open_session,
    unknown_rover,
)

__all__ = ["add_common_arguments", "confirm", "format_event", "plan", "print_answer", "send",
           "tool_main", "writer_for"]


def add_common_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=ANSWER_S, metavar="S",
                   help=f"how long to wait for the twin's answer (default {ANSWER_S:g} s)")
    p.add_argument("--wait", type=float, default=10.0, metavar="S",
                   help="how long to wait for a router that does not answer (default 10 s)")
    p.add_argument("--json", action="store_true", help="print the answer as JSON")
    add_connection_args(p)


def plan(rover: str, tail: str, payload: bytes | None) -> Write:
    """The checked write; :class:`ToolError` (exit 1) saying in words what is wrong."""
    try:
        return plan_write(rover, tail, payload)
    except BadInput as exc:
        raise ToolError(humane(str(exc)), 1) from None


@contextlib.contextmanager
def writer_for(args: argparse.Namespace, rover: str) -> Iterator[Writer]:
    """A writer on ``rover`` for one command: the session opened (or :class:`ToolError`), the
    rover's services and link known (:meth:`Writer.ready`), an unknown rover refused."""
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    mirror = Mirror(rover, families=("clock",), events=False)
    writer: Writer | None = None
    try:
        mirror.start(session)
        writer = Writer(session, mirror, "instructor", args.timeout)
        if not writer.ready(rover):
            raise ToolError(unknown_rover(rover, live_rovers(session)))
        yield writer
    finally:
        if writer is not None:
            writer.close()
        mirror.close()
        close_session(session)


def send(args: argparse.Namespace, write: Write) -> Answer:
    with writer_for(args, write.rover) as writer:
        return writer.write(write)


def format_event(ev: Event) -> str:
    verdict = "rejected" if ev.kind == "rejected" else "accepted"
    message = humane(ev.message) if ev.kind == "rejected" else ev.message
    return f"{verdict}: {ev.kind} at t={ev.t_s:.1f} s [{ev.source}] {message}  ({ev.key})"


def print_answer(name: str, answer: Answer, as_json: bool = False) -> int:
    """Print the answer (the event on stdout; why it was not applied on stderr) and return
    the exit status: 0 accepted, 1 rejected, 2 not applied."""
    if isinstance(answer, NotApplied):
        if as_json:
            print(msgspec.json.encode({"verdict": "not applied", "message": answer.reason,
                                       "key": answer.write.key}).decode())
        print(f"lunaris {name}: {answer.reason}  ({answer.write.key})", file=sys.stderr)
        return 2
    print(msgspec.json.encode(answer.event).decode() if as_json else format_event(answer.event))
    return 1 if isinstance(answer, Rejected) else 0 if isinstance(answer, Accepted) else 2


def confirm(args: argparse.Namespace, name: str, write: Write) -> int:
    """Send ``write``, print the answer, return the exit status."""
    return print_answer(name, send(args, write), args.json)


def tool_main(name: str, run: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run ``run(args)`` and turn a :class:`ToolError` into its message and exit status."""
    try:
        return int(run(args))
    except ToolError as exc:
        print(f"lunaris {name}: {exc}", file=sys.stderr)
        return exc.code
