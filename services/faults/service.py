"""Faults service: keeps the session's journal and answers ``get lunaris/<rover>/faults``.

It is also the gatekeeper for what no other service owns: an instructor key for
a rover no service serves, a fault on an unknown component, an unknown input or
command. Each is rejected with an event, like every other bad input.
"""

from __future__ import annotations

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.faults import CATALOGUE
from common.messages import BadInput, Event, decode
from common.runtime import Runtime, Sample
from services.faults.model import Journal

__all__ = ["serve"]

OWNED_INPUTS = {"sun_angle", "radio", "umbilical"}
OWNED_COMMANDS = {"rail"}


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    journals = {r.id: Journal() for r in rovers}
    live_rovers: set[str] = set()

    def on_token(s: zenoh.Sample) -> None:
        rover, _ = keys.split(str(s.key_expr))
        if s.kind == zenoh.SampleKind.PUT:
            live_rovers.add(rover)

    rt.keep(rt.session.liveliness().declare_subscriber(
        keys.service("*", "*"), on_token, history=True))

    def on_event(s: Sample) -> None:
        journals[s.rover].record(decode(s.payload, Event))

    def on_instructor_key(s: Sample) -> None:
        if s.rover not in rt.rovers and s.rover not in live_rovers:
            raise BadInput(f"unknown rover {s.rover!r}: no Lunaris service serves it")
        if s.rover not in rt.rovers:
            return  # another faults service journals that rover
        head, rest = s.parts[0], s.parts[1:]
        if head == "fault" and (not rest or rest[0] not in CATALOGUE):
            known = ", ".join(sorted(CATALOGUE))
            raise BadInput(f"unknown component {rest[0] if rest else ''!r} (known: {known})")
        if head == "input" and (not rest or rest[0] not in OWNED_INPUTS):
            raise BadInput(f"unknown input {'/'.join(rest)!r} "
                           f"(inputs: {', '.join(sorted(OWNED_INPUTS))})")
        if head == "cmd" and (not rest or rest[0] not in OWNED_COMMANDS):
            raise BadInput(f"unknown command {'/'.join(rest)!r} (commands: rail/<name>)")

    def on_query(q: zenoh.Query) -> None:
        selector = str(q.key_expr)
        want_journal = selector.endswith("/journal")
        for rover, journal in journals.items():
            key = keys.faults_journal(rover) if want_journal else keys.faults(rover)
            if not zenoh.KeyExpr(key).intersects(q.key_expr):
                continue
            if want_journal:
                q.reply(key, msgspec.json.encode(list(journal.events)))
            else:
                q.reply(key, msgspec.json.encode(journal.active_faults()))

    rt.subscribe(keys.event("*"), on_event, history=True)
    for head in ("fault/**", "input/**", "cmd/**", "clock/control"):
        rt.subscribe(f"{keys.ROOT}/*/{head}", on_instructor_key, any_rover=True)
    rt.queryable(keys.faults("*"), on_query)
    rt.queryable(keys.faults_journal("*"), on_query)
