"""``lunaris pdm [--rover ID]``: the PDM device distribution as the crew's dashboard shows it.

One line per value - its dashboard name, the integer value and its unit (mV, mA, mW) - for
the system bus voltage, the battery's voltage, current and power, and each rail's voltage,
current, power and current limit. The values are the twin's, converted by the same mapping
the bridge publishes (the mappings of ``group: pdm`` in ``config/bridge/default.yaml`` or
``--mapping``): the same scale, the same rounding, the same names.

The values are the client's mirror of the rover (:class:`lunaris.client.Mirror`): they appear
at once when the tool joins a running session. ``--once`` prints one table when the values have arrived;
otherwise the table is reprinted every ``--interval`` seconds until Ctrl-C.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import msgspec
import zenoh

from common import keys
from common.config import ConfigError
from common.connection import add_connection_args
from lunaris.client import START_HINT, Change, Mirror, ToolError, close_session, live_rovers, open_session
from services.bridge.bindings import Binding, RoverNames, expand
from services.bridge.convert import out_value
from services.bridge.mapping import PLACEHOLDERS, MappingFile, load_mapping
from services.bridge.service import resolve_mapping

__all__ = ["PdmView", "add_arguments", "main", "pdm_mappings", "render"]

SETTLE_S = 0.3  # --once: the table is printed once no new key has come for this long


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rover", metavar="ID", help="rover to show (default: the first live one)")
    p.add_argument("--mapping", metavar="FILE", default=None,
                   help="bridge mapping file (default config/bridge/default.yaml)")
    p.add_argument("--once", action="store_true", help="print the values once, then exit")
    p.add_argument("--interval", type=float, default=1.0, metavar="S",
                   help="seconds between tables (default 1)")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="how long to wait for the router and the values (default 10 s)")
    add_connection_args(p)


def pdm_mappings(mf: MappingFile) -> MappingFile:
    """The mapping reduced to the PDM device distribution (``group: pdm``, outbound values)."""
    return msgspec.structs.replace(mf, mappings=[
        m for m in mf.mappings if m.group == "pdm" and m.direction == "out" and m.convert is None])


class PdmView:
    """One rover's PDM values as the mapping shows them, read off the client's mirror."""

    def __init__(self, mf: MappingFile, rover: str):
        self.mf, self.rover = mf, rover
        self.changed_at = time.monotonic()
        self._families: list[keys.Family] = []
        for m in mf.mappings:
            found = keys.family_of_template(m.key)
            if found is not None and found[0] not in self._families:
                self._families.append(found[0])
        self.mirror = Mirror(rover, families=[f.name for f in self._families], events=False)
        self._seen: set[str] = set()
        self.mirror.listen(self._on_change)

    def _on_change(self, change: Change) -> None:
        if change.kind == "value" and change.key not in self._seen:
            self._seen.add(change.key)
            self.changed_at = time.monotonic()  # a key not seen before: the table grows

    @property
    def t_s(self) -> float | None:
        clock = self.mirror.value(keys.clock(self.rover))
        return None if clock is None else clock.t_s

    def names(self) -> dict[str, list[str]]:
        """The component names seen so far, per placeholder, in the order they came."""
        out: dict[str, list[str]] = {p: [] for p in PLACEHOLDERS}
        for key in self.mirror.latest(self.rover):
            _, parts = keys.split(key)
            fam = next((f for f in self._families if f.matches(parts)), None)
            if fam is not None and fam.placeholder is not None:
                name = parts[fam.chunks.index(f"{{{fam.placeholder}}}")]
                if name not in out[fam.placeholder]:
                    out[fam.placeholder].append(name)
        return out

    def bindings(self) -> list[Binding]:
        n = self.names()
        names = RoverNames(self.rover, load=tuple(n["load"]), rail=tuple(n["rail"]),
                           radio=tuple(n["radio"]), panel=tuple(n["panel"]))
        try:
            return expand(self.mf, [names])
        except ConfigError:  # a mapping naming a component this rover lacks: show the rest
            return [b for m in self.mf.mappings for b in _expand_one(self.mf, m, names)]

    def lines(self) -> list[tuple[str, Any, str]]:
        """(label, value or None, unit) for every value of the distribution: the values of
        the rover first, then each component's values together (a rail's voltage, current,
        power and current limit), in the mapping's order."""
        groups: dict[str | None, list[Binding]] = {None: []}
        for b in self.bindings():
            groups.setdefault(b.item, []).append(b)
        out = []
        for b in (b for group in groups.values() for b in group):
            payload = self.mirror.value(b.key)
            value = out_value(b.mapping, payload) if payload is not None else None
            out.append((b.label, value, b.mapping.unit or ""))
        return out

    def complete(self) -> bool:
        """Every value that needs no component name has arrived, and some rail has."""
        bindings = self.bindings()
        return bool(bindings) and all(self.mirror.get(b.key) is not None for b in bindings) and (
            bool(self.names()["rail"]) or not any("{rail}" in m.key for m in self.mf.mappings))


def _expand_one(mf: MappingFile, m: Any, names: RoverNames) -> list[Binding]:
    try:
        return expand(msgspec.structs.replace(mf, mappings=[m]), [names])
    except ConfigError:
        return []


def render(rover: str, lines: list[tuple[str, Any, str]], t_s: float | None = None) -> str:
    """The table: a title, then ``name  value unit`` per line, values right-aligned."""
    when = f" at t = {t_s:.1f} s" if t_s is not None else ""
    width = max((len(label) for label, _, _ in lines), default=0)
    out = [f"PDM device distribution - {rover}{when}"]
    for label, value, unit in lines:
        text = "-" if value is None else (f"{value:d}" if isinstance(value, int) else f"{value:.3f}")
        out.append(f"  {label:<{width}}  {text:>10} {unit}".rstrip())
    return "\n".join(out)


def main(args: argparse.Namespace) -> int:
    try:
        mf = pdm_mappings(load_mapping(resolve_mapping(args.mapping)))
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    if not mf.mappings:
        print("lunaris pdm: the mapping has no values of group pdm", file=sys.stderr)
        return 2
    try:
        session = open_session(args, wait_s=args.timeout)
    except ToolError as exc:
        print(f"lunaris pdm: {exc}", file=sys.stderr)
        return exc.code
    view: PdmView | None = None
    try:
        rover = args.rover or _first_rover(session, args.timeout)
        if rover is None:
            print(f"lunaris pdm: no live rover (is the twin running? {START_HINT})", file=sys.stderr)
            return 1
        view = PdmView(mf, rover)
        view.mirror.start(session)
        if args.once:
            deadline = time.monotonic() + args.timeout
            while time.monotonic() < deadline and not (
                    view.complete() and time.monotonic() - view.changed_at > SETTLE_S):
                time.sleep(0.05)
            print(render(rover, view.lines(), view.t_s), flush=True)
            return 0 if view.complete() else 1
        while True:
            print(render(rover, view.lines(), view.t_s) + "\n", flush=True)
            time.sleep(args.interval)
    except KeyboardInterrupt:
        return 0
    finally:
        if view is not None:
            view.mirror.close()
        close_session(session)


def _first_rover(session: zenoh.Session, timeout_s: float) -> str | None:
    deadline = time.monotonic() + timeout_s
    while True:
        live = live_rovers(session)
        if live:
            return sorted(live)[0]
        if time.monotonic() > deadline:
            return None
        time.sleep(0.2)
