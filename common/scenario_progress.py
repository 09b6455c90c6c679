"""``lunaris/<rover>/scenario/progress``: how a scenario plays, as its runner publishes it.

The scenario runner (:mod:`lunaris.client.runner`, used by ``lunaris scenario run`` and the
console) puts one :class:`ScenarioProgress` whenever something happens (a step fires, an
answer comes, what it waits for changes) and at least once a second while it plays, and a last
one when it ends; its publisher keeps the latest for a late joiner. Any tool may show it: the
console's page, a second console, a recording for the debrief. Structs only, so the key table
(:mod:`common.keys`) can name the payload without importing the player.
"""

from __future__ import annotations

from typing import Literal

import msgspec

__all__ = ["ExpectProgress", "ScenarioProgress", "StepProgress"]


class ExpectProgress(msgspec.Struct, omit_defaults=False):
    """An expect step's score as it stands: met (true), missed (false), or not yet (null)."""

    label: str  # what the crew is expected to do
    condition: str  # the condition that scores it
    within_s: float  # the time the crew has from when it is armed [s]
    met: bool | None = None
    met_t_s: float | None = None  # when it was met, from the scenario's start [s]
    deadline_t_s: float | None = None  # when it is missed if not met, from the start [s]; null until armed


class StepProgress(msgspec.Struct, omit_defaults=False):
    """One step of the scenario: what it does, when, and what became of it."""

    index: int  # from 0
    label: str  # its name, or what it does
    trigger: str  # "at 2 s", "when battery.soc < 0.5 (within 30 s)" ...
    action: str  # "inject solar/left dust 0.5" ...
    status: str  # waiting, armed, fired, ramping, done, timed out, not fired; met, missed
    outcome: str = ""  # accepted, rejected, not applied, reached ...; met, missed
    detail: str = ""  # the reason of a rejection, the condition as it held ...
    armed_t_s: float | None = None  # when its time gate opened, from the scenario's start [s]
    fired_t_s: float | None = None  # when it fired, from the scenario's start [s]
    expect: ExpectProgress | None = None  # an expect step's score; null for the other steps


class ScenarioProgress(msgspec.Struct, omit_defaults=False):
    """A scenario as it plays on one rover."""

    t_s: float  # the rover's sim time of this report [s]
    scenario: str  # its name
    rover: str
    state: Literal["starting", "playing", "ended"]
    t_rel_s: float  # sim time since the scenario's start [s]
    waiting: str  # what it waits for now, in words
    message: str  # the latest thing it said
    steps: list[StepProgress]
    end_reason: str = ""
    ok: bool | None = None  # at the end: every step fired and was accepted (expectations aside)
    actor: str = "scenario"
    session: str = ""  # the trainee session it plays in (a drill belongs to it: SPEC 13a)
