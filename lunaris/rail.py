"""``lunaris rail ROVER RAIL on|off|reset``: switch a rail, or reset it after a trip.

Puts ``lunaris/<rover>/cmd/rail/<rail>`` and prints the twin's answer: the ``command`` event
with the rail's new state, or the rejection (an unknown rail, the solar rail ...). Exit
status as ``lunaris fault``: 0 accepted, 1 rejected, 2 not applied. ``--as-crew``: the
instructor standing in for the crew, the command counted as the crew's.
"""

from __future__ import annotations

import argparse

import msgspec

from common.messages import RailCommand
from common.writes import stand_in
from lunaris.client import shown
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["COMMANDS", "add_arguments", "main"]

COMMANDS = {"on": RailCommand(on=True), "off": RailCommand(on=False), "reset": RailCommand(reset=True)}


def _action(text: str) -> str:
    if text not in COMMANDS:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not an action: give on, off or reset")
    return text


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("rail", help="rail name, e.g. 5V_CH2")
    p.add_argument("action", type=_action, metavar="ACTION", help="on, off, or reset (after a trip)")
    p.add_argument("--as-crew", action="store_true",
                   help="the instructor standing in for the crew (a drill run without its "
                        "dashboard): the command counts as the crew's action in its response and "
                        "the debrief")
    add_common_arguments(p)


def main(args: argparse.Namespace) -> int:
    body = msgspec.json.encode(COMMANDS[args.action])

    def run(a: argparse.Namespace) -> int:
        write = plan(a.rover, f"cmd/rail/{a.rail}", body)
        return confirm(a, "rail", stand_in(write) if a.as_crew else write)
    return tool_main("rail", run, args)
