"""``lunaris pdm [--rover ID]``: the PDM device distribution as the crew's dashboard shows it.

One line per value - its dashboard name, the integer value and its unit (mV, mA, mW) - for
the system bus voltage, the battery's voltage, current and power, and each rail's voltage,
current, power and current limit. The values are the twin's, converted by the same mapping
the bridge publishes (the mappings of ``group: pdm`` in ``config/bridge/default.yaml`` or
``--mapping``): the same scale, the same rounding, the same names.

The subscriptions are advanced subscribers with history, so the values appear at once when
the tool joins a running session. ``--once`` prints one table when the values have arrived;
otherwise the table is reprinted every ``--interval`` seconds until Ctrl-C.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.config import ConfigError
from common.connection import add_connection_args
from common.messages import Clock, decode
from lunaris.client import ToolError, live_rovers, open_session
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
    """The latest twin payloads of one rover and the component names seen so far."""

    def __init__(self, mf: MappingFile, rover: str):
        self.mf, self.rover = mf, rover
        self.latest: dict[str, msgspec.Struct] = {}
        self.names: dict[str, list[str]] = {p: [] for p in PLACEHOLDERS}
        self.t_s: float | None = None
        self.changed_at = time.monotonic()
        self._lock = threading.Lock()
        self._families: list[keys.Family] = []
        for m in mf.mappings:
            found = keys.family_of_template(m.key)
            if found is not None and found[0] not in self._families:
                self._families.append(found[0])

    def patterns(self) -> list[str]:
        return sorted({fam.pattern(self.rover) for fam in self._families} | {keys.clock(self.rover)})

    def on_sample(self, s: zenoh.Sample) -> None:
        key = str(s.key_expr)
        rover, parts = keys.split(key)
        payload = s.payload.to_bytes()
        if parts == ["clock"]:
            self.t_s = decode(payload, Clock).t_s
            return
        fam = next((f for f in self._families if f.matches(parts)), None)
        if fam is None:
            return
        with self._lock:
            if key not in self.latest:
                self.changed_at = time.monotonic()
            self.latest[key] = decode(payload, fam.payload)
            if fam.placeholder is not None:
                name = parts[fam.chunks.index(f"{{{fam.placeholder}}}")]
                if name not in self.names[fam.placeholder]:
                    self.names[fam.placeholder].append(name)

    def bindings(self) -> list[Binding]:
        n = self.names
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
        with self._lock:
            groups: dict[str | None, list[Binding]] = {None: []}
            for b in self.bindings():
                groups.setdefault(b.item, []).append(b)
            out = []
            for b in (b for group in groups.values() for b in group):
                payload = self.latest.get(b.key)
                value = out_value(b.mapping, payload) if payload is not None else None
                out.append((b.label, value, b.mapping.unit or ""))
            return out

    def complete(self) -> bool:
        """Every value that needs no component name has arrived, and some rail has."""
        with self._lock:
            bindings = self.bindings()
            return bool(bindings) and all(b.key in self.latest for b in bindings) and (
                bool(self.names["rail"]) or not any("{rail}" in m.key for m in self.mf.mappings))


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
    keep: list[Any] = []
    try:
        rover = args.rover or _first_rover(session, args.timeout)
        if rover is None:
            print("lunaris pdm: no live rover (is the twin running?)", file=sys.stderr)
            return 1
        view = PdmView(mf, rover)
        history = zext.HistoryConfig(detect_late_publishers=True)
        for pattern in view.patterns():
            keep.append(zext.declare_advanced_subscriber(session, pattern, view.on_sample,
                                                         history=history))
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
        keep.clear()
        session.close()


def _first_rover(session: zenoh.Session, timeout_s: float) -> str | None:
    deadline = time.monotonic() + timeout_s
    while True:
        live = live_rovers(session)
        if live:
            return sorted(live)[0]
        if time.monotonic() > deadline:
            return None
        time.sleep(0.2)
