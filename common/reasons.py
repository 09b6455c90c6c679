"""Why an input is refused, in words an instructor reads: no ``$.field`` paths, no Python
reprs, no parser jargon.

msgspec and the JSON parser say what is wrong in their own terms (``Expected `float` <= 1.0 -
at `$.fraction```, ``Expecting value: line 1 column 1 (char 0)``). :func:`humane` turns
such a message into plain words, with the value that was given when it is known
(``fraction must be at most 1 (got 30)``); :func:`shown` writes a value as a person would
read it. :mod:`common.messages` builds every rejection of an input with these, so the
events, the command line and the console all say the same.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

__all__ = ["field_name", "humane", "json_error", "number", "shown"]

_LIMIT_WORDS = {"<=": "at most", ">=": "at least", "<": "below", ">": "above"}
_KIND_WORDS = {"float": "a number", "int": "a whole number", "bool": "true or false",
               "str": "text", "array": "a list", "object": "a JSON object", "null": "null",
               "bytes": "text"}
_MAX_SHOWN = 40  # characters of a value quoted back


def number(text: str | float) -> str:
    """``1.0`` -> ``1``, ``10000000.0`` -> ``10000000``, ``0.05`` -> ``0.05``."""
    try:
        value = float(text)
    except ValueError:
        return str(text)
    if math.isfinite(value) and value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:g}"


def shown(value: Any) -> str:
    """A value as a person reads it: ``'thick'``, ``30``, ``true``, ``null``, ``[1, 2]``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, int | float):
        return number(value) if isinstance(value, float) else str(value)
    if isinstance(value, bytes):
        try:
            value = value.decode("utf-8")
        except UnicodeDecodeError:
            return f"{len(value)} bytes that are not text"
    if isinstance(value, str):
        text = value if len(value) <= _MAX_SHOWN else value[:_MAX_SHOWN] + "..."
        return "'" + "".join(c if c.isprintable() else "?" for c in text) + "'"
    try:
        text = json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError):
        text = type(value).__name__
    return text if len(text) <= _MAX_SHOWN else text[:_MAX_SHOWN] + "..."


_PATH_TOKEN = re.compile(r"\.([^.\[\]]+)|\[(\d+)\]")


def _path(path: str) -> list[str | int]:
    """``$.waypoints[0].x_m`` -> ``["waypoints", 0, "x_m"]``."""
    return [name if name else int(index) for name, index in _PATH_TOKEN.findall(path)]


def field_name(tokens: list[str | int]) -> str:
    """``["waypoints", 0, "x_m"]`` -> ``x_m of waypoint 1``; ``["fraction"]`` -> ``fraction``."""
    parts: list[str] = []
    for token in tokens:
        if isinstance(token, int):
            owner = parts.pop() if parts else "item"
            single = owner[:-1] if owner.endswith("s") and len(owner) > 1 else owner
            parts.append(f"{single} {token + 1}")
        else:
            parts.append(token)
    return " of ".join(reversed(parts)) if parts else "the input"


def _lookup(raw: Any, tokens: list[str | int]) -> tuple[bool, Any]:
    for token in tokens:
        if isinstance(token, int) and isinstance(raw, list) and 0 <= token < len(raw):
            raw = raw[token]
        elif isinstance(token, str) and isinstance(raw, dict) and token in raw:
            raw = raw[token]
        else:
            return False, None
    return True, raw


def _kinds(types: str) -> str:
    """``float | null`` -> ``a number``; ``int | str`` -> ``a whole number or text``."""
    words = [_KIND_WORDS.get(t.strip(), t.strip()) for t in types.split("|")
             if t.strip() != "null"] or ["null"]
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


_UNSEEN = object()  # humane's raw when the value the message is about is not at hand


def humane(message: str, raw: Any = _UNSEEN, fields: list[str] | None = None,
           choices: dict[str, list[Any]] | None = None) -> str:
    """A msgspec validation message in plain words.

    ``raw`` is the decoded JSON the message is about (to quote the value given), ``fields``
    the names the input takes (to list them when an unknown one is given), ``choices`` the
    values each field of a fixed set takes. A message already in plain words comes back
    unchanged.
    """
    m = re.fullmatch(r"(.*?) - at `\$(.*)`", message, re.S)
    text, tokens = (m.group(1), _path(m.group(2))) if m else (message, [])
    where = field_name(tokens)
    known, value = _lookup(raw, tokens) if raw is not _UNSEEN else (False, None)
    got = f" (got {shown(value)})" if known else ""

    if mm := re.fullmatch(r"Expected `(\w+)` (<=|>=|<|>) (\S+)", text):
        kind = "a whole number " if mm.group(1) == "int" else ""
        return f"{where} must be {kind}{_LIMIT_WORDS[mm.group(2)]} {number(mm.group(3))}{got}"
    if mm := re.fullmatch(r"Expected `([\w |]+)`, got `(\w+)`", text):
        return f"{where} must be {_kinds(mm.group(1))}{got or ', not ' + _kinds(mm.group(2))}"
    if mm := re.fullmatch(r"Expected `(str|array|object)` of length (<=|>=) (\d+)", text):
        unit = {"str": "characters", "array": "items", "object": "fields"}[mm.group(1)]
        if mm.group(2) == ">=" and mm.group(3) == "1":
            return f"{where} must not be empty"
        return f"{where} must have {_LIMIT_WORDS[mm.group(2)]} {mm.group(3)} {unit}{got}"
    if mm := re.fullmatch(r"Object missing required field `(\w+)`", text):
        inside = f" in {where}" if tokens else ""
        return f"{mm.group(1)} is missing{inside}"
    if mm := re.fullmatch(r"Object contains unknown field `(.*)`", text, re.S):
        inside = f" of {where}" if tokens else " of this input"
        takes = f" (it takes {', '.join(fields)})" if fields and not tokens else ""
        return f"{shown(mm.group(1))} is not a field{inside}{takes}"
    if mm := re.fullmatch(r"Invalid enum value (.*)", text, re.S):
        allowed = (choices or {}).get(where)
        if allowed:
            return (f"{where} must be one of {', '.join(shown(c) for c in allowed)} "
                    f"(got {mm.group(1).strip()})")
        return f"{where} cannot be {mm.group(1).strip()}"
    if mm := re.fullmatch(r"Expected `(\w+)`, got `(\w+)`", text):
        return f"{where} must be {_kinds(mm.group(1))}{got}"
    if m:  # another message about one field: its words, the field named plainly
        return f"{where}: {text.replace('`', '')}{got}"
    return message.replace("`", "")


_JSON_WORDS = [
    ("Expecting value", "a value is missing"),
    ("Expecting property name enclosed in double quotes", "a field name in double quotes is expected"),
    ("Expecting ',' delimiter", "a comma is missing"),
    ("Expecting ':' delimiter", "a colon is missing"),
    ("Unterminated string starting at", "a text in quotes is never closed"),
    ("Extra data", "something follows the value"),
    ("Invalid control character at", "a control character is inside a text"),
    ("Invalid \\uXXXX escape", "a \\u escape is not four hexadecimal digits"),
    ("Invalid \\escape", "a backslash escape is not one JSON knows"),
]
_BARE_WORD = re.compile(r"[^\s{}\[\]\",:]{1,40}")


def json_error(text: str, msg: str, pos: int, bare: bool) -> str:
    """The words for a payload the JSON parser refused (``msg`` at character ``pos``)."""
    stripped = text.strip()
    if _BARE_WORD.fullmatch(stripped):
        wanted = "a number, true/false or a JSON object" if bare else "a JSON object"
        return f"{shown(stripped)} is not {wanted}"
    what = next((words for prefix, words in _JSON_WORDS if msg.startswith(prefix)), msg)
    return f"not valid JSON: {what} at character {pos + 1}"
