"""An instructor's write on the twin, checked as the twin will check it, before it is sent.

Every tool that writes on the twin's keys (``lunaris fault``, ``rail``, ``clock``, ``input``,
``reset``, ``snapshot``, ``traverse``, the scenario player, the console's HTTP API) plans the
write here: :func:`plan_write` checks the key (exactly one key: no wildcard chunk, DECISIONS
D2) and the payload with the very Structs and catalogue the services decode it with
(:mod:`common.messages`, :mod:`common.faults`, :func:`common.session.parse_control`), so what
the tool refuses the twin would have refused, for the same reason. What only the twin knows
(the names of its loads, rails, panels and radios, whether it drives) is the twin's to
refuse, with a ``rejected`` event.

:func:`answer_of` is the one table of which event answers a write, and which service sends it.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import msgspec

from common import keys
from common.armed import parse_arm
from common.config import Rover
from common.datafile import ID_PATTERN, NAME_PATTERN
from common.faults import parse_fault_key, parse_params
from common.messages import BARE_FIELD, BadInput, ScenarioMark, SessionStart, TimelineMark, decode_input
from common.session import parse_control

__all__ = ["DELETABLE", "FAULT_OWNERS", "STANDS_IN", "Write", "answer_of", "check_chunks", "fault_owners",
           "plan_write", "snapshot_name_problem", "stand_in", "unreachable_words"]

DELETABLE = keys.DELETABLE  # the inputs that take a delete
# The service that owns (and answers for) each component type of the fault catalogue: the
# services' port tables (each node's ``Owns``) as the tools and the faults service read them
# without importing the services; tests/architecture/test_owners.py holds the two to one another.
FAULT_OWNERS = {"battery": "battery", "load": "loads", "rail": "power", "solar": "solar",
                "umbilical": "solar", "radio": "radio"}


def fault_owners(rover: Rover) -> set[str]:
    """The services that own the faults of a rover's components, as its file implies them:
    the owner (:data:`FAULT_OWNERS`) of each kind of component it has."""
    has = {"battery": True, "load": bool(rover.loads), "rail": bool(rover.rails),
           "solar": bool(rover.solar.panels),
           "umbilical": rover.umbilical.power_w > 0 or rover.umbilical.connected,
           "radio": bool(rover.radios)}
    return {FAULT_OWNERS[component] for component, present in has.items() if present}


def unreachable_words(rover: str, owner: str, since: str | None) -> str:
    """Why a write cannot reach its owner, in the words the bridge's controls and the tools'
    writer both say: its liveliness token gone (``since``: the time it went, as the user's
    clock shows it), or never heard (None)."""
    if since is not None:
        return f"{rover}'s {owner} service is unreachable since {since} (no liveliness)"
    return f"{rover}'s {owner} service is not running (no liveliness token)"
_ACCEPTED = {"cmd": "command", "clock": "clock", "input": "input"}
# Who answers a control, and with what event kind (the rest: a session event of the faults
# service): the clock begins a trainee's session and a restore (it checks every part first).
_CONTROL_ANSWERS = {"control/scenario": ("scenario", "faults"),
                    "control/mark": ("mark", "faults"),
                    "control/session": ("session", "clock"),
                    "control/restore": ("session", "clock")}
_CONTROL_PAYLOADS: dict[str, type[msgspec.Struct]] = {
    "scenario": ScenarioMark, "mark": TimelineMark, "session": SessionStart}
_CHUNK = re.compile(NAME_PATTERN)
_ROVER = re.compile(ID_PATTERN)


STANDS_IN = ("cmd/rail/", "input/drive/traverse")  # what an instructor may do as the crew


def stand_in(write: Write) -> Write:
    """The write made by the instructor standing in for the crew (a drill run without the
    crew's dashboard): it counts as the crew's action in the crew's response and the debrief.
    Only the crew's rail controls and its stop of the rover (a delete of the traverse: the
    crew never drives it); else :class:`BadInput`."""
    tail = write.tail
    if tail == "input/drive/traverse" and write.payload is not None:
        raise BadInput("the crew stops the rover (a delete of input/drive/traverse) but does not "
                       "send it a traverse: send it as the instructor")
    if not tail.startswith(STANDS_IN):
        if tail.startswith("input/"):  # the dashboard writes some inputs; a stand-in does not
            raise BadInput(f"standing in for the crew covers its rail commands and stopping the "
                           f"rover only: send {tail} as the instructor")
        raise BadInput(f"the crew's dashboard cannot write {tail}: only its rail commands and "
                       "stopping the rover can be made for the crew")
    return write._replace(actor="crew")


class Write(NamedTuple):
    """A write on one key of the twin: the key, the payload to send (None: a delete), the
    event kind that accepts it and the service that answers it."""

    key: str
    payload: bytes | None
    accepted: str
    owner: str
    actor: str | None = None  # who it says made it; None: its writer (see stand_in)

    @property
    def rover(self) -> str:
        return keys.split(self.key)[0]

    @property
    def tail(self) -> str:
        """The key under ``lunaris/<rover>/``: ``fault/battery/heating``."""
        return "/".join(keys.split(self.key)[1])


def check_chunks(rover: str, parts: list[str]) -> None:
    """Refuse a key that is not exactly one key of a rover: a wildcard chunk (``*``, ``**``,
    ``$*``), a verbatim (``@``) chunk, or any character a key of the twin never holds."""
    for chunk in [rover, *parts]:
        if "*" in chunk:
            raise BadInput(f"the key chunk {chunk!r} is a wildcard: a write names exactly one key "
                           "(no '*', '**' or '$*')")
        if chunk.startswith("@"):
            raise BadInput(f"the key chunk {chunk!r} is a verbatim chunk ('@'): no key of the twin "
                           "has one")
        if not _CHUNK.match(chunk):
            raise BadInput(f"the key chunk {chunk!r} holds characters no key of the twin has "
                           "(letters, digits, '_', '-' and '.' only)")
    if not _ROVER.match(rover):
        raise BadInput(f"bad rover id {rover!r}: lower-case letters, digits, '_' and '-'")


SNAPSHOT_MAX = 64  # characters of a snapshot's name (common.keys.SNAPSHOT_NAME)
_SNAPSHOT_WORDS = "a snapshot name is letters, digits, '-', '_' and '.'"
_CHAR_NAMES = {" ": "a space", "/": "a '/'", "\t": "a tab", "*": "a '*'"}


def snapshot_name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a snapshot, in words (None: it can): "a snapshot name is
    letters, digits, '-', '_' and '.'; 'before storm' has a space"."""
    if not name:
        return f"{_SNAPSHOT_WORDS}: give one"
    bad = [c for c in dict.fromkeys(name) if not (c.isascii() and (c.isalnum() or c in "-_."))]
    if bad:
        said = [_CHAR_NAMES.get(c, f"{c!r}" if c.isprintable() else "a control character") for c in bad[:3]]
        shown = "".join(c if c.isprintable() else "?" for c in name[:SNAPSHOT_MAX])
        return f"{_SNAPSHOT_WORDS}; {shown!r} has {' and '.join(said)}"
    if len(name) > SNAPSHOT_MAX:
        return f"{_SNAPSHOT_WORDS}, at most {SNAPSHOT_MAX} of them; this one has {len(name)}"
    return None


def answer_of(parts: list[str] | tuple[str, ...], delete: bool) -> tuple[str, str]:
    """(event kind that accepts, service that answers) a write on ``lunaris/<rover>/<parts>``;
    :class:`BadInput` for a key no service reads. The one table every writer uses."""
    if not parts:
        raise BadInput("no key")
    head = parts[0]
    if head == "fault":
        fk = parse_fault_key(list(parts[1:]))
        return ("fault_cleared" if delete else "fault_injected"), FAULT_OWNERS[fk.component]
    if head == "control":
        return _CONTROL_ANSWERS.get("/".join(parts[:2]), ("session", "faults"))
    if keys.ARMED_FAULT.matches(parts):
        parse_fault_key(list(parts[2:]))
        return ("fault_cancelled" if delete else "fault_armed"), "faults"
    family = keys.family_of(list(parts))
    if family is None or family.direction != "in" or head not in _ACCEPTED:
        writable = ", ".join(f.name for f in keys.families("in"))
        raise BadInput(f"no such input or command {'/'.join(parts)!r} (the twin reads: {writable}, "
                       "fault/..., control/...)")
    return _ACCEPTED[head], family.owner


def plan_write(rover: str, parts: list[str] | str, payload: bytes | None) -> Write:
    """Check a put (``payload`` bytes) or delete (None) on ``lunaris/<rover>/<parts>``; raise
    :class:`BadInput` saying what is wrong. The payload planned is the checked one, re-encoded."""
    if isinstance(parts, str):
        parts = [p for p in parts.split("/") if p]
    try:
        return _plan(rover, list(parts), payload)
    except BadInput:
        raise
    except UnicodeError:
        raise BadInput("the payload holds text that is not valid Unicode (a lone surrogate)") from None
    except (ValueError, OverflowError, RecursionError) as exc:
        if "digits" in str(exc):
            raise BadInput("the payload holds a number with thousands of digits: no input takes "
                           "one") from None
        raise BadInput(f"the payload cannot be read: {exc}") from None


def _plan(rover: str, parts: list[str], payload: bytes | None) -> Write:
    if parts[:1] == ["control"] and len(parts) >= 2 and parts[1] in ("snapshot", "restore"):
        problem = snapshot_name_problem("/".join(parts[2:]))
        if problem is not None:  # before the key's own check: said as a name, not as a key
            raise BadInput(problem)
    check_chunks(rover, parts)
    accepted, owner = answer_of(parts, payload is None)
    key = keys.under(rover, "/".join(parts))
    head = parts[0]
    if head == "fault":
        fk = parse_fault_key(parts[1:])
        if payload is None:
            return Write(key, None, accepted, owner)
        # on the wire without the tag (common.faults): the kind is the key's last chunk
        return Write(key, msgspec.json.encode(msgspec.structs.asdict(parse_params(fk, payload))),
                     accepted, owner)
    if head == "control":
        struct = _CONTROL_PAYLOADS.get(parts[1]) if len(parts) == 2 else None
        if struct is not None:
            if payload is None:
                raise BadInput(f"a {'session control' if struct is SessionStart else parts[1] + ' mark'} "
                               "is a put, not a delete")
            return Write(key, msgspec.json.encode(decode_input(payload, struct)), accepted, owner)
        if parse_control(parts) is None:
            raise BadInput(f"no such control {'/'.join(parts)!r} (control/session, control/mark, "
                           "control/reset, control/snapshot/<name>, control/restore/<name>; a name "
                           "is letters, digits, '_', '-' and '.', at most 64)")
        if payload is None:
            raise BadInput("a session control is a put, not a delete")
        return Write(key, b"", accepted, owner)
    if keys.ARMED_FAULT.matches(parts):
        if payload is None:
            return Write(key, None, accepted, owner)
        arming = parse_arm(parts[2:], payload)  # the rover's names are the twin's to check
        return Write(key, msgspec.json.encode(arming.request), accepted, owner)
    family = keys.family_of(parts)
    assert family is not None  # answer_of refused the rest
    if payload is None:
        if family.name not in DELETABLE:
            raise BadInput(f"{family.name} takes a put, not a delete")
        return Write(key, None, accepted, owner)
    value = decode_input(payload, family.payload, bare=BARE_FIELD.get(family.payload))
    return Write(key, msgspec.json.encode(value), accepted, owner)
