"""``lunaris clock ROVER pause|resume|scale X``: pause, resume or speed up simulated time.

Puts ``lunaris/<rover>/clock/control`` and prints the twin's answer: the ``clock`` event
saying whether it runs and at what speed, or the rejection. Exit status as ``lunaris fault``.
"""

from __future__ import annotations

import argparse
import math

import msgspec

from lunaris.client import ToolError, shown
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["add_arguments", "main", "payload"]


ACTIONS = ("pause", "resume", "scale")


def _action(text: str) -> str:
    if text not in ACTIONS:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not an action: give pause, resume or scale X")
    return text


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("action", type=_action, metavar="ACTION",
                   help="pause, resume, or scale X: simulated seconds per wall second")
    p.add_argument("factor", nargs="?", metavar="X", help="with scale: the speed (> 0)")
    add_common_arguments(p)


def payload(action: str, factor: str | float | None) -> bytes:
    """The ``clock/control`` payload of an action (checked when the write is planned)."""
    if action == "scale":
        if factor is None:
            raise ToolError("scale needs a factor: lunaris clock ROVER scale 10", 1)
        try:
            speed = float(factor)
        except ValueError:
            speed = math.nan
        if not math.isfinite(speed):
            raise ToolError(f"the speed must be a number above 0, simulated seconds per second (got "
                            f"{shown(str(factor))}), e.g. lunaris clock ROVER scale 10", 1)
        body = msgspec.json.encode({"time_scale": speed})
    elif factor is not None:
        raise ToolError(f"{action} takes no factor", 1)
    else:
        body = msgspec.json.encode({"paused": action == "pause"})
    return body


def main(args: argparse.Namespace) -> int:
    return tool_main("clock", lambda a: confirm(a, "clock", plan(a.rover, "clock/control",
                                                                 payload(a.action, a.factor))), args)
