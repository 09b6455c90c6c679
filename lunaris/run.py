"""``lunaris run SERVICE --rover FILE``: one service, as a container runs it.

``--shard K/N`` splits a fleet over N processes of one service: this one serves the K-th
rover of the list, the (K+N)-th, and so on (the bridge shares a large fleet so). The bridge
still knows the whole fleet: each rover keeps its own ROS 2 domain and topic names whichever
process serves it.

A service module (``services/<name>/service.py``) holds a node, ``NODE``: a
:class:`common.node.Node` class, made with the rovers it serves and attached to the runtime,
which declares its ports. (The bridge still defines ``serve(rt, rovers, ...)``: it reads its
mapping file, then a class of its own, :class:`services.bridge.service.Bridge`, declares its
ports on the runtime.)

A node's ``serves(rover)`` (or a module's ``serves``) leaves out the rovers a service has
nothing to do for (the drive serves only rovers with a ``drive`` section). When that leaves
no rover, the service says so and exits 0 at once: ``lunaris up`` does not start it then,
and a container of it stops cleanly instead of serving nothing.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from common.config import ConfigError, Rover, load_rover
from common.connection import add_connection_args, config_from_args
from common.runtime import AlreadyRunning, Runtime
from lunaris.supervised import SUPERVISOR_ENV, supervisor

__all__ = ["ALREADY_RUNNING", "CONFIG_ERROR", "SERVICES", "SUPERVISOR_ENV", "add_arguments",
           "load_rovers", "main", "parse_shard", "served"]

CONFIG_ERROR = 2  # exit status: a rover file, mapping or option that cannot work (do not retry)
ALREADY_RUNNING = 3  # exit status: another instance serves these rovers (do not retry)
STARTS_ENV = "LUNARIS_COUNT_STARTS"  # a file each service's start adds a line to (make test counts)

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("service", choices=SERVICES)
    p.add_argument("--rover", action="append", required=True, metavar="FILE",
                   help="rover definition (repeat for a fleet)")
    p.add_argument("--state-dir", metavar="DIR", help="where persisted state is kept")
    p.add_argument("--seed", type=int, default=None, help="random seed (loads)")
    p.add_argument("--bridge-config", metavar="FILE", default=None,
                   help="bridge mapping (bridge service only)")
    p.add_argument("--shard", metavar="K/N", default=None,
                   help="serve only every N-th rover of the list from the K-th (1 <= K <= N): "
                        "a fleet shared by N processes of the service")
    add_connection_args(p)


def load_rovers(paths: list[str]) -> list[Rover]:
    """Load every rover file; print every problem of every file and exit 2 if any."""
    rovers, failed = [], False
    for path in paths:
        try:
            rovers.append(load_rover(path))
        except ConfigError as exc:
            print(exc, file=sys.stderr)
            failed = True
    ids = [r.id for r in rovers]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        print(f"rover id used by more than one file: {', '.join(dup)}", file=sys.stderr)
        failed = True
    if failed:
        raise SystemExit(CONFIG_ERROR)
    return rovers


def served(service: str, rovers: list[Rover]) -> list[Rover]:
    """The rovers a service has something to do for (see the module's docstring)."""
    module = importlib.import_module(f"services.{service}.service")
    node = getattr(module, "NODE", None)
    serves = node.serves if node is not None else getattr(module, "serves", None)
    return [r for r in rovers if serves is None or serves(r)]


def parse_shard(text: str | None) -> tuple[int, int]:
    """``"2/4"`` -> (2, 4); ValueError naming the problem."""
    if text is None:
        return 1, 1
    k, sep, n = text.partition("/")
    if not (sep and k.isdigit() and n.isdigit() and 1 <= int(k) <= int(n)):
        raise ValueError(f"--shard: expected K/N with 1 <= K <= N, got {text!r}")
    return int(k), int(n)


def _count_start(service: str) -> None:
    """One line in :data:`STARTS_ENV`'s file, if it names one (``make test`` prints the count):
    the service and the test that started it (pytest's ``PYTEST_CURRENT_TEST``, inherited)."""
    path = os.environ.get(STARTS_ENV)
    if path:
        test = os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0]
        with open(path, "a", encoding="utf-8") as f:  # one short append: whole lines, any writers
            f.write(f"{service} {test}\n")


def main(args: argparse.Namespace) -> int:
    try:
        k, n = parse_shard(args.shard)
    except ValueError as exc:
        print(f"lunaris run: {exc}", file=sys.stderr)
        return CONFIG_ERROR
    fleet = load_rovers(args.rover)
    rovers = served(args.service, fleet[k - 1::n])
    module = importlib.import_module(f"services.{args.service}.service")
    _count_start(args.service)
    if not rovers:
        print(f"lunaris {args.service}: no rover to serve (none of {', '.join(args.rover)} "
              f"{'in shard ' + args.shard + ' ' if args.shard else ''}needs it); exiting",
              flush=True)
        return 0
    options: dict[str, object] = {"seed": args.seed}
    if args.service == "bridge":
        options["mapping_file"] = args.bridge_config
        options["fleet"] = [r.id for r in fleet]
    state_dir = args.state_dir
    if state_dir is not None and n > 1:  # each shard its own lock and state
        state_dir = os.path.join(state_dir, f"{args.service}-{k}of{n}")
    with Runtime(args.service, [r.id for r in rovers], config_from_args(args), state_dir) as rt:
        try:
            rt.claim()
        except AlreadyRunning as exc:
            print(f"lunaris {args.service}: not starting: {exc}", file=sys.stderr, flush=True)
            return ALREADY_RUNNING
        parent = supervisor()  # started by `lunaris up`: the kernel's signal, and this watch
        if parent is not None:
            rt.watch_parent(parent)
        node = getattr(module, "NODE", None)
        if node is not None:
            node(rovers, seed=args.seed).attach(rt)
        else:
            module.serve(rt, rovers, **options)
        print(f"lunaris {args.service}: serving {', '.join(r.id for r in rovers)}", flush=True)
        rt.run()
    return 0
