"""Words a person reads: what the CLI, the console's answers and the page must not show (issue
26.9). :func:`unplain` lists what in a text is not in plain words:

- a traceback, or the name of a Python exception;
- a JSON path (``$.fraction``, `` `$` ``), a validator's or a parser's jargon (``Expected
  `float```, ``Expecting value``, ``line 1 column 5 (char 4)``);
- a Python repr: bytes (``b'5'``), escapes of bytes that are not text (``\\xff``,
  ``'\\udcff``), an object's (``<... object at 0x...>``), ``NoneType``, a Python type named as
  what was given (``got int``, ``got str``);
- raw JSON of the tool's own: an object or a list written as JSON, unless it is what the user
  gave, quoted back to them.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

__all__ = ["unplain"]

_JARGON = [
    (re.compile(r"Traceback \(most recent call last\)|^\s*File \"", re.M), "a traceback"),
    (re.compile(r"\b\w*(Error|Exception)\b(?!s)(?=:|\(|$| \()"), "the name of a Python exception"),
    (re.compile(r"\$\.\w|`\$"), "a JSON path"),
    (re.compile(r"Expected `|`(float|int|str|bool|object|array|null|bytes)`"), "a validator's types"),
    (re.compile(r"Expecting |line \d+ column \d+|\(char \d+\)"), "the JSON parser's jargon"),
    (re.compile(r"(?<![\w])b'[^']*'|(?<![\w])b\"[^\"]*\""), "a Python bytes repr"),
    (re.compile(r"\\x[0-9a-fA-F]{2}|'\\udc[89a-fA-F][0-9a-fA-F]"), "escaped bytes"),
    (re.compile(r"<[\w.]+ object at 0x|NoneType"), "a Python object"),
    (re.compile(r"\bgot (int|str|float|list|dict|bool|bytes|tuple)\b"), "a Python type as what was given"),
]
_JSON = re.compile(r"[{\[]\s*\"|\"\w+\"\s*:")


def unplain(text: str, given: Iterable[str] = ()) -> list[str]:
    """What in ``text`` is not in plain words (empty: all of it is). ``given``: what the user
    typed, which may be quoted back as it was (JSON included)."""
    found = [what for pattern, what in _JARGON if pattern.search(text)]
    bare = text
    for g in sorted((g for g in given if g), key=len, reverse=True):
        bare = bare.replace(g, "...").replace(g[:40], "...")
    if _JSON.search(bare):
        found.append("raw JSON")
    return found
