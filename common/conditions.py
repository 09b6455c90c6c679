"""The condition language of scenarios (and of anything else that watches the twin).

``<source>.<field> <op> <value>`` joined by ``and``; ``op`` is one of
``< <= > >= == !=``; ``value`` a number, ``true``/``false``, or a word for text fields
(``rail.12V.state == tripped``). Sources: ``battery``, ``summary``, ``clock``,
``umbilical``, ``drive``, ``rail.<name>``, ``load.<name>``, ``solar.<panel>``, ``radio.<name>``.
Field names and value types are checked against the payload Structs of SPEC §5. No
``eval``: the text is matched against this grammar only.
"""

from __future__ import annotations

import math
import operator
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common import keys
from common.datafile import field_kind, struct_fields

__all__ = ["SOURCES", "Comparison", "Condition", "Lookup", "parse_condition"]

# source -> (key chunks after lunaris/<rover>/ with {name} for a named source, payload Struct)
SOURCES: dict[str, keys.Family] = {
    source: fam for source, fam in (
        (source, keys.family_of(shape.split("/"))) for source, shape in (
            ("battery", "battery/state"),
            ("summary", "power/summary"),
            ("clock", "clock"),
            ("umbilical", "umbilical/state"),
            ("drive", "drive/state"),
            ("rail", "rail/{rail}/state"),
            ("load", "load/{load}/power"),
            ("solar", "solar/{panel}/power"),
            ("radio", "radio/{radio}/link"),
        )
    ) if fam is not None
}
_NAMED = {s for s, fam in SOURCES.items() if fam.placeholder is not None}
_OPS: dict[str, Callable[[Any, Any], bool]] = {
    "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
    "==": operator.eq, "!=": operator.ne,
}
_COMPARISON = re.compile(r"^\s*(?P<ref>[A-Za-z][A-Za-z0-9_.\-]*)\s*(?P<op><=|>=|==|!=|<|>)\s*"
                         r"(?P<value>\S+)\s*$")
_WORD = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

Lookup = Callable[[tuple[str, ...]], dict | None]  # key chunks -> latest payload


@dataclass(frozen=True)
class Comparison:
    source: str
    name: str | None
    field: str
    op: str
    value: float | bool | str

    @property
    def key_parts(self) -> tuple[str, ...]:
        chunks = SOURCES[self.source].chunks
        return tuple(self.name if p.startswith("{") else p for p in chunks) if self.name else chunks

    @property
    def ref(self) -> str:
        return ".".join(p for p in (self.source, self.name, self.field) if p)

    def current(self, lookup: Lookup) -> Any:
        payload = lookup(self.key_parts)
        return None if payload is None else payload.get(self.field)

    def holds(self, lookup: Lookup) -> bool:
        current = self.current(lookup)
        if current is None:  # no telemetry yet, or a null (time to empty while charging)
            return False
        if isinstance(self.value, bool) != isinstance(current, bool):
            return False
        return bool(_OPS[self.op](current, self.value))


@dataclass(frozen=True)
class Condition:
    """``comparison (and comparison)*``: holds when every comparison holds."""

    text: str
    comparisons: tuple[Comparison, ...]

    def holds(self, lookup: Lookup) -> bool:
        return all(c.holds(lookup) for c in self.comparisons)

    def describe(self, lookup: Lookup) -> str:
        """The current values, for progress lines: ``battery.soc = 0.412``."""
        out = []
        for c in self.comparisons:
            v = c.current(lookup)
            out.append(f"{c.ref} = {v:.4g}" if isinstance(v, float) else f"{c.ref} = {v}")
        return ", ".join(out)


def parse_condition(text: str) -> Condition:
    """Parse a condition; raise ValueError saying what is wrong. Field names and value types
    are checked against the payload Structs of SPEC §5."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError("empty condition")
    comparisons = []
    for part in re.split(r"\s+and\s+", text.strip()):
        m = _COMPARISON.match(part)
        if m is None:
            raise ValueError(f"cannot read {part.strip()!r}: expected <source>.<field> <op> <value> "
                             f"with op one of {' '.join(_OPS)}")
        comparisons.append(_comparison(m["ref"], m["op"], m["value"]))
    return Condition(text.strip(), tuple(comparisons))


def _comparison(ref: str, op: str, raw: str) -> Comparison:
    source, _, rest = ref.partition(".")
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r} (sources: {', '.join(sorted(SOURCES))})")
    name: str | None = None
    if source in _NAMED:
        name, _, fld = rest.rpartition(".")  # a name may contain dots; a field never does
        if not name or not fld:
            raise ValueError(f"{source} needs a name and a field: {source}.<name>.<field>")
    else:
        fld = rest
        if not fld or "." in fld:
            raise ValueError(f"{source} has no names: {source}.<field>")
    struct = SOURCES[source].payload
    fields = {f.name: f for f in struct_fields(struct)}
    if fld not in fields:
        raise ValueError(f"unknown field {fld!r} of {source} (fields: {', '.join(fields)})")
    kind, words = field_kind(fields[fld].type)
    value: float | bool | str
    if kind == "number":
        try:
            value = float(raw)
        except ValueError:
            raise ValueError(f"{source}.{fld} is a number; cannot compare it with {raw!r}") from None
        if not math.isfinite(value):
            raise ValueError(f"{raw!r} is not a finite number")
    elif kind == "bool":
        if raw not in ("true", "false"):
            raise ValueError(f"{source}.{fld} is true or false; cannot compare it with {raw!r}")
        value = raw == "true"
    elif kind == "word":
        if not _WORD.match(raw):
            raise ValueError(f"{source}.{fld} is text; compare it with a word, got {raw!r}")
        if words is not None and raw not in words:
            raise ValueError(f"{source}.{fld} is one of {', '.join(words)}; got {raw!r}")
        value = raw
    else:
        raise ValueError(f"{source}.{fld} cannot be compared")
    if kind != "number" and op not in ("==", "!="):
        raise ValueError(f"{source}.{fld} can only be compared with == or !=")
    return Comparison(source, name, fld, op, value)
