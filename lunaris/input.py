"""``lunaris input ROVER KEY VALUE...``: set an input of the twin without writing Zenoh code.

``KEY`` is the input's key under ``lunaris/<rover>/input/``:

- ``sun_angle 75``: the sun angle of every panel [deg];
- ``solar/<panel>/sun_angle 80``: one panel's own angle (``--delete``: back to the rover's);
- ``solar/<panel>/dust 0.4``: dust laid on one panel, as the dashboard does, besides the
  instructor's dust fault (``--delete``: none);
- ``radio/<radio>/position 300 45``: the rover's distance [m] and angle [deg, counter-clockwise
  from east] to a radio without a ``site``, or on a rover that does not drive. A radio that
  stands at a site on a rover that drives (the shipped MAPP and LTV) follows the drive: the
  twin refuses its position, and the command says how to drive the rover there instead
  (``lunaris traverse ROVER --to X Y Z``, the point worked out from the twin's telemetry);
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
import math
import os
import sys

import msgspec

from common import keys
from common.messages import RadioPosition
from common.traverse import TraverseError, load_traverse
from common.writes import Write
from lunaris.client import Answer, Mirror, Rejected, ToolError, shown
from lunaris.confirm import add_common_arguments, confirm, plan, print_answer, tool_main, writer_for

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


POSITION = ("a radio position is two numbers, the distance [m] and the angle [deg, counter-"
            "clockwise from east]: lunaris input ROVER radio/RADIO/position 300 45")


def _raw(key: str, values: list[str]) -> bytes:
    """The payload the words on the command line stand for, before it is checked (bytes that
    are not text come as the shell passed them: the check says so)."""
    if key == "drive/traverse" and len(values) == 1 and not values[0].lstrip().startswith("{"):
        try:
            return msgspec.json.encode(load_traverse(values[0]).command())
        except TraverseError as exc:
            raise ToolError(f"the traverse file {exc.source} cannot be driven: {'; '.join(exc.problems)}",
                            1) from None
    if key.startswith("radio/") and key.endswith("/position"):
        if len(values) == 2:
            values = [json.dumps({"distance_m": _number(values[0], "the distance"),
                                  "angle_deg": _number(values[1], "the angle")})]
        elif len(values) != 1 or not values[0].lstrip().startswith("{"):
            raise ToolError(POSITION, 1)
    if len(values) != 1:
        raise ToolError(f"give one VALUE for {key} (got {len(values)})", 1)
    return os.fsencode(values[0])


def _number(text: str, what: str) -> float:
    try:
        number = float(text)
    except ValueError:
        raise ToolError(f"{what} must be a number (got {shown(text)}); {POSITION}", 1) from None
    if not math.isfinite(number):
        raise ToolError(f"{what} must be a finite number (got {shown(text)})", 1)
    return number


def payload(rover: str, key: str, values: list[str], delete: bool = False) -> Write:
    """The checked write of ``input/<key>`` (a delete with ``delete``)."""
    if delete and values:
        raise ToolError("--delete takes no VALUE", 1)
    if not delete and not values:
        raise ToolError(f"give a VALUE for {key}, or --delete", 1)
    tail = "input/" + key.strip("/").removeprefix("input/")
    return plan(rover, tail, None if delete else _raw(key, values))


FOLLOWS = "follows the rover's drive"  # the radio service's reason for refusing a position


def follow_hint(answer: Answer, mirror: Mirror) -> str | None:
    """What to do instead when the twin refused a radio position because the radio follows the
    drive: drive the rover to the point that is at the asked distance and angle from the
    radio's site. The site is where the rover is less its offset from the radio (``drive/state``
    minus ``radio/<radio>/link``)."""
    if not isinstance(answer, Rejected) or FOLLOWS not in answer.message:
        return None
    rover, radio = answer.write.rover, answer.write.tail.split("/")[2]
    wanted = msgspec.json.decode(answer.write.payload or b"{}", type=RadioPosition)
    drive = mirror.value(keys.drive_state(rover))
    link = mirror.value(keys.radio_link(rover, radio))
    said = (f"the {radio} radio stands at a fixed site and {rover} drives: the rover's distance and "
            f"angle to it come from where the rover is")
    if drive is None or link is None:
        return (f"{said}. Move the rover instead: lunaris traverse {rover} --to X Y Z (a point of the "
                "site frame, metres east, north, up) or lunaris traverse ROVER FILE")
    site_x, site_y = drive.x_m - link.x_m, drive.y_m - link.y_m
    a = math.radians(wanted.angle_deg)
    x, y = site_x + wanted.distance_m * math.cos(a), site_y + wanted.distance_m * math.sin(a)
    now_d, now_a = math.hypot(link.x_m, link.y_m), math.degrees(math.atan2(link.y_m, link.x_m))
    return (f"{said} (now {now_d:.0f} m at {now_a:.0f} deg). To put it {wanted.distance_m:g} m from "
            f"{radio} at {wanted.angle_deg:g} deg (counter-clockwise from east), drive it there: "
            f"lunaris traverse {rover} --to {x:.1f} {y:.1f} {drive.z_m:.1f}")


def _send(args: argparse.Namespace) -> int:
    write = payload(args.rover, args.key, args.value, args.delete)
    parts = write.tail.split("/")
    if len(parts) != 4 or parts[1] != "radio" or write.payload is None:
        return confirm(args, "input", write)
    with writer_for(args, write.rover, families=("drive/state", "radio/*/link")) as writer:
        answer = writer.write(write)
        hint = follow_hint(answer, writer.mirror)
    code = print_answer("input", answer, args.json)
    if hint is not None and not args.json:
        print(f"  {hint}", file=sys.stderr)
    return code


def main(args: argparse.Namespace) -> int:
    return tool_main("input", _send, args)
