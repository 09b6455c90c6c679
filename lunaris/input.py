"""``lunaris input ROVER KEY VALUE...``: set an input of the twin without writing Zenoh code.

``KEY`` is the input's key under ``lunaris/<rover>/input/``:

- ``sun_angle 75``: the sun angle of every panel [deg];
- ``solar/<panel>/sun_angle 80``: one panel's own angle (``--delete``: back to the rover's);
- ``solar/<panel>/dust 0.4``: dust laid on one panel, as the dashboard does, besides the
  instructor's dust fault (``--delete``: none);
- ``radio/<radio>/position 300 45``: the rover's distance [m] and bearing [deg] to a radio;
- ``umbilical true|false``: plug the umbilical in, or out;
- ``drive/traverse FILE`` (a traverse file) or a JSON traverse (``--delete``: stop the rover;
  ``lunaris traverse`` has more options).

A VALUE may also be the JSON object the key takes. The value is checked with the twin's own
Struct before it is sent, then the twin's answer is printed: the ``input`` event, or the
rejection. Exit status as ``lunaris fault``: 0 accepted, 1 rejected, 2 not applied.
"""

from __future__ import annotations

import argparse
import json

import msgspec

from common.traverse import TraverseError, load_traverse
from common.writes import Write
from lunaris.client import ToolError
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["add_arguments", "main", "payload"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("key", help="sun_angle, solar/<panel>/sun_angle, solar/<panel>/dust, "
                               "radio/<radio>/position, umbilical or drive/traverse")
    p.add_argument("value", nargs="*", metavar="VALUE",
                   help="a number, two numbers for a position (distance_m angle_deg), true or "
                        "false, a traverse file, or the JSON object the key takes")
    p.add_argument("--delete", action="store_true",
                   help="delete the input (a panel's own sun angle or dust, a traverse: the rover "
                        "stops)")
    add_common_arguments(p)


def _raw(key: str, values: list[str]) -> bytes:
    """The payload the words on the command line stand for, before it is checked."""
    if key == "drive/traverse" and len(values) == 1 and not values[0].lstrip().startswith("{"):
        try:
            return msgspec.json.encode(load_traverse(values[0]).command())
        except TraverseError as exc:
            raise ToolError(str(exc), 1) from None
    if key.startswith("radio/") and len(values) == 2:
        values = [json.dumps({"distance_m": _number(values[0]), "angle_deg": _number(values[1])})]
    if len(values) != 1:
        raise ToolError(f"give one VALUE for {key} (got {len(values)})", 1)
    return values[0].encode()


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ToolError(f"{text!r} is not a number", 1) from None


def payload(rover: str, key: str, values: list[str], delete: bool = False) -> Write:
    """The checked write of ``input/<key>`` (a delete with ``delete``)."""
    if delete and values:
        raise ToolError("--delete takes no VALUE", 1)
    if not delete and not values:
        raise ToolError(f"give a VALUE for {key}, or --delete", 1)
    tail = "input/" + key.strip("/").removeprefix("input/")
    return plan(rover, tail, None if delete else _raw(key, values))


def main(args: argparse.Namespace) -> int:
    return tool_main("input", lambda a: confirm(a, "input", payload(a.rover, a.key, a.value, a.delete)),
                     args)
