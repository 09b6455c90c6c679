"""What the instructor tools share: opening a session, finding rovers, reading events.

Client sessions retry a missing router forever (``connect/timeout_ms -1``), and
``zenoh.open`` blocks in native code where Ctrl-C cannot reach it; so the
session is opened on a helper thread while the main thread waits, with a
deadline, and stays interruptible.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Callable

import zenoh

from common import keys
from common.connection import CONFIG_ENV, DEFAULT_ENDPOINT, config_from_args

__all__ = ["ToolError", "close_session", "describe_endpoint", "ignored", "live_rovers",
           "open_session", "require_rover"]


class ToolError(Exception):
    """A problem the user can fix; ``code`` is the exit status of the command."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


_IGNORED: set[str] = set()


def ignored(key: str, reason: str) -> None:
    """Say, once per key, that a sample the tool cannot read is being skipped (a payload that
    is not what its key carries: a foreign or forged publisher)."""
    if key not in _IGNORED:
        _IGNORED.add(key)
        print(f"ignoring samples on {key}: {reason}", file=sys.stderr, flush=True)


def describe_endpoint(args: argparse.Namespace) -> str:
    """Where the tool connects, in words (for progress and error messages)."""
    if getattr(args, "connect", None):
        return ", ".join(args.connect)
    config = getattr(args, "config", None) or os.environ.get(CONFIG_ENV)
    return f"the router of {config}" if config else DEFAULT_ENDPOINT


def open_session(args: argparse.Namespace, wait_s: float | None = 10.0,
                 on_waiting: Callable[[], None] | None = None) -> zenoh.Session:
    """A client session from the shared connection options.

    Raises :class:`ToolError` when the configuration is bad or no router answers within
    ``wait_s`` (None: wait for ever). ``on_waiting`` is called once if the router is not
    there at once, to tell the user what the tool is waiting for.
    """
    try:
        conf = config_from_args(args)
    except (ValueError, zenoh.ZError) as exc:
        raise ToolError(f"bad connection settings: {exc}") from None
    box: list = []

    def opener() -> None:
        try:
            box.append(zenoh.open(conf))
        except Exception as exc:  # reported by the waiting thread
            box.append(exc)

    thread = threading.Thread(target=opener, name="zenoh-open", daemon=True)
    thread.start()
    thread.join(min(1.0, wait_s) if wait_s is not None else 1.0)
    if not box and on_waiting is not None:
        on_waiting()
    thread.join(None if wait_s is None else max(0.0, wait_s - 1.0))
    while wait_s is None and thread.is_alive():  # short joins keep Ctrl-C responsive
        thread.join(0.2)
    if not box:
        raise ToolError(f"no Zenoh router answered at {describe_endpoint(args)} within {wait_s:g} s")
    if isinstance(box[0], Exception):
        raise ToolError(f"cannot open a Zenoh session: {box[0]}")
    return box[0]


CALLBACK_THREADS_WAIT_S = 2.0  # the longest close_session waits for zenoh's callback threads


def close_session(session: zenoh.Session) -> None:
    """Close ``session`` and wait for the Python threads in which zenoh ran its callbacks.

    zenoh-python runs a subscriber's callbacks on a thread of its own, a daemon when the
    subscriber was declared from a daemon thread (:func:`open_session`'s waiting is one). Such
    a thread is not waited for at exit: closing the session wakes it while the interpreter
    shuts down, and the process aborts ("FATAL: exception not rethrown", exit -6; 5 runs of
    30 of ``lunaris watch --once`` on a loaded machine).
    """
    session.close()
    deadline = time.monotonic() + CALLBACK_THREADS_WAIT_S
    for thread in threading.enumerate():
        if thread.daemon and thread.name.endswith("(pyo3-closure)"):
            thread.join(max(0.0, deadline - time.monotonic()))


def live_rovers(session: zenoh.Session, timeout_s: float = 2.0) -> dict[str, set[str]]:
    """Rover id -> the services that have declared a liveliness token for it."""
    out: dict[str, set[str]] = {}
    for reply in session.liveliness().get(keys.service("*", "*"), timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            rover, parts = keys.split(str(reply.ok.key_expr))
        except ValueError:
            continue
        out.setdefault(rover, set()).add(parts[-1])
    return out


def require_rover(session: zenoh.Session, rover: str) -> set[str]:
    """The services live for ``rover``; :class:`ToolError` naming the live rovers if none."""
    live = live_rovers(session)
    if rover not in live:
        known = ", ".join(sorted(live)) or "none"
        raise ToolError(f"unknown rover {rover!r}: no Lunaris service serves it (live rovers: {known})")
    return live[rover]
