"""``lunaris console``: the instructor console in a web browser (SPEC §8a).

    lunaris console                                   # http://127.0.0.1:8080/, you are the instructor
    lunaris console --accounts users.json --http 0.0.0.0:8080
    lunaris console users add ana --role instructor --accounts users.json

Without an accounts file it listens on loopback only and whoever opens the page is the
instructor (it says so when it starts). With one, every page and API call needs a sign-in,
observers may watch but not change anything, and it may listen on any address. The modules:
:mod:`~lunaris.console.server` (the web server and the sign-in gate),
:mod:`~lunaris.console.live` (the twin's values, pushed to the pages),
:mod:`~lunaris.console.api` (writes and queries), :mod:`~lunaris.console.auth` (accounts),
:mod:`~lunaris.console.extras` (scenarios, recordings, reports), :mod:`~lunaris.console.drive`
(traverses), :mod:`~lunaris.console.rovers` (what the page needs of each rover), ``static/``
(the page). The console takes its address first (one in use is said, with what holds it), and
its page is up before the twin is: it reaches the twin behind it.
"""

from __future__ import annotations

import argparse
import getpass
import os
import sys
import termios
import threading
from collections.abc import Mapping
from pathlib import Path

import zenoh

from common.connection import add_connection_args, config_from_args
from lunaris.address import AddressTaken, bind, free_port_after
from lunaris.client import ToolError, describe_endpoint, open_session
from lunaris.console.auth import ROLES, Accounts, AccountsError, is_loopback
from lunaris.console.rovers import RoverFiles

__all__ = ["ALLOW_HOST_ENV", "DEFAULT_HTTP", "add_arguments", "allowed_hosts", "main", "parse_http",
           "taken"]

DEFAULT_HTTP = "127.0.0.1:8080"
ACCOUNTS_ENV = "LUNARIS_CONSOLE_ACCOUNTS"
ALLOW_HOST_ENV = "LUNARIS_ALLOW_HOST"  # more names, comma-separated: a container's published name
REPO = Path(__file__).resolve().parent.parent.parent


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--http", default=DEFAULT_HTTP, metavar="HOST:PORT",
                   help=f"where the console listens (default {DEFAULT_HTTP})")
    p.add_argument("--accounts", metavar="FILE", default=os.environ.get(ACCOUNTS_ENV),
                   help=f"the users who may sign in (default ${ACCOUNTS_ENV}; none: loopback only, "
                        "the local user is the instructor)")
    p.add_argument("--scenarios", metavar="DIR", default=str(REPO / "config" / "scenarios"),
                   help="the scenarios offered (default config/scenarios)")
    p.add_argument("--rover", metavar="FILE", action="append", default=[],
                   help="a rover file of the session (repeatable): the console then knows which "
                        "radios follow the drive, their sites and footprints (lunaris up gives its own)")
    p.add_argument("--traverses", metavar="DIR", action="append", default=[],
                   help="a folder of traverse files offered besides the shipped ones "
                        "(config/traverses); repeatable")
    p.add_argument("--recordings", metavar="DIR", default="recordings",
                   help="where recordings are made and listed (default ./recordings)")
    p.add_argument("--tls-cert", metavar="FILE", help="serve HTTPS with this certificate (PEM)")
    p.add_argument("--tls-key", metavar="FILE", help="... and this private key (PEM)")
    p.add_argument("--wait", type=float, default=None, metavar="S",
                   help="how long to wait for the twin's Zenoh router, then stop (default: for ever; "
                        "the page is up meanwhile and says it waits)")
    p.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                   help="another name this computer is reached by (a request's Host header must "
                        "be one of the console's names: its address, localhost, and these); "
                        f"repeat, or list them in ${ALLOW_HOST_ENV}, separated by commas (both "
                        "count: a container's compose file passes the variable)")
    add_connection_args(p)
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    users = sub.add_parser("users", help="add, remove and list the console's users")
    verbs = users.add_subparsers(dest="verb", required=True, metavar="VERB")
    add = verbs.add_parser("add", help="add a user (asks for the password)")
    add.add_argument("name")
    add.add_argument("--role", choices=ROLES, required=True)
    add.add_argument("--password-stdin", action="store_true", help="read the password from standard input")
    add.add_argument("--replace", action="store_true", help="change an existing user's role or password")
    rm = verbs.add_parser("remove", help="remove a user: their sign-ins end at once")
    rm.add_argument("name")
    ls = verbs.add_parser("list", help="list the users and their roles")
    for q in (add, rm, ls):
        q.add_argument("--accounts", metavar="FILE", default=argparse.SUPPRESS)


def parse_http(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise ToolError(f"--http {text!r}: give HOST:PORT, e.g. {DEFAULT_HTTP}")
    return host.strip("[]") or "127.0.0.1", int(port)


def allowed_hosts(given: list[str], environ: Mapping[str, str] | None = None) -> list[str]:
    """The names given with ``--allow-host`` and those of ``$LUNARIS_ALLOW_HOST`` (comma-separated,
    blanks around them ignored)."""
    text = (os.environ if environ is None else environ).get(ALLOW_HOST_ENV, "")
    return [*given, *(n.strip() for n in text.split(",") if n.strip())]


def main(args: argparse.Namespace) -> int:
    try:
        if args.action == "users":
            return _users(args)
        return _serve(args)
    except (ToolError, AccountsError) as exc:
        print(f"lunaris console: {exc}", file=sys.stderr)
        return getattr(exc, "code", 2)


def _users(args: argparse.Namespace) -> int:
    if not args.accounts:
        raise ToolError(f"give --accounts FILE (or set ${ACCOUNTS_ENV})")
    if args.verb == "list":
        for name, role in Accounts(args.accounts).users().items():
            print(f"{name:<24} {role}")
        return 0
    if args.verb == "remove":
        Accounts.remove(args.accounts, args.name)
        print(f"removed {args.name} from {args.accounts}")
        return 0
    if args.password_stdin:
        password = sys.stdin.readline().rstrip("\n")
    else:
        no_terminal = ToolError("no terminal to ask the password on: give it on standard input "
                                "with --password-stdin", 2)
        if not sys.stdin.isatty():
            raise no_terminal
        try:
            password = getpass.getpass(f"password for {args.name}: ")
            again = getpass.getpass("again: ")
        except (EOFError, OSError, termios.error):
            raise no_terminal from None
        if again != password:
            raise ToolError("the two passwords differ", 1)
    Accounts.add(args.accounts, args.name, args.role, password, replace=args.replace)
    print(f"{args.name} may sign in to the console as {args.role} ({args.accounts})")
    return 0


def _serve(args: argparse.Namespace) -> int:
    import uvicorn

    from lunaris.console.server import Protocol, host_names, make_app

    host, port = parse_http(args.http)
    accounts = Accounts(args.accounts) if args.accounts else None
    if accounts is None and not is_loopback(host):
        raise ToolError(f"without an accounts file the console listens on this computer only "
                        f"(loopback), not on {host}: add users with `lunaris console users add NAME "
                        f"--role instructor --accounts FILE`, then give --accounts FILE")
    if bool(args.tls_cert) != bool(args.tls_key):
        raise ToolError("give both --tls-cert and --tls-key")
    try:
        config_from_args(args)
    except (ValueError, zenoh.ZError) as exc:
        raise ToolError(f"bad connection settings: {exc}") from None
    try:
        sock = bind(host, port)  # first: an address in use is said before anything starts
    except AddressTaken as exc:
        raise ToolError(taken(exc)) from None
    except OSError as exc:
        raise ToolError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    endpoint = describe_endpoint(args)
    rover_files = RoverFiles(Path(f) for f in args.rover)

    def opener(stop: threading.Event) -> zenoh.Session:
        return open_session(args, wait_s=args.wait, stop=stop, on_waiting=lambda: print(
            f"  waiting for the twin at {endpoint} (nothing answers there yet: start it with make run "
            "or lunaris up); the page is up and says so", flush=True))

    connection = [a for ep in args.connect or [] for a in ("--connect", ep)]
    if args.config:
        connection += ["--config", args.config]
    gave_up: list[str] = []
    server: list[uvicorn.Server] = []

    def give_up(why: str) -> None:
        gave_up.append(why)
        if server:
            server[0].should_exit = True

    app = make_app(opener, accounts, tls=bool(args.tls_cert), scenarios_dir=Path(args.scenarios),
                   recordings_dir=Path(args.recordings), connection=connection,
                   traverse_dirs=[Path(d) for d in args.traverses], rover_files=rover_files,
                   hosts=host_names(host, allowed_hosts(args.allow_host)), endpoint=endpoint,
                   give_up=give_up)
    scheme = "https" if args.tls_cert else "http"
    shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
    print(f"Lunaris console: {scheme}://{shown}:{port}/  (twin at {endpoint})", flush=True)
    if accounts is None:
        print("  no accounts file: listening on this computer only, and you, the local user, "
              "are the instructor", flush=True)
    else:
        users = accounts.users()
        n = sum(1 for r in users.values() if r == "instructor")
        print(f"  sign-in required: {len(users)} user(s) in {args.accounts}, {n} instructor(s)"
              + ("" if users else f" - add one with lunaris console users add NAME --role "
                                  f"instructor --accounts {args.accounts}"), flush=True)
        if not args.tls_cert and not is_loopback(host):
            print("  warning: passwords cross the network in clear text: give --tls-cert and "
                  "--tls-key, or put the console behind an HTTPS proxy", flush=True)
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", access_log=False,
                            timeout_graceful_shutdown=1, ssl_certfile=args.tls_cert,
                            ssl_keyfile=args.tls_key, lifespan="on", http=Protocol)
    server.append(uvicorn.Server(config))
    try:
        server[0].run(sockets=[sock])
    finally:
        sock.close()
    if gave_up:
        raise ToolError(gave_up[0])
    print("Lunaris console: stopped", flush=True)
    return 0


def taken(exc: AddressTaken, option: str = "--http", make_port: bool = False) -> str:
    """Words for a console address in use: what holds it, and another address to give."""
    nxt = free_port_after(exc.host, exc.port)
    other = f"{exc.host}:{nxt}" if nxt else f"{exc.host}:PORT"
    make = f" (make run PORT={nxt or 'PORT'})" if make_port else ""
    command = "lunaris up --console" if option == "--console" else "lunaris console --http"
    return (f"the console's address {exc.host}:{exc.port} is taken by {exc.holder}. Give the "
            f"console another address: {command} {other}{make}, or stop what holds it")
