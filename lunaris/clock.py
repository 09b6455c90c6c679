"""``lunaris clock ROVER pause|resume|scale X``: pause, resume or speed up simulated time.

Puts ``lunaris/<rover>/clock/control`` and prints the twin's answer: the ``clock`` event
saying whether it runs and at what speed, or the rejection. Exit status as ``lunaris fault``.
"""

from __future__ import annotations

import argparse

import msgspec

from lunaris.client import ToolError
from lunaris.confirm import add_common_arguments, confirm, plan, tool_main

__all__ = ["add_arguments", "main", "payload"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("rover", help="rover id, e.g. mapp-1")
    p.add_argument("action", choices=("pause", "resume", "scale"),
                   help="pause, resume, or scale X: simulated seconds per wall second")
    p.add_argument("factor", nargs="?", type=float, metavar="X", help="with scale: the speed (> 0)")
    add_common_arguments(p)


def payload(action: str, factor: float | None) -> bytes:
    """The ``clock/control`` payload of an action (checked when the write is planned)."""
    if action == "scale":
        if factor is None:
            raise ToolError("scale needs a factor: lunaris clock ROVER scale 10", 1)
        body = msgspec.json.encode({"time_scale": factor})
    elif factor is not None:
        raise ToolError(f"{action} takes no factor", 1)
    else:
        body = msgspec.json.encode({"paused": action == "pause"})
    return body


def main(args: argparse.Namespace) -> int:
    return tool_main("clock", lambda a: confirm(a, "clock", plan(a.rover, "clock/control",
                                                                 payload(a.action, a.factor))), args)
