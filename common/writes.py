"""An instructor's write on the twin, checked as the twin will check it, before it is sent.

Every tool that writes on the twin's keys (``lunaris rail``, ``clock``, ``input``, the
console's HTTP API) validates the write here with the very Structs and catalogue the
services decode it with (:mod:`common.messages`, :mod:`common.faults`,
:func:`common.session.parse_control`), so what the tool refuses the twin would have refused,
for the same reason, in the same words. What only the twin knows (the names of its loads,
rails, panels and radios, whether it drives) is the twin's to refuse, with a ``rejected``
event.
"""

from __future__ import annotations

from typing import NamedTuple

import msgspec

from common import keys
from common.faults import parse_fault_key, parse_params
from common.messages import BARE_FIELD, BadInput, ScenarioMark, decode_input
from common.session import parse_control

__all__ = ["DELETABLE", "Write", "check_write"]

# The inputs that take a delete: a panel back to the rover's sun angle, a panel's dust input
# gone, the rover stopped.
DELETABLE = ("input/solar/*/sun_angle", "input/solar/*/dust", "input/drive/traverse")
_ACCEPTED = {"cmd": "command", "clock": "clock", "input": "input"}


class Write(NamedTuple):
    """A checked write: the payload to send (None: a delete) and the event that accepts it."""

    payload: bytes | None
    accepted: str


def check_write(parts: list[str], payload: bytes | None) -> Write:
    """Check a put (``payload`` bytes) or delete (None) on ``lunaris/<rover>/<parts>``; raise
    :class:`BadInput` saying what is wrong. The payload returned is the checked one, re-encoded."""
    if not parts:
        raise BadInput("no key")
    head = parts[0]
    if head == "fault":
        fk = parse_fault_key(parts[1:])
        if payload is None:
            return Write(None, "fault_cleared")
        params = parse_params(fk, payload)
        return Write(msgspec.json.encode(params), "fault_injected")
    if head == "control":
        if parts == ["control", "scenario"]:
            if payload is None:
                raise BadInput("a scenario mark is a put")
            return Write(msgspec.json.encode(decode_input(payload, ScenarioMark)), "scenario")
        if parse_control(parts) is None:
            raise BadInput(f"no such control {'/'.join(parts)!r} (control/reset, "
                           "control/snapshot/<name>, control/restore/<name>; a name is letters, "
                           "digits, '_', '-' and '.', at most 64)")
        if payload is None:
            raise BadInput("a session control is a put, not a delete")
        return Write(b"", "session")
    family = keys.family_of(parts)
    if family is None or family.direction != "in":
        writable = ", ".join(f.name for f in keys.families("in"))
        raise BadInput(f"no such input or command {'/'.join(parts)!r} (the twin reads: {writable}, "
                       "fault/..., control/...)")
    if payload is None:
        if family.name not in DELETABLE:
            raise BadInput(f"{family.name} takes a put, not a delete")
        return Write(None, _ACCEPTED[head])
    value = decode_input(payload, family.payload, bare=BARE_FIELD.get(family.payload))
    return Write(msgspec.json.encode(value), _ACCEPTED[head])
