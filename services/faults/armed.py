"""The armed faults of one rover (SPEC 13b): the logic, without Zenoh, files or a clock.

A fault armed for a time (``at_t_s``, or ``in_s`` from when it was armed) warns ``warn_s``
of sim time before it is due and fires when it is due. A fault armed for a condition (the
scenario language) warns at the first tick its condition holds, and is then due ``warn_s``
later, whether the condition still holds or not (a simulator's malfunction trigger: the
instructor has that long to cancel it). A fault armed late for its warning (``in_s`` shorter
than ``warn_s``) warns at the first tick. Arming the same key again replaces what was
armed there, as injecting a fault again replaces its parameters.

:class:`ArmedBook` is stepped with each tick's sim time and a lookup of the latest telemetry
(:data:`common.conditions.Lookup`) and returns what to do, in order: ``("warn", armed)``,
``("fire", armed)``; a fault fired or cancelled leaves the book. Each armed fault remembers
the epoch and session of the ticks it was armed in: the faults service ends it when the
ticks leave them (a reset, a restore, a new trainee's session).
"""

from __future__ import annotations

from typing import Any, Literal

import msgspec

from common.armed import DEFAULT_WARN_S, Arming
from common.conditions import Condition, Lookup, parse_condition
from common.messages import ArmedFault, BadInput

__all__ = ["Armed", "ArmedBook", "Step", "arm"]

Step = tuple[Literal["warn", "fire"], "Armed"]


class Armed(msgspec.Struct, kw_only=True):
    """One armed fault, as the book keeps it and the faults service saves it."""

    key: str  # lunaris/<rover>/faults/armed/<component>/<kind>
    fault: str  # <component>/<kind>, as after fault/
    value: Any = None  # as the arming gave it
    payload: str = ""  # the fault's put, checked (common.armed.parse_arm)
    at_t_s: float | None = None
    in_s: float | None = None
    when: str | None = None
    warn_s: float = DEFAULT_WARN_S
    armed_t_s: float = 0.0
    due_t_s: float | None = None  # None: a condition that has not held yet
    warned_t_s: float | None = None
    actor: str = "instructor"
    epoch: int = 0  # the ticks' epoch and session when it was armed
    session: str = ""

    def condition(self) -> Condition | None:
        return None if self.when is None else parse_condition(self.when)

    def listed(self) -> ArmedFault:
        return ArmedFault(key=self.key, fault=self.fault, value=self.value, at_t_s=self.at_t_s,
                          in_s=self.in_s, when=self.when, warn_s=self.warn_s,
                          armed_t_s=self.armed_t_s, due_t_s=self.due_t_s,
                          warned_t_s=self.warned_t_s, actor=self.actor)

    def trigger(self) -> str:
        """What it waits for, in words: "at t=130.0 s", "when battery.soc < 0.5"."""
        if self.when is not None:
            return f"when {self.when}"
        return f"at t={self.due_t_s:.1f} s"


def arm(key: str, arming: Arming, now_t_s: float, actor: str, epoch: int, session: str) -> Armed:
    """The armed fault of a checked request, at sim time ``now_t_s``; :class:`BadInput` for a
    time already past."""
    req = arming.request
    due = req.at_t_s if req.at_t_s is not None else (
        now_t_s + req.in_s if req.in_s is not None else None)
    if req.at_t_s is not None and req.at_t_s < now_t_s:
        raise BadInput(f"at_t_s={req.at_t_s:g} is past: the rover's time is t={now_t_s:.1f} s "
                       "(give a later time, or in_s)")
    return Armed(key=key, fault=arming.fault.path, value=req.value,
                 payload=arming.payload.decode(), at_t_s=req.at_t_s, in_s=req.in_s,
                 when=req.when, warn_s=DEFAULT_WARN_S if req.warn_s is None else req.warn_s,
                 armed_t_s=now_t_s, due_t_s=due, actor=actor,
                 epoch=epoch, session=session)


class ArmedBook:
    """The armed faults of one rover, by armed key, in the order they were armed."""

    def __init__(self) -> None:
        self.armed: dict[str, Armed] = {}
        self._conditions: dict[str, Condition | None] = {}

    def __len__(self) -> int:
        return len(self.armed)

    def arm(self, a: Armed) -> Armed | None:
        """Keep ``a``; the one it replaces on the same key, if any."""
        before = self.armed.pop(a.key, None)
        self.armed[a.key] = a
        self._conditions[a.key] = a.condition()
        return before

    def cancel(self, key: str) -> Armed | None:
        """Take the fault armed on ``key`` out (None when nothing is armed there)."""
        self._conditions.pop(key, None)
        return self.armed.pop(key, None)

    def watched(self) -> set[tuple[str, ...]]:
        """The telemetry keys (chunks after ``lunaris/<rover>/``) the conditions still waited
        for read."""
        out: set[tuple[str, ...]] = set()
        for key, a in self.armed.items():
            cond = self._conditions.get(key)
            if cond is not None and a.warned_t_s is None:
                out.update(c.key_parts for c in cond.comparisons)
        return out

    def tick(self, t_s: float, lookup: Lookup) -> list[Step]:
        """What is due at sim time ``t_s``: warnings, then firings, in the order armed; the
        fired leave the book."""
        steps: list[Step] = []
        for key, a in list(self.armed.items()):
            if a.warned_t_s is None:
                cond = self._conditions.get(key)
                if cond is not None:
                    if cond.holds(lookup):
                        a.warned_t_s, a.due_t_s = t_s, t_s + a.warn_s
                        steps.append(("warn", a))
                elif a.due_t_s is not None and t_s >= a.due_t_s - a.warn_s:
                    a.warned_t_s = t_s
                    steps.append(("warn", a))
            if a.warned_t_s is not None and a.due_t_s is not None and t_s >= a.due_t_s:
                self.cancel(key)
                steps.append(("fire", a))
        return steps

    def outside(self, epoch: int, session: str) -> list[Armed]:
        """Take out the faults armed in another epoch or session than the ticks' now."""
        gone = [a for a in self.armed.values() if (a.epoch, a.session) != (epoch, session)]
        for a in gone:
            self.cancel(a.key)
        return gone

    def listed(self) -> list[ArmedFault]:
        return [a.listed() for a in self.armed.values()]

    def saved(self) -> list[dict[str, Any]]:
        return [msgspec.to_builtins(a) for a in self.armed.values()]

    def restore(self, saved: Any) -> None:
        """Take back what :meth:`saved` returned; ValueError naming what is wrong."""
        try:
            records = msgspec.convert(saved, list[Armed])
            for a in records:
                a.condition()
        except (msgspec.ValidationError, ValueError) as exc:
            raise ValueError(str(exc)) from None
        for a in records:
            self.arm(a)
