"""What the instructor tools know about the keys they read: one table of key families.

A *family* is a key shape under ``lunaris/<rover>/`` with ``*`` for a name
(``load/*/power``) and the msgspec Struct its payload follows (SPEC §5).
:func:`family_of` classifies a received key; :func:`json_schema` turns a
family's Struct into the self-contained JSON schema that ``lunaris record``
writes per MCAP channel. Nothing here opens a session.
"""

from __future__ import annotations

from typing import Any

import msgspec

from common import keys
from common.messages import KEY_PAYLOADS, is_telemetry

__all__ = [
    "FAMILIES",
    "INSTRUCTOR_HEADS",
    "family_of",
    "json_schema",
    "rover_and_family",
]

# family pattern (after lunaris/<rover>/) -> payload Struct
FAMILIES: dict[str, type[msgspec.Struct]] = {
    "/".join("*" if c.startswith("{") else c for c in chunks): struct
    for chunks, struct in KEY_PAYLOADS.items() if is_telemetry(struct)
}

# Keys an instructor writes (SPEC §5): their payloads may be bare numbers, empty or deletes.
INSTRUCTOR_HEADS = ("fault", "input", "cmd", "clock/control")


def family_of(parts: list[str]) -> str | None:
    """The family of a key's chunks after ``lunaris/<rover>/``, or None if it has none.

    >>> family_of(["load", "imu", "power"])
    'load/*/power'
    """
    for pattern in FAMILIES:
        chunks = pattern.split("/")
        if len(chunks) == len(parts) and all(c in ("*", p) for c, p in zip(chunks, parts, strict=True)):
            return pattern
    return None


def rover_and_family(key: str) -> tuple[str, str | None]:
    """``lunaris/mapp-1/rail/12V/state`` -> ``("mapp-1", "rail/*/state")``; raises ValueError
    for a key outside ``lunaris/<rover>/``."""
    rover, parts = keys.split(key)
    return rover, family_of(parts)


def json_schema(struct: type[msgspec.Struct]) -> dict[str, Any]:
    """The JSON schema of ``struct`` with the Struct itself at the root.

    ``msgspec.json.schema`` returns ``{"$ref": "#/$defs/Name", "$defs": {...}}``; viewers
    such as Foxglove want the object at the top, so the root reference is resolved and
    any other definitions are kept in ``$defs``.
    """
    full = msgspec.json.schema(struct)
    defs = dict(full.get("$defs", {}))
    ref = full.get("$ref", "")
    if not ref.startswith("#/$defs/"):
        return full
    root = dict(defs.pop(ref.removeprefix("#/$defs/")))
    if defs:
        root["$defs"] = defs
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **root}
