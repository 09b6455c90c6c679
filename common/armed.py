"""An armed fault's request checked (SPEC 13b): the one check the tools and the faults service
make, so what a tool refuses the twin would have refused, for the same reason.

``put lunaris/<rover>/faults/armed/<component>/<kind>`` with an :class:`~common.messages.ArmFault`
arms a fault of the catalogue (:mod:`common.faults`) for a sim time (``at_t_s``), a time from
now (``in_s``) or a condition of the scenario language (``when``, :mod:`common.conditions`),
with a warning ``warn_s`` before it fires. :func:`parse_arm` checks the key, the payload,
the fault's parameters (as a put on ``fault/...`` would be checked), that exactly one trigger
is given and the condition's grammar; with the rover's file, the names its key and its
condition use too.
"""

from __future__ import annotations

from typing import NamedTuple

import msgspec

from common.conditions import Condition, parse_condition
from common.config import Rover
from common.faults import FaultKey, parse_fault_key, parse_params
from common.messages import ArmFault, BadInput, decode_input
from common.scenario import condition_problems, fault_name_problem

__all__ = ["DEFAULT_WARN_S", "TRIGGERS", "Arming", "parse_arm"]

TRIGGERS = ("at_t_s", "in_s", "when")
DEFAULT_WARN_S = 10.0  # the warning's lead when an arming gives none (or null) [s of sim time]


class Arming(NamedTuple):
    """A checked request: the fault, its parameters as a put on ``fault/...`` carries them
    (``b""`` for none), the request and its condition (None for a time)."""

    fault: FaultKey
    payload: bytes
    request: ArmFault
    condition: Condition | None


def parse_arm(parts: list[str], payload: bytes, rover: Rover | None = None) -> Arming:
    """Check an arming: ``parts`` the key's chunks after ``faults/armed/``; :class:`BadInput`
    saying in words what is wrong."""
    fk = parse_fault_key(parts)
    if rover is not None:
        problem = fault_name_problem(fk, rover)
        if problem is not None:
            raise BadInput(problem)
    req = decode_input(payload, ArmFault)
    given = [t for t in TRIGGERS if getattr(req, t) is not None]
    if len(given) != 1:
        said = ", ".join(given) if given else "none"
        raise BadInput(f"give exactly one of at_t_s (a sim time), in_s (seconds from now) and "
                       f"when (a condition); got {said}")
    value = b"" if req.value is None else msgspec.json.encode(req.value)
    try:
        params = parse_params(fk, value)
    except BadInput as exc:
        raise BadInput(f"value: {exc}") from None
    fault_payload = b"" if req.value is None else msgspec.json.encode(msgspec.structs.asdict(params))
    condition = None
    if req.when is not None:
        problems = condition_problems(req.when, rover)
        if problems:
            raise BadInput("; ".join(problems))
        condition = parse_condition(req.when)
    return Arming(fk, fault_payload, req, condition)
