"""A TCP address to listen on, and in words what holds it when it is taken.

``lunaris console`` binds its address before anything else and ``lunaris up`` looks at the
console's and the router's addresses before it starts anything, so that an address in use is
said at once, with what holds it (another Lunaris console and the twin it serves, another
program and its process, a program of another user) and what to do, instead of a console
announced and then failing.

What holds a port is read from Linux's ``/proc``: the listening socket's inode in
``/proc/net/tcp`` and ``tcp6``, then the process whose open files include it (the processes of
this user only; another's are said to be another user's). A web server there is asked
``GET /api/about``: a Lunaris console answers who it is.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

__all__ = ["AddressTaken", "bind", "ensure_free", "free_port_after", "holder", "listening"]

ABOUT_PATH = "/api/about"
ABOUT_APP = "lunaris console"
_LISTEN = "0A"  # TCP_LISTEN in /proc/net/tcp's st column
_SHOWN_CMD = 120  # characters of a command line said


class AddressTaken(Exception):
    """The address ``host:port`` is in use; ``holder`` says by what, in words."""

    def __init__(self, host: str, port: int, holder: str):
        super().__init__(f"{host}:{port} is taken by {holder}")
        self.host, self.port, self.holder = host, port, holder


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (as uvicorn makes its own: ``SO_REUSEADDR``);
    :class:`AddressTaken` when something else listens there."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(2048)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise AddressTaken(host, port, holder(host, port)) from None
        raise
    return sock


def ensure_free(host: str, port: int) -> None:
    """:class:`AddressTaken` if ``host:port`` cannot be listened on now."""
    bind(host, port).close()


def free_port_after(host: str, port: int, tries: int = 20) -> int | None:
    """The first port after ``port`` that ``host`` can listen on (to suggest one), or None."""
    for candidate in range(port + 1, min(port + 1 + tries, 65536)):
        try:
            ensure_free(host, candidate)
        except (AddressTaken, OSError):
            continue
        return candidate
    return None


def _proc_listeners(port: int) -> Iterator[tuple[str, int]]:
    """(inode, uid) of each socket listening on ``port`` (any address), from /proc/net."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if len(cols) < 10 or cols[3] != _LISTEN:
                continue
            if int(cols[1].rsplit(":", 1)[1], 16) == port:
                yield cols[9], int(cols[7])


def listening(port: int) -> tuple[int | None, str, int | None]:
    """(pid, command line, uid) of the process listening on ``port``: the pid and command are
    None and "" when it is not one of this user's processes (or /proc cannot say)."""
    found = list(_proc_listeners(port))
    if not found:
        return None, "", None
    inodes = {f"socket:[{inode}]" for inode, _ in found}
    uid = found[0][1]
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            fds = os.scandir(f"/proc/{entry.name}/fd")
        except OSError:
            continue
        with fds:
            for fd in fds:
                try:
                    if os.readlink(fd.path) in inodes:
                        return int(entry.name), _command(int(entry.name)), uid
                except OSError:
                    continue
    return None, "", uid


def _command(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return ""
    args = [a.decode("utf-8", "replace") for a in raw.split(b"\0") if a]
    if len(args) > 2 and args[1:3] == ["-m", "lunaris.cli"]:
        args = ["lunaris", *args[3:]]  # as the user typed it
    elif args:
        args[0] = os.path.basename(args[0])
    text = " ".join(args)
    return text if len(text) <= _SHOWN_CMD else text[:_SHOWN_CMD] + "..."


def _about(host: str, port: int) -> tuple[dict | None, str]:
    """What a web server at ``host:port`` says it is: (a Lunaris console's ``/api/about``, or
    None; the ``Server`` header of another web server, or "")."""
    shown = f"[{host}]" if ":" in host else host
    if host in ("0.0.0.0", "::", ""):
        shown = "127.0.0.1"
    try:
        with urllib.request.urlopen(f"http://{shown}:{port}{ABOUT_PATH}", timeout=1.0) as r:
            data = json.loads(r.read(4096))
            if isinstance(data, dict) and data.get("app") == ABOUT_APP:
                return data, ""
            return None, r.headers.get("Server", "") or "a web server"
    except urllib.error.HTTPError as exc:
        return None, exc.headers.get("Server", "") or "a web server"
    except (OSError, ValueError):
        return None, ""


def holder(host: str, port: int) -> str:
    """What holds ``host:port``, in words: "another Lunaris console (pid 4242: lunaris
    console --http 127.0.0.1:8080 ...), serving the twin at tcp/127.0.0.1:7447 (rovers:
    mapp-1)", "a program of another user", "the web server nginx (pid 77: nginx)" ..."""
    pid, command, uid = listening(port)
    process = f"pid {pid}: {command}" if pid is not None and command else (
        f"pid {pid}" if pid is not None else "")
    about, server = _about(host, port)
    if about is not None:
        twin = about.get("twin")
        rovers = about.get("rovers")
        serving = (f", serving the twin at {twin}" if twin else "") + (
            f" (rovers: {', '.join(map(str, rovers)) or 'none yet'})" if isinstance(rovers, list) else "")
        return "another Lunaris console" + (f" ({process})" if process else "") + serving
    if server:
        what = "a web server" if server == "a web server" else f"the web server {server!r}"
        return what + (f" ({process})" if process else "")
    if process:
        return f"another program ({process})"
    if uid is not None and uid != os.getuid():
        return "a program of another user"
    return "another program"
