"""The ``lunaris`` command line (SPEC §8).

Each command is a module of this package with ``add_arguments(parser)`` and
``main(args) -> int``; they are imported only when used, so ``lunaris watch`` does not pay for
the services. A command whose reader goes away (``lunaris pdm | head``) ends quietly.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys

import zenoh

from common.connection import ConnectionConfigError
from lunaris.processes import quiet_stdout
from lunaris.supervised import follow_supervisor

__all__ = ["COMMANDS", "main"]

# command -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "up": ("lunaris.up", "embedded router + every service for the given rovers, supervised"),
    "router": ("lunaris.router", "a standalone embedded Zenoh router"),
    "run": ("lunaris.run", "run one service (what a container runs)"),
    "check": ("lunaris.check", "validate rover definitions and print every problem"),
    "sim": ("lunaris.sim", "accelerated power-budget run of the models in one process"),
    "watch": ("lunaris.watch", "live terminal view of a rover or the fleet"),
    "pdm": ("lunaris.pdm", "print the PDM device distribution as the dashboard shows it"),
    "fault": ("lunaris.fault", "inject, clear and list faults"),
    "record": ("lunaris.record", "record every lunaris key to an MCAP file"),
    "report": ("lunaris.report", "draw a recorded session for the debrief"),
    "scenario": ("lunaris.scenario", "play a scripted training scenario"),
    "deploy": ("lunaris.deploy", "a deployment's router access control, secrets and their check"),
    "traverse": ("lunaris.traverse", "send a rover on a traverse, or stop it"),
    "predict": ("lunaris.predict", "Monte Carlo time to empty and state of charge, from a file or "
                "the live twin"),
    "rail": ("lunaris.rail", "switch a rail on or off, or reset it after a trip"),
    "clock": ("lunaris.clock", "pause, resume or speed up a rover's simulated time"),
    "input": ("lunaris.input", "set an input: sun angle, radio position, umbilical, traverse"),
    "reset": ("lunaris.reset", "put a rover back to its rover file's initial conditions"),
    "snapshot": ("lunaris.snapshot", "save, restore and list snapshots of a rover's session"),
    "session": ("lunaris.session", "begin a trainee's session (the twin reset or a snapshot), or "
                "list the sessions"),
    "mark": ("lunaris.mark", "mark the session's timeline with a note"),
    "console": ("lunaris.console", "the instructor console in a web browser"),
}


def main(argv: list[str] | None = None) -> int:
    follow_supervisor()  # first: started by `lunaris up`, die with it (lunaris.supervised)
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = argparse.ArgumentParser(
        prog="lunaris", description="Lunaris: digital twin of a lunar rover's power and radio.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = argv[0] if argv and argv[0] in COMMANDS else None
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == chosen:  # only the chosen command's module is imported
            importlib.import_module(module).add_arguments(p)
    try:
        args = parser.parse_args(argv)
    except BrokenPipeError:  # the help, read by a reader that went
        quiet_stdout()
        return 0
    try:
        return int(importlib.import_module(COMMANDS[args.command][0]).main(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader of our output has gone (| head): nothing more to say
        quiet_stdout()
        return 0
    except (zenoh.ZError, ConnectionConfigError) as exc:  # a port in use, a bad endpoint or file
        print(f"lunaris {args.command}: {_zenoh_message(exc)}", file=sys.stderr)
        return 1



def _zenoh_message(exc: Exception) -> str:
    """Zenoh's error without the Rust source locations it carries."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc)).strip()


if __name__ == "__main__":
    sys.exit(main())
