"""``lunaris rail ROVER RAIL on|off|reset``: switch a rail, or reset it after a trip.

Puts ``lunaris/<rover>/cmd/rail/<rail>`` and prints the twin's answer: the ``command`` event
with the rail's new state, or the rejection (an unknown rail, the solar rail ...). Exit
status as ``lunaris fault``: 0 accepted, 1 rejected, 2 not applied.
"""

from __future__ import annotations

import argparse

import msgspec

from common.messages import RailCommand
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["COMMANDS", "add_arguments", "main"]

COMMANDS = {"on": RailCommand(on=True), "off": RailCommand(on=False), "reset": RailCommand(reset=True)}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("rail", help="rail name, e.g. 5V_CH2")
    p.add_argument("action", choices=sorted(COMMANDS), help="switch it on or off, or reset a trip")
    add_common_arguments(p)


def main(args: argparse.Namespace) -> int:
    body = msgspec.json.encode(COMMANDS[args.action])
    return tool_main("rail", lambda a: confirm(a, "rail", plan(a.rover, f"cmd/rail/{a.rail}", body)),
                     args)
