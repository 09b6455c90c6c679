"""Playing a training scenario: the clock-driven state machine, without Zenoh or a clock.

:class:`Player` is stepped with the simulated time and a lookup of the latest telemetry
and returns the writes to make, so a scenario can be played in a test without a twin.
The runner that plays it against the running twin is :class:`lunaris.client.runner.Runner`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Literal

import msgspec

from common import keys
from common.conditions import Lookup, parse_condition
from common.messages import (
    ClockControl,
    RadioPosition,
    RailCommand,
    SunAngle,
    UmbilicalInput,
)
from common.scenario import Scenario, Step
from common.writes import Write, answer_of

__all__ = ["SETTLED", "Player", "StepResult", "StepStatus", "StepWrite", "describe_action",
           "describe_trigger"]

StepStatus = Literal["waiting", "armed", "fired", "ramping", "done", "timed out", "not fired",
                     "met", "missed"]
# An expect step ends met or missed (or not fired, never armed); the others end as before.
SETTLED: frozenset[str] = frozenset({"fired", "done", "timed out", "met", "missed"})


@dataclass(frozen=True)
class StepWrite:
    """A write the player asks for (:class:`common.writes.Write`: the key, the payload, None
    for a delete, the event that accepts it and who sends it), for step ``step``; ``final`` is
    False for the values of a ramp before its last."""

    write: Write
    step: int
    final: bool = True

    @property
    def key(self) -> str:
        return self.write.key

    @property
    def payload(self) -> bytes | None:
        return self.write.payload

    @property
    def accepted(self) -> str:
        return self.write.accepted


def _write(rover: str, tail: str, payload: bytes | None, step: int, final: bool = True) -> StepWrite:
    parts = tail.split("/")
    accepted, owner = answer_of(parts, payload is None)
    return StepWrite(Write(keys.under(rover, tail), payload, accepted, owner), step, final)


def _encode(struct: msgspec.Struct) -> bytes:
    """A typed input, with the fields it does not set left out."""
    return msgspec.json.encode({k: v for k, v in msgspec.structs.asdict(struct).items() if v is not None})


@dataclass
class StepResult:
    """What happened to one step."""

    index: int
    label: str
    armed_t_s: float | None = None  # when its time gate opened (relative to the start)
    fired_t_s: float | None = None  # relative to the start
    status: StepStatus = "waiting"
    outcome: str = ""  # accepted, rejected, not applied, reached (set by the runner); met, missed
    detail: str = ""
    # an expect step: met (True), missed (False) or not yet scored (None), and when it was
    # met or its deadline (both relative to the start)
    met: bool | None = None
    met_t_s: float | None = None
    deadline_t_s: float | None = None


def _ramp(value: Any) -> tuple[float, float, float] | None:
    if isinstance(value, dict):
        return float(value["from"]), float(value["to"]), float(value["over_s"])
    return None


def _at(value: Any, since_s: float) -> float:
    """A number, or a ramp's value ``since_s`` after it started."""
    r = _ramp(value)
    if r is None:
        return float(value)
    lo, hi, over = r
    return lo + (hi - lo) * min(1.0, max(0.0, since_s / over))


def _ramp_length(step: Step) -> float:
    values = [step.sun_angle] if step.sun_angle is not None else []
    if step.position is not None:
        values += [step.position.distance_m, step.position.angle_deg]
    return max((r[2] for r in map(_ramp, values) if r is not None), default=0.0)


def describe_action(step: Step) -> str:
    def val(v: Any, unit: str) -> str:
        r = _ramp(v)
        return f"{r[0]:g} -> {r[1]:g}{unit} over {r[2]:g} s" if r else f"{float(v):g}{unit}"

    if step.inject is not None:
        value = "" if step.inject.value is None else f" {json.dumps(step.inject.value)}"
        return f"inject {step.inject.component} {step.inject.kind}{value}"
    if step.clear is not None:
        return f"clear {step.clear.component} {step.clear.kind}"
    if step.sun_angle is not None:
        return f"sun angle {val(step.sun_angle, ' deg')}"
    if step.position is not None:
        p = step.position
        return f"position to radio {p.radio}: {val(p.distance_m, ' m')}, {val(p.angle_deg, ' deg')}"
    if step.umbilical is not None:
        return "umbilical " + ("connected" if step.umbilical else "disconnected")
    if step.clock is not None:
        what = []
        if step.clock.time_scale is not None:
            what.append(f"x{step.clock.time_scale:g}")
        if step.clock.paused is not None:
            what.append("paused" if step.clock.paused else "running")
        return "clock " + " ".join(what)
    if step.rail is not None:
        switch = "reset" if step.rail.reset else ("on" if step.rail.on else "off")
        return f"rail {step.rail.name} {switch}"
    if step.traverse is not None:
        t = step.traverse
        if not isinstance(t, dict):
            return "traverse stop"
        speed = f" at {t['speed_m_per_s']:g} m/s" if t.get("speed_m_per_s") is not None else ""
        back = ", and back" if t.get("return_to_start") else ""
        return f"traverse through {len(t.get('waypoints', []))} waypoint(s){speed}{back}"
    if step.expect is not None:
        return f"expect {step.expect.when} within {step.expect.within_s:g} s"
    return "checkpoint"


def describe_trigger(step: Step) -> str:
    parts = []
    if step.at_s is not None:
        parts.append(f"at {step.at_s:g} s")
    if step.after_s is not None:
        parts.append(f"{step.after_s:g} s after the previous step")
    if step.when is not None:
        parts.append(f"when {step.when}" + (f" (within {step.timeout_s:g} s)" if step.timeout_s else ""))
    if not parts and step.expect is not None:
        parts.append("when the previous step fires")
    return ", then ".join(parts)


class Player:
    """The scenario's clock-driven state machine. Call :meth:`tick` with every clock tick's
    ``t_s``; it returns the writes to make now. Times in results are relative to the first
    tick (the scenario's start)."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.rover = scenario.rover
        self.conditions = [parse_condition(s.when) if s.when else None for s in scenario.steps]
        self.expects = [parse_condition(s.expect.when) if s.expect else None for s in scenario.steps]
        self.results = [StepResult(i, s.label if s.expect else s.name or describe_action(s))
                        for i, s in enumerate(scenario.steps)]
        self.t0: float | None = None
        self.t_rel = 0.0
        self._ramps: dict[int, float] = {}  # step -> start (relative)
        self.finished = False
        self.end_reason = ""

    def _after(self, i: int) -> float | None:
        """The ``after_s`` of step ``i``: its own, 0 for an expect step without a time gate (it
        is armed when the previous step fires), None for a step not chained to the previous."""
        step = self.scenario.steps[i]
        if step.at_s is not None:
            return None
        if step.after_s is not None:
            return step.after_s
        return 0.0 if step.expect is not None else None

    def _gate(self, i: int) -> float | None:
        """When step ``i``'s time gate opens (relative), None while it cannot be known. A step
        after an expect step counts from when the expectation was armed (it holds nothing up)."""
        step = self.scenario.steps[i]
        if step.at_s is not None:
            return step.at_s
        after = self._after(i)
        if after is not None:
            if i == 0:
                return after
            prev = self.results[i - 1]
            base = prev.armed_t_s if self.scenario.steps[i - 1].expect is not None else prev.fired_t_s
            return None if base is None else base + after
        return 0.0

    def tick(self, t_s: float, lookup: Lookup) -> list[StepWrite]:
        if self.finished:
            return []
        if self.t0 is None:
            self.t0 = t_s
        t = self.t_rel = t_s - self.t0
        writes: list[StepWrite] = []
        for i, step in enumerate(self.scenario.steps):
            r = self.results[i]
            if r.status not in ("waiting", "armed"):
                continue
            gate = self._gate(i)
            if gate is None or t < gate:
                continue
            if r.status == "waiting":
                r.status, r.armed_t_s = "armed", gate
            assert r.armed_t_s is not None  # set when the step was armed, just above or before
            if step.expect is not None:
                self._score(i, t, lookup)
                continue
            cond = self.conditions[i]
            if cond is not None and not cond.holds(lookup):
                if step.timeout_s is not None and t - r.armed_t_s >= step.timeout_s:
                    r.status = "timed out"
                    r.detail = (f"{cond.text} did not hold within {step.timeout_s:g} s "
                                f"({cond.describe(lookup)})")
                continue
            r.fired_t_s = t
            r.status = "fired"
            if cond is not None:
                r.detail = cond.describe(lookup)
            fired = self.writes_of(i, 0.0, final=_ramp_length(step) == 0)
            if not fired:
                r.outcome = "reached"  # a checkpoint: nothing to write
            writes += fired
            if _ramp_length(step) > 0:
                self._ramps[i] = t
                r.status = "ramping"
        for i, start in list(self._ramps.items()):
            if self.results[i].fired_t_s == t:
                continue  # already written this tick
            done = t - start >= _ramp_length(self.scenario.steps[i])
            writes += self.writes_of(i, t - start, final=done)
            if done:
                del self._ramps[i]
                self.results[i].status = "done"
        self._check_end(t)
        return writes

    def _score(self, i: int, t: float, lookup: Lookup) -> None:
        """An armed expectation: met at the first tick its condition holds, missed once its
        ``within_s`` is over without."""
        expect, cond, r = self.scenario.steps[i].expect, self.expects[i], self.results[i]
        assert expect is not None and cond is not None and r.armed_t_s is not None
        r.deadline_t_s = r.armed_t_s + expect.within_s
        if cond.holds(lookup):
            r.status, r.outcome, r.met, r.met_t_s = "met", "met", True, t
            r.detail = f"{cond.describe(lookup)} after {t - r.armed_t_s:.1f} s of {expect.within_s:g} s"
        elif t >= r.deadline_t_s:
            r.status, r.outcome, r.met = "missed", "missed", False
            r.detail = (f"{cond.text} did not hold within {expect.within_s:g} s "
                        f"({cond.describe(lookup)})")

    def _check_end(self, t: float) -> None:
        duration = self.scenario.duration_s
        if duration is not None and t >= duration:
            self.finish(f"duration of {duration:g} s reached")
            return
        if duration is None and all(r.status in SETTLED for r in self.results):
            self.finish("every step has played")
        elif duration is None and not self._ramps and not self._drop_blocked():
            self.finish("no remaining step can fire")

    def waiting(self, lookup: Lookup) -> str:
        """What the scenario waits for now, in words (said at least every 10 s while it plays)."""
        if self.finished:
            return f"ended: {self.end_reason}"
        expecting = "".join(
            f"; expecting {r.label!r} for {max(0.0, r.deadline_t_s - self.t_rel):.0f} s more"
            for r in self.results if r.status == "armed" and r.deadline_t_s is not None)
        for r in self.results:
            if r.status not in ("waiting", "armed") or r.deadline_t_s is not None:
                continue
            step = self.scenario.steps[r.index]
            gate = self._gate(r.index)
            cond = self.conditions[r.index]
            if r.status == "waiting" and gate is not None and gate > self.t_rel:
                what = f"its time, in {gate - self.t_rel:.0f} s"
            elif cond is not None:
                what = f"{cond.text} (now {cond.describe(lookup)})"
                if step.timeout_s is not None and r.armed_t_s is not None:
                    what += f", for {max(0.0, r.armed_t_s + step.timeout_s - self.t_rel):.0f} s more"
            else:
                what = describe_trigger(step)
            return f"waiting for step {r.index + 1} {r.label!r}: {what}{expecting}"
        if expecting:
            return expecting[2:]
        for i, start in self._ramps.items():
            left = start + _ramp_length(self.scenario.steps[i]) - self.t_rel
            return f"step {i + 1} {self.results[i].label!r} ramping, {left:.0f} s to go"
        if self.scenario.duration_s is not None:
            return (f"every step has played; the scenario ends at its duration of "
                    f"{self.scenario.duration_s:g} s, in {self.scenario.duration_s - self.t_rel:.0f} s")
        return "finishing"

    def _drop_blocked(self) -> bool:
        """Mark the steps chained to a step that will never fire; True if any can still fire."""
        for i, r in enumerate(self.results):
            if r.status in ("waiting", "armed"):
                blocked = (self._after(i) is not None and i > 0
                           and self.results[i - 1].status in ("timed out", "not fired"))
                if not blocked:
                    return True
                r.status = "not fired"
                r.detail = "the previous step did not fire"
        return False

    def finish(self, reason: str) -> None:
        if self.finished:
            return
        self.finished = True
        self.end_reason = reason
        for r in self.results:
            if self.scenario.steps[r.index].expect is not None and r.met is None:
                r.met = False
                if r.status == "armed":
                    r.status = r.outcome = "missed"
                    r.detail = f"not met when the scenario ended ({reason})"
                else:
                    r.status, r.outcome = "not fired", "missed"
                    r.detail = (r.detail + "; " if r.detail else "") + f"never armed ({reason})"
            elif r.status in ("waiting", "armed"):
                r.status = "not fired"
            elif r.status == "ramping":
                r.status = "fired"
                r.detail = (r.detail + "; " if r.detail else "") + "ramp cut short"

    def writes_of(self, i: int, since_s: float, final: bool = True) -> list[StepWrite]:
        """The writes of step ``i``'s action, ``since_s`` after it fired (for ramps). The twin
        checks them as it checks every write, and answers."""
        rover, step = self.rover, self.scenario.steps[i]
        if step.inject is not None:
            value = step.inject.value
            payload = b"" if value is None else msgspec.json.encode(value)
            return [_write(rover, f"fault/{step.inject.component.strip('/')}/{step.inject.kind}", payload, i)]
        if step.clear is not None:
            return [_write(rover, f"fault/{step.clear.component.strip('/')}/{step.clear.kind}", None, i)]
        if step.sun_angle is not None:
            body = _encode(SunAngle(angle_deg=_at(step.sun_angle, since_s)))
            return [_write(rover, "input/sun_angle", body, i, final)]
        if step.position is not None:
            p = step.position
            body = _encode(RadioPosition(distance_m=_at(p.distance_m, since_s),
                                         angle_deg=_at(p.angle_deg, since_s)))
            return [_write(rover, f"input/radio/{p.radio}/position", body, i, final)]
        if step.umbilical is not None:
            return [_write(rover, "input/umbilical", _encode(UmbilicalInput(connected=step.umbilical)), i)]
        if step.clock is not None:
            body = _encode(ClockControl(time_scale=step.clock.time_scale, paused=step.clock.paused))
            return [_write(rover, "clock/control", body, i)]
        if step.rail is not None:
            body = _encode(RailCommand(on=step.rail.on, reset=step.rail.reset))
            return [_write(rover, f"cmd/rail/{step.rail.name}", body, i)]
        if step.traverse is not None:
            traverse = msgspec.json.encode(step.traverse) if isinstance(step.traverse, dict) else None
            return [_write(rover, "input/drive/traverse", traverse, i)]
        return []
