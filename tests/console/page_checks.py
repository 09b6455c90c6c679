"""What every view of the console must be, checked in the browser (issue 26).

- Layout: every control (``button``, ``input``, ``select``, ``[data-action]``) lies inside the
  viewport's width and inside every box around it that clips (a card that would scroll
  sideways hides it); nothing is wider than its card or sticks out of it; the page itself
  never scrolls sideways. Vertically a control may be anywhere the page, or the box it is in,
  scrolls to. What is inside a drawing (an ``<svg>``, the map) is clipped by it: the drawing is
  checked, not its shapes.
- Touch: on a tablet every control is at least ``TOUCH_PX`` high and wide (its label, for a
  checkbox).
- Words: the visible text holds no raw JSON object, no ``$.field`` path, no Python repr or
  traceback, and none of the twin's snake_case field names.
"""

from __future__ import annotations

import re
from pathlib import Path

import msgspec

from common import keys
from common.faults import CATALOGUE

TOUCH_PX = 40

SCRIPT = (Path(__file__).parent / "page_checks.js").read_text()
LAYOUT = f"{SCRIPT}\nreturn layout();"
TOUCH = f"{SCRIPT}\nreturn touch(arguments[0]);"
COVERED = f"{SCRIPT}\nreturn covered();"
TEXT = "return document.body.innerText;"


def field_names() -> set[str]:
    """The twin's payload field names and fault parameters that a person would not write
    (those with an underscore: ``heat_w``, ``time_to_empty_s``)."""
    names: set[str] = set()
    for family in keys.FAMILIES:
        typ = getattr(family, "payload", None) or getattr(family, "type", None)
        if typ is None:
            continue
        try:
            info = msgspec.inspect.type_info(typ)
        except (TypeError, ValueError):
            continue
        names |= {f.name for f in getattr(info, "fields", ())}
    for kinds in CATALOGUE.values():
        for spec in kinds.values():
            names |= {f.name for f in msgspec.structs.fields(spec.params)} if spec.params else set()
    return {n for n in names if "_" in n}


WORDS = [
    (re.compile(r"\{\s*\"[^\"\n]*\"\s*:"), "a raw JSON object"),
    (re.compile(r"\$\.\w"), "a $.field path"),
    (re.compile(r"\bb'[^'\n]*'|\bb\"[^\"\n]*\""), "a Python bytes repr"),
    (re.compile(r"Traceback|\bFile \"[^\"]+\", line \d+"), "a Python traceback"),
    (re.compile(r"\bNone\b|\bTrue\b|\bFalse\b"), "a Python value"),
    (re.compile(r"Ctrl-C|\(exit \d+\)|^\[t\+|\w/\*|\blunaris\.[A-Z]\w+", re.M), "raw command-line output"),
    # (a session's id, 20261125-205727, is a name the instructor types, not a number)
    (re.compile(r"\^\d|\b\d{7,}\b(?!-\d{6}\b)"), "a formula or a number too long to read"),
]
UNIT = re.compile(r"_(w|v|a|s|m|c|j|deg|ohm|n|nm|hz)$")


def vocabulary(text: str, fields: set[str]) -> list[str]:
    """What a person should not read in ``text``: each problem with the words around it. A
    field name counts as written (``heat_w``) and with its underscores as spaces where it ends
    in a unit (``heat w``)."""
    out = []
    for pattern, what in WORDS:
        for m in pattern.finditer(text):
            out.append(f"{what}: ...{text[max(0, m.start() - 40):m.end() + 40]!r}...")
    for name in sorted(fields):
        forms = [name] + ([name.replace("_", " ")] if UNIT.search(name) else [])
        for form in forms:
            for m in re.finditer(rf"(?<![\w/.-]){re.escape(form)}(?![\w/-])", text):
                out.append(f"the field name {name!r}: ...{text[max(0, m.start() - 40):m.end() + 40]!r}...")
    return out
