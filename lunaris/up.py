"""``lunaris up``: an embedded router and every service for the given rovers, supervised.

Each service runs in its own process (``lunaris run``), connected as a client to
the router this process opens. A service no rover needs is not started (the drive, when no
rover has a ``drive`` section). A service that dies is restarted (with a growing
back-off if it keeps dying) and resumes from its persisted state; one that keeps dying soon
after it starts (``FAILING_AFTER`` times in a row, each within ``QUICK_EXIT_S``) is shown
FAILED with its last error and not restarted again: a crash loop helps no one, the error
does. A compact status line per rover is shown; Ctrl-C stops everything.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgspec
import zenoh

from common import keys
from common.connection import DEFAULT_ENDPOINT, make_config
from common.messages import BatteryState, RailState, decode
from lunaris.address import AddressTaken, ensure_free, free_port_after
from lunaris.client import ToolError
from lunaris.processes import lunaris_cmd, run_args, stop_processes
from lunaris.run import ALREADY_RUNNING, CONFIG_ERROR, SERVICES, SUPERVISOR_ENV, load_rovers, served

__all__ = ["ROVERS_PER_BRIDGE", "Supervisor", "add_arguments", "default_bridges", "main"]

DEFAULT_ROVER = "config/rovers/mapp.yaml"
# A bridge process serves this many rovers by default: at 100 MAPP rovers each of two
# shards took 25-45 % of a core (bench/fleet.py), one Python thread's worth to spare.
ROVERS_PER_BRIDGE = 50
QUICK_EXIT_S = 30.0  # a service that exits within this of its start has failed to start
FAILING_AFTER = 5  # so many such exits in a row: shown FAILED, not restarted again


def default_bridges(rovers: int) -> int:
    """How many bridge processes share a fleet of ``rovers`` when ``--bridges`` is not given."""
    return max(1, -(-rovers // ROVERS_PER_BRIDGE))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rover", action="append", metavar="FILE",
                   help=f"rover definition, repeat for a fleet (default {DEFAULT_ROVER})")
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"router endpoint (default {DEFAULT_ENDPOINT})")
    p.add_argument("--state-dir", metavar="DIR",
                   help="persisted state (default: a fresh temporary folder per session)")
    p.add_argument("--services", default=",".join(SERVICES),
                   help="comma-separated services to run (default: all)")
    p.add_argument("--seed", type=int, default=None, help="random seed for the loads")
    p.add_argument("--bridge-config", metavar="FILE", default=None,
                   help="the bridge's mapping (default config/bridge/default.yaml)")
    p.add_argument("--bridges", type=int, default=None, metavar="N",
                   help="bridge processes sharing the fleet (default: one per "
                        f"{ROVERS_PER_BRIDGE} rovers)")
    p.add_argument("--no-status", action="store_true", help="no live status display")
    p.add_argument("--console", nargs="?", const="127.0.0.1:8080", default=None, metavar="HOST:PORT",
                   help="also serve the instructor console (default address 127.0.0.1:8080), "
                        "supervised like the services")
    p.add_argument("--console-accounts", metavar="FILE",
                   help="the console's accounts file (without one it serves this computer only)")
    p.add_argument("--recordings", metavar="DIR", default="recordings",
                   help="where the console makes and lists its recordings (default ./recordings, "
                        "from where up runs: kept when a temporary state folder goes)")


class Supervisor:
    """Starts the services and restarts any that exit while it runs."""

    def __init__(self, services: list[str], rover_files: list[str], endpoint: str,
                 state_dir: Path, seed: int | None, bridge_config: str | None = None,
                 bridges: int = 1):
        if bridges > 1 and "bridge" in services:
            at = services.index("bridge")
            services = (services[:at] + [f"bridge-{k}" for k in range(1, bridges + 1)]
                        + services[at + 1:])
        self.services = services
        self.rover_files = rover_files
        self.endpoint = endpoint
        self.state_dir = state_dir
        self.seed = seed
        self.bridge_config = bridge_config
        self.bridges = bridges
        self.procs: dict[str, subprocess.Popen] = {}
        self.restarts: dict[str, int] = dict.fromkeys(self.services, 0)
        self.failed: dict[str, str] = {}  # service -> why it is not restarted
        self._next_start: dict[str, float] = {}
        self._started: dict[str, float] = {}  # service -> monotonic time of its last start
        self._quick: dict[str, list[float]] = {}  # service -> lifetimes of its quick exits in a row
        self.commands: dict[str, list[str]] = {}  # processes other than services: the console

    def add(self, name: str, args: list[str]) -> None:
        """Supervise another ``lunaris`` command (the console) like a service."""
        self.services.append(name)
        self.restarts[name] = 0
        self.commands[name] = lunaris_cmd(*args)

    def command(self, service: str) -> list[str]:
        if service in self.commands:
            return self.commands[service]
        kind, _, shard = service.partition("-")
        extra = []
        if kind == "bridge" and self.bridge_config is not None:
            extra += ["--bridge-config", self.bridge_config]
        if shard:
            extra += ["--shard", f"{shard}/{self.bridges}"]
        return lunaris_cmd(*run_args(service, self.rover_files, self.state_dir,
                                     connect=self.endpoint, seed=self.seed, extra=extra))

    def log_path(self, service: str) -> Path:
        return self.state_dir / "logs" / f"{service}.log"

    def start(self, service: str) -> None:
        # What a service says goes to its log (a banner would scroll the status lines away);
        # when it exits, the end of its log is shown.
        log = self.log_path(service)
        log.parent.mkdir(parents=True, exist_ok=True)
        # Each child follows this process: it dies with it, kill -9 or not (lunaris.supervised,
        # set in the child: no preexec_fn in a process with the router's threads). Started from
        # the main thread only: the kernel's parent-death signal follows the thread that forked.
        env = {**os.environ, SUPERVISOR_ENV: str(os.getpid())}
        with log.open("ab") as out:
            proc = subprocess.Popen(self.command(service), stdin=subprocess.DEVNULL, stdout=out,
                                    stderr=subprocess.STDOUT, env=env, start_new_session=True)
        self.procs[service] = proc
        self._started[service] = time.monotonic()
        print(f"[up] {service} started (pid {proc.pid})", flush=True)

    def _tail(self, service: str, lines: int = 8) -> str:
        try:
            text = self.log_path(service).read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(f"      {line}" for line in text.strip().splitlines()[-lines:])

    def _last_error(self, service: str) -> str:
        """The last error a service's log shows (a traceback's last line), else its last line."""
        try:
            lines = [ln.strip() for ln in self.log_path(service).read_text(errors="replace")
                     .splitlines()[-200:] if ln.strip()]
        except OSError:
            return "no log"
        errors = [ln for ln in lines if ln.split(":", 1)[0].replace(".", "").isidentifier()
                  and ln.split(":", 1)[0].endswith(("Error", "Exception", "Exit", "Interrupt"))]
        last = (errors or lines or ["nothing in its log"])[-1]
        return last if len(last) <= 200 else last[:197] + "..."

    def start_all(self) -> None:
        for service in self.services:
            self.start(service)

    def poll(self) -> None:
        """Restart the services that have exited, backing off when one keeps failing. A
        service that cannot work as configured (exit 2) or finds another instance already
        serving its rovers (exit 3) is not restarted: it is shown as failed, with its error,
        once."""
        now = time.monotonic()
        for service, proc in list(self.procs.items()):
            code = proc.poll()
            if code is None or service in self.failed:
                continue
            if code in (CONFIG_ERROR, ALREADY_RUNNING):
                why = "configuration error" if code == CONFIG_ERROR else "already running"
                self.failed[service] = why
                print(f"[up] {service} (pid {proc.pid}) FAILED ({why}, exit {code}); not "
                      f"restarting it. It said:\n{self._tail(service)}", flush=True)
                continue
            due = self._next_start.get(service)
            if due is None:
                lived = now - self._started.get(service, now)
                quick = self._quick.setdefault(service, [])
                if lived < QUICK_EXIT_S:
                    quick.append(lived)
                else:
                    quick.clear()
                if len(quick) >= FAILING_AFTER:
                    error = self._last_error(service)
                    self.failed[service] = f"kept failing: {error}"
                    print(f"[up] {service} (pid {proc.pid}) FAILED: it exited {len(quick)} times in "
                          f"a row, each within {QUICK_EXIT_S:g} s of its start (last exit status "
                          f"{code}); not restarting it. Its last error: {error}\n"
                          f"{self._tail(service)}", flush=True)
                    continue
                self.restarts[service] += 1
                delay = min(5.0, 0.2 * 2 ** min(self.restarts[service] - 1, 5))
                self._next_start[service] = now + delay
                print(f"[up] {service} (pid {proc.pid}) exited with {code}; "
                      f"restarting in {delay:.1f} s\n{self._tail(service, 4)}", flush=True)
            elif now >= due:
                del self._next_start[service]
                self.start(service)

    def stop_all(self, timeout_s: float = 5.0) -> None:
        stop_processes(self.procs.values(), timeout_s)


class _Status:
    """What the status line needs, kept up to date by subscriptions on the router session."""

    def __init__(self, session: zenoh.Session, rover_ids: list[str]):
        self.battery: dict[str, BatteryState] = {}
        self.rails: dict[str, dict[str, str]] = {r: {} for r in rover_ids}
        self.services: dict[str, set[str]] = {r: set() for r in rover_ids}
        self._subs = [
            session.declare_subscriber(keys.battery_state("*"), self._on_battery),
            session.declare_subscriber(keys.rail_state("*", "*"), self._on_rail),
            session.liveliness().declare_subscriber(keys.service("*", "*"), self._on_token,
                                                    history=True),
        ]

    # A payload that is no state (a forged or junk put: the services say it in words) leaves
    # the line as it was; it printed a traceback into up's output.

    def _on_battery(self, s: zenoh.Sample) -> None:
        rover, _ = keys.split(str(s.key_expr))
        if rover in self.rails:
            with contextlib.suppress(msgspec.DecodeError):  # a ValidationError is one
                self.battery[rover] = decode(s.payload.to_bytes(), BatteryState)

    def _on_rail(self, s: zenoh.Sample) -> None:
        rover, parts = keys.split(str(s.key_expr))
        if rover in self.rails:
            with contextlib.suppress(msgspec.DecodeError):
                self.rails[rover][parts[1]] = decode(s.payload.to_bytes(), RailState).state

    def _on_token(self, s: zenoh.Sample) -> None:
        rover, parts = keys.split(str(s.key_expr))
        live = self.services.setdefault(rover, set())
        (live.add if s.kind == zenoh.SampleKind.PUT else live.discard)(parts[-1])

    def lines(self, expected: dict[str, int], failed: dict[str, str] | None = None) -> list[str]:
        """One line per rover; ``expected`` is how many services serve each rover."""
        out = []
        failing = (" FAILED: " + ", ".join(f"{s} ({why})" for s, why in sorted(failed.items()))
                   if failed else "")
        for rover in self.rails:
            b = self.battery.get(rover)
            rails = self.rails[rover]
            on = sum(1 for s in rails.values() if s == "on")
            svc = f"services {len(self.services.get(rover, ()))}/{expected.get(rover, 0)}{failing}"
            if b is None:
                out.append(f"{rover:<12} waiting for the battery ...  {svc}")
                continue
            faults = ",".join(b.faults) or "nominal"
            out.append(
                f"{rover:<12} t={b.t_s:9.1f}s  soc={b.soc * 100:7.3f}%  {b.voltage_v:6.2f} V  "
                f"{b.current_a:7.2f} A  {b.temperature_c:5.1f} C  rails on {on}/{len(rails)}  "
                f"{svc}  [{faults}]")
        return out


def _check_addresses(console: str | None, listen: list[str]) -> None:
    """:class:`ToolError` in words when the console's address or a router endpoint (tcp) is
    in use: what holds it, and what to give instead."""
    if console:
        from lunaris.console import parse_http, taken

        host, port = parse_http(console)
        try:
            ensure_free(host, port)
        except AddressTaken as exc:
            raise ToolError(taken(exc, "--console", make_port=True) + "; nothing was started") from None
        except OSError as exc:
            raise ToolError(f"the console cannot listen on {host}:{port}: {exc.strerror or exc}; "
                            "nothing was started") from None
    for endpoint in listen:
        proto, _, address = endpoint.partition("/")
        host, sep, port_text = address.split("#", 1)[0].rpartition(":")
        if proto not in ("tcp", "tls") or not sep or not port_text.isdigit():
            continue
        host = host.strip("[]")
        try:
            ensure_free(host, int(port_text))
        except AddressTaken as exc:
            nxt = free_port_after(host, int(port_text))
            other = f"{proto}/{address.rpartition(':')[0]}:{nxt or 'PORT'}"
            raise ToolError(
                f"the router's address {endpoint} is taken by {exc.holder} (another twin?): "
                f"{os.strerror(errno.EADDRINUSE)}; nothing was started. Give the router another "
                f"address: lunaris up --listen {other} (the tools then --connect {other}), or stop "
                "what holds it") from None
        except OSError:
            continue  # an address of another machine, or a name: the router says


def main(args: argparse.Namespace) -> int:
    rover_files = args.rover or [DEFAULT_ROVER]
    rovers = load_rovers(rover_files)
    services = [s.strip() for s in args.services.split(",") if s.strip()]
    unknown = sorted(set(services) - set(SERVICES))
    if unknown:
        print(f"unknown service(s): {', '.join(unknown)} (known: {', '.join(SERVICES)})",
              file=sys.stderr)
        return 2
    for service in [s for s in services if not served(s, rovers)]:
        print(f"[up] {service} not started: no rover needs it ({service} serves only rovers "
              f"with a {service} section)", flush=True)
        services.remove(service)
    bridges = default_bridges(len(rovers)) if args.bridges is None else args.bridges
    if bridges < 1:
        print(f"--bridges: expected 1 or more, got {bridges}", file=sys.stderr)
        return 2
    bridge_config = None
    if args.bridge_config is not None:
        bridge_config = os.path.abspath(args.bridge_config)
        if not os.path.isfile(bridge_config):
            print(f"--bridge-config: no such file {args.bridge_config}", file=sys.stderr)
            return 2
    expected = {r.id: sum(1 for s in services if served(s, [r])) for r in rovers}
    listen = args.listen or [DEFAULT_ENDPOINT]
    try:  # before anything starts: an address in use is said now, with what holds it
        _check_addresses(args.console, listen)
    except ToolError as exc:
        print(f"lunaris up: {exc}", file=sys.stderr)
        return 1  # as a port in use always was (the router's Zenoh error)
    temp_state = args.state_dir is None
    state_dir = Path(tempfile.mkdtemp(prefix="lunaris-")) if temp_state else Path(args.state_dir)
    state_dir.mkdir(parents=True, exist_ok=True)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    router = zenoh.open(make_config("router", listen=listen))
    print(f"[up] router listening on {', '.join(listen)}; rovers: "
          f"{', '.join(r.id for r in rovers)}; state in {state_dir}", flush=True)
    sup = Supervisor(services, [os.path.abspath(f) for f in rover_files], listen[0], state_dir,
                     args.seed, bridge_config, bridges)
    if args.console:
        console = ["console", "--http", args.console, "--connect", listen[0]]
        for f in rover_files:  # which radios follow the drive, their sites and footprints
            console += ["--rover", os.path.abspath(f)]
        if args.console_accounts:
            console += ["--accounts", args.console_accounts]
        recordings = os.path.abspath(args.recordings)
        console += ["--recordings", recordings]
        sup.add("console", console)
        who = ("sign-in with the accounts of " + args.console_accounts if args.console_accounts
               else "this computer only; you are the instructor")
        print(f"[up] instructor console: http://{args.console}/  ({who}; recordings in "
              f"{recordings}; its log: {sup.log_path('console')})", flush=True)
    status = _Status(router, [r.id for r in rovers])
    tty = sys.stdout.isatty() and not args.no_status
    try:
        sup.start_all()
        # Not on a terminal: a first report once the services are up, then every 10 s.
        last_print = time.monotonic() - 7.0
        shown = 0
        while not stop.wait(0.2):
            sup.poll()
            now = time.monotonic()
            if args.no_status:
                continue
            if tty and now - last_print >= 1.0:
                lines = status.lines(expected, sup.failed)
                if shown:
                    sys.stdout.write(f"\x1b[{shown}F")
                sys.stdout.write("".join(f"\x1b[2K{line}\n" for line in lines))
                sys.stdout.flush()
                shown, last_print = len(lines), now
            elif not tty and now - last_print >= 10.0:
                print("\n".join(status.lines(expected, sup.failed)), flush=True)
                last_print = now
    finally:
        print("[up] stopping ...", flush=True)
        sup.stop_all()
        router.close()
        if temp_state:
            shutil.rmtree(state_dir, ignore_errors=True)
        print("[up] stopped", flush=True)
    return 0
