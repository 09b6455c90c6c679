"""Opening a session on the twin, as every tool does, and saying in words when it cannot.

Client sessions retry a missing router forever (``connect/timeout_ms -1``), and ``zenoh.open``
blocks in native code where Ctrl-C cannot reach it; so the session is opened on a helper thread
while the main thread waits, with a deadline, and stays interruptible. Before that, a tool that
means to give up (a finite ``wait_s``) knocks on the router's TCP port: a refused connection
means no router listens there, and the tool says so at once instead of after its deadline.
When the deadline passes though a router listens there, the tool asks Zenoh once more, in a
child process whose Zenoh log it reads: a router that answered the session's opening with a
close refused its credentials (a wrong or rotated password), which is said so, rather than
"no router answered".
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from common import keys
from common.connection import CONFIG_ENV, DEFAULT_ENDPOINT, config_from_args

__all__ = ["START_HINT", "ToolError", "close_session", "describe_endpoint", "ignored", "live_rovers",
           "open_session", "require_rover", "unknown_rover"]

START_HINT = "start the twin with `make run` or `lunaris up` (or give --connect ENDPOINT)"


class ToolError(Exception):
    """A problem the user can fix; ``code`` is the exit status of the command."""

    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


_IGNORED: set[str] = set()
_IGNORED_MAX = 64  # keys said aloud; past them, once that more are skipped


def ignored(key: str, reason: str) -> None:
    """Say, once per key, that a sample the tool cannot read is being skipped (a payload that
    is not what its key carries: a foreign or forged publisher). The keys remembered are
    bounded: a flood of forged keys is said once, not kept."""
    if key in _IGNORED or len(_IGNORED) > _IGNORED_MAX:
        return
    _IGNORED.add(key)
    if len(_IGNORED) > _IGNORED_MAX:
        print(f"ignoring samples on {key}: {reason}; more keys with unreadable samples are "
              "skipped without a word", file=sys.stderr, flush=True)
        return
    print(f"ignoring samples on {key}: {reason}", file=sys.stderr, flush=True)


def describe_endpoint(args: argparse.Namespace) -> str:
    """Where the tool connects, in words (for progress and error messages)."""
    if getattr(args, "connect", None):
        return ", ".join(args.connect)
    config = getattr(args, "config", None) or os.environ.get(CONFIG_ENV)
    return f"the router of {config}" if config else DEFAULT_ENDPOINT


def _tcp_addresses(endpoints: list[str]) -> list[tuple[str, int]] | None:
    """The (host, port) of each ``tcp/`` or ``tls/`` endpoint; None when any endpoint is of
    another kind (then only Zenoh can tell whether a router is there)."""
    out = []
    for ep in endpoints:
        proto, sep, rest = str(ep).partition("/")
        if not sep or proto not in ("tcp", "tls"):
            return None
        address = rest.split("#", 1)[0].split("?", 1)[0]
        host, sep, port = address.rpartition(":")
        if not sep or not port.isdigit():
            return None
        out.append((host.strip("[]"), int(port)))
    return out


def _all_refused(conf: zenoh.Config, timeout_s: float) -> bool:
    """Whether every router endpoint of ``conf`` refuses a TCP connection right now (nothing
    listens there). False when one accepts, does not answer in time, or cannot be tried."""
    try:
        endpoints = json.loads(conf.get_json("connect/endpoints"))
    except (zenoh.ZError, ValueError):
        return False
    if isinstance(endpoints, dict):  # per-mode endpoints: the client's
        endpoints = endpoints.get("client", [])
    addresses = _tcp_addresses(endpoints) if isinstance(endpoints, list) and endpoints else None
    if not addresses:
        return False
    for host, port in addresses:
        try:
            with socket.create_connection((host, port), timeout=timeout_s):
                return False
        except ConnectionRefusedError:
            continue
        except OSError as exc:
            if exc.errno != errno.ECONNREFUSED:
                return False
    return True


# Runs in a child process: opens the session of argv[1:] (connect endpoints as JSON, the
# configuration file or "") once, failing fast, with Zenoh's transport errors in its output.
_PROBE = """
import json, sys
import zenoh
from common.connection import make_config
zenoh.init_log_from_env_or("zenoh_transport=error")
conf = make_config("client", connect=json.loads(sys.argv[1]) or None, config_file=sys.argv[2] or None)
conf.insert_json5("connect/timeout_ms", "2000")
conf.insert_json5("connect/exit_on_failure", "true")
try:
    zenoh.open(conf).close()
    print("OPENED", flush=True)
except zenoh.ZError as exc:
    print(f"FAILED {exc}", flush=True)
"""
# zenoh 1.10's words when the router answers the session's opening with a close: what its
# authentication (user and password) does to credentials it refuses
_REFUSED = re.compile(r"Received a close message .*in response to an? (Init|Open)Syn")
PROBE_TIMEOUT_S = 10.0


def _someone_listens(conf: zenoh.Config) -> bool:
    """Whether a TCP connection to one of ``conf``'s router endpoints is accepted right now."""
    try:
        endpoints = json.loads(conf.get_json("connect/endpoints"))
    except (zenoh.ZError, ValueError):
        return False
    if isinstance(endpoints, dict):
        endpoints = endpoints.get("client", [])
    for host, port in (_tcp_addresses(endpoints) if isinstance(endpoints, list) else None) or []:
        try:
            with socket.create_connection((host, port), timeout=1.0):
                return True
        except OSError:
            continue
    return False


def refused_credentials(args: argparse.Namespace) -> bool:
    """Whether the router of ``args`` answers and refuses the session's credentials: one more
    opening, in a child process (Zenoh logs the router's close to its output, not to Python),
    that the router closed during the handshake."""
    root = Path(__file__).resolve().parents[2]  # the source tree: common/, lunaris/
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), env.get("PYTHONPATH")]))
    try:
        connect = json.dumps(getattr(args, "connect", None) or [])
        done = subprocess.run([sys.executable, "-c", _PROBE, connect, getattr(args, "config", None) or ""],
                              capture_output=True, text=True, env=env, timeout=PROBE_TIMEOUT_S,
                              stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return "OPENED" not in done.stdout and _REFUSED.search(done.stdout + done.stderr) is not None


def _who(args: argparse.Namespace, conf: zenoh.Config) -> str:
    try:
        user = json.loads(conf.get_json("transport/auth/usrpwd/user"))
    except (zenoh.ZError, ValueError):
        user = None
    config = getattr(args, "config", None) or os.environ.get(CONFIG_ENV)
    return (f"user {user!r}" if user else "no user") + (f" of {config}" if config else "")


def open_session(args: argparse.Namespace, wait_s: float | None = 10.0,
                 on_waiting: Callable[[], None] | None = None,
                 stop: threading.Event | None = None) -> zenoh.Session:
    """A client session from the shared connection options.

    Raises :class:`ToolError` when the configuration is bad, when no router listens at the
    endpoint (a refused connection: at once, with ``wait_s`` finite) or no router answers
    within ``wait_s`` (None: wait for ever), or when ``stop`` is set while it waits (within
    0.2 s). ``on_waiting`` is called once if the router is not there at once, to tell the user
    what the tool is waiting for.
    """
    try:
        conf = config_from_args(args)
    except (ValueError, zenoh.ZError) as exc:
        raise ToolError(f"bad connection settings: {exc}") from None
    if wait_s is not None and _all_refused(conf, min(1.0, wait_s)):
        raise ToolError(f"No Zenoh router answered at {describe_endpoint(args)}: the connection "
                        f"was refused (nothing listens there); {START_HINT}")
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
    deadline = None if wait_s is None else time.monotonic() + max(0.0, wait_s - 1.0)
    while thread.is_alive():  # short joins keep Ctrl-C (and stop) responsive
        if stop is not None and stop.is_set():
            raise ToolError("stopped while waiting for the router")
        if deadline is not None and time.monotonic() >= deadline:
            break
        thread.join(0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic())))
    if not box:
        if _someone_listens(conf) and refused_credentials(args):
            raise ToolError(f"the router at {describe_endpoint(args)} answered and refused these "
                            f"credentials ({_who(args, conf)}): the password is wrong or was "
                            "rotated; use the client configuration of the deployment's current "
                            "secrets (lunaris deploy secrets DIR makes them)")
        raise ToolError(f"No Zenoh router answered at {describe_endpoint(args)} within {wait_s:g} s; "
                        f"{START_HINT}")
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
            try:
                thread.join(max(0.0, deadline - time.monotonic()))
            except RuntimeError:  # listed while it starts (threading's "limbo"): nothing to wait for yet
                continue


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


def unknown_rover(rover: str, live: dict[str, set[str]] | list[str]) -> str:
    """Words for a rover no service serves, naming the live ones (or how to start the twin)."""
    known = ", ".join(sorted(live))
    return (f"unknown rover {rover!r}: no Lunaris service serves it (live rovers: {known})" if known
            else f"unknown rover {rover!r}: no Lunaris service serves it (live rovers: none; "
                 f"{START_HINT})")


def require_rover(session: zenoh.Session, rover: str) -> set[str]:
    """The services live for ``rover``; :class:`ToolError` naming the live rovers if none."""
    live = live_rovers(session)
    if rover not in live:
        raise ToolError(unknown_rover(rover, live))
    return live[rover]
