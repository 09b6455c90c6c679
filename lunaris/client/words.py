"""The twin's reasons in words a person uses: ``heat_w must be at least 0.0``, not
``Expected `float` >= 0.0 - at `$.heat_w```.

:func:`humane` is ``common.messages.humane`` (the harden-input branch moves it there); until
that lands, the copy below, which was the console's, stands in for it. Delete the copy once
``common.messages`` has it.
"""

from __future__ import annotations

import re

__all__ = ["humane"]

try:
    from common.messages import humane  # type: ignore[attr-defined, unused-ignore]
except ImportError:  # until common.messages has it (the harden-input branch)

    def humane(message: str) -> str:  # type: ignore[misc, unused-ignore]
        """A validation message in plain words: ``Expected `float` <= 1.0 - at `$.fraction```
        becomes ``fraction must be at most 1.0``."""
        words = {"<=": "at most", ">=": "at least", "<": "below", ">": "above"}
        message = re.sub(r"got b'([^']*)'", r"got \1", message)  # bytes shown as Python writes them
        named = re.match(r"(\w+): (Expected .*)$", message)
        if named and re.search(r"- at `\$`$", message):  # a bare value of a named parameter
            message = named.group(2).replace("- at `$`", f"- at `$.{named.group(1)}`")
        m = re.search(r"Expected `\w+` (<=|>=|<|>) (\S+) - at `\$\.?(\w*)`", message)
        if m:
            field = m.group(3) or "the value"
            return message[:m.start()] + f"{field} must be {words[m.group(1)]} {m.group(2)}"
        m = re.search(r"Expected `(\w+)`, got `(\w+)` - at `\$\.?(\w*)`", message)
        if m:
            kinds = {"float": "a number", "int": "a whole number", "bool": "true or false",
                     "str": "text", "object": "an object", "array": "a list", "null": "null"}
            got = {"int": "a number", "float": "a number"}.get(m.group(2), kinds.get(m.group(2), m.group(2)))
            field = m.group(3) or "the value"
            return message[:m.start()] + f"{field} must be {kinds.get(m.group(1), m.group(1))}, not {got}"
        m = re.search(r"Object missing required field `(\w+)`(?: - at `\$(.*)`)?", message)
        if m:
            return message[:m.start()] + f"{m.group(1)} is missing"
        m = re.search(r"Object contains unknown field `(\w+)`(?: - at `\$(.*)`)?", message)
        if m:
            return message[:m.start()] + f"{m.group(1)} is not a field of this input"
        m = re.search(r"malformed JSON: Expecting value: line 1 column 1 \(char 0\)", message)
        if m:
            return message[:m.start()] + "not a number, true/false or a JSON object"
        m = re.search(r"malformed JSON: .*\(char (\d+)\)", message)
        if m:
            return message[:m.start()] + f"not valid JSON (at character {int(m.group(1)) + 1})"
        m = re.search(r"malformed JSON: ", message)
        if m:
            return message[:m.start()] + "not valid JSON: " + message[m.end():]
        return message
