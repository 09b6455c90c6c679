"""``lunaris rail ROVER RAIL on|off|reset``: switch a rail, or reset it after a trip.

Puts ``lunaris/<rover>/cmd/rail/<rail>`` and prints the twin's answer: the ``command`` event
with the rail's new state, or the rejection (an unknown rail, the solar rail ...). Exit
status as ``lunaris fault``: 0 accepted, 1 rejected, 2 not applied.
"""

from __future__ import annotations

import argparse

import msgspec

from common.messages import RailCommand
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
    add_common_arguments(p)


def main(args: argparse.Namespace) -> int:
    body = msgspec.json.encode(COMMANDS[args.action])
    return tool_main("rail", lambda a: confirm(a, "rail", plan(a.rover, f"cmd/rail/{a.rail}", body)),
                     args)
