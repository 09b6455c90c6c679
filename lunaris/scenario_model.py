"""Training scenarios: the YAML format, its validation, conditions, and the player's logic.

Pure: no Zenoh, no clock. :func:`parse_scenario` validates a whole file and
reports every problem with its path (as :mod:`common.config` does for rovers);
:class:`Player` is stepped with the simulated time and a lookup of the latest
telemetry and returns the writes to make, so a scenario can be played in a
test without a twin.

A scenario::

    scenario: {name: Dust storm, description: ...}
    rover: mapp-1
    time_scale: 20            # optional: clock speed while it plays (restored at the end)
    duration_s: 900           # optional: stop this long (sim time) after the start
    steps:
      - name: dust on the left panel
        at_s: 30              # sim seconds after the start
        inject: {component: solar/left, kind: dust, value: 0.6}
      - after_s: 60           # sim seconds after the previous step fired
        sun_angle: {from: 60, to: 85, over_s: 120}   # a ramp, re-published every tick
      - when: battery.soc < 0.4 and rail.5V_CH2.state == on
        timeout_s: 600        # give up if it has not held 600 s after being armed
        rail: {name: 5V_CH2, on: false}

A step has a time gate (``at_s`` or ``after_s``, optional), a condition (``when``,
optional; at least one of the two), and one action: ``inject``, ``clear``,
``sun_angle``, ``position``, ``umbilical``, ``clock`` or ``rail``. A step with
both waits for its time, then for its condition; ``after_s: 0`` with a ``when``
therefore waits for the condition only once the previous step has fired. A step
with a ``note`` and no action is a checkpoint: it marks, in the run's report,
when something the instructor expects (a trip, the crew's response) happened.

Conditions: ``<source>.<field> <op> <value>`` joined by ``and``; ``op`` is one of
``< <= > >= == !=``; ``value`` a number, ``true``/``false``, or a word for text
fields (``rail.12V.state == tripped``). Sources: ``battery``, ``summary``,
``clock``, ``umbilical``, ``rail.<name>``, ``load.<name>``, ``solar.<panel>``,
``radio.<name>``. No ``eval``: the text is matched against this grammar only.
"""

from __future__ import annotations

import json
import math
import operator
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import msgspec
import msgspec.inspect as mi
import yaml

from common import keys
from common.config import ConfigError, Rover, YamlLoader, parse_yaml, read_text
from common.faults import FaultKey, parse_fault_key, parse_params
from common.messages import KEY_PAYLOADS, BadInput

__all__ = [
    "SOURCES",
    "Condition",
    "Player",
    "Scenario",
    "ScenarioError",
    "Step",
    "StepResult",
    "Write",
    "describe_action",
    "describe_trigger",
    "load_scenario",
    "parse_condition",
    "parse_scenario",
    "rover_id_of",
]

Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.-]+$")]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]
Positive = Annotated[float, msgspec.Meta(gt=0.0)]


class _Strict(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    pass


class ScenarioInfo(_Strict):
    name: str
    description: str = ""


class InjectAction(_Strict):
    component: str  # battery, umbilical, load/<name>, rail/<name>, solar/<panel>, radio/<name>
    kind: str
    value: Any = None  # a number for one-parameter kinds, or a mapping of parameters


class ClearAction(_Strict):
    component: str
    kind: str


class PositionAction(_Strict):
    radio: Name
    distance_m: Any  # metres, or a ramp {from, to, over_s}
    angle_deg: Any = 0.0  # degrees, or a ramp


class ClockAction(_Strict):
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    paused: bool | None = None


class RailAction(_Strict):
    name: Name
    on: bool | None = None
    reset: bool | None = None


class Step(_Strict):
    name: str = ""
    note: str = ""  # shown to the instructor when the step fires
    at_s: NonNegative | None = None
    after_s: NonNegative | None = None
    when: str | None = None
    timeout_s: Positive | None = None
    inject: InjectAction | None = None
    clear: ClearAction | None = None
    sun_angle: Any = None  # degrees, or a ramp {from, to, over_s}
    position: PositionAction | None = None
    umbilical: bool | None = None
    clock: ClockAction | None = None
    rail: RailAction | None = None


class Scenario(_Strict):
    scenario: ScenarioInfo
    rover: Annotated[str, msgspec.Meta(pattern=r"^[a-z0-9][a-z0-9_-]*$")]
    steps: list[Step]
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    duration_s: Positive | None = None


ACTIONS = ("inject", "clear", "sun_angle", "position", "umbilical", "clock", "rail")


class ScenarioError(ConfigError):
    """A scenario with problems; ``problems`` lists every one of them."""


# -- conditions -----------------------------------------------------------------------------

# source -> (key chunks after lunaris/<rover>/ with {name} for a named source, payload Struct)
SOURCES: dict[str, tuple[tuple[str, ...], type[msgspec.Struct]]] = {
    source: (chunks, KEY_PAYLOADS[chunks]) for source, chunks in (
        ("battery", ("battery", "state")),
        ("summary", ("power", "summary")),
        ("clock", ("clock",)),
        ("umbilical", ("umbilical", "state")),
        ("rail", ("rail", "{rail}", "state")),
        ("load", ("load", "{load}", "power")),
        ("solar", ("solar", "{panel}", "power")),
        ("radio", ("radio", "{radio}", "link")),
    )
}
_NAMED = {s for s, (parts, _) in SOURCES.items() if any(p.startswith("{") for p in parts)}
_OPS: dict[str, Callable[[Any, Any], bool]] = {
    "<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge,
    "==": operator.eq, "!=": operator.ne,
}
_COMPARISON = re.compile(r"^\s*(?P<ref>[A-Za-z][A-Za-z0-9_.\-]*)\s*(?P<op><=|>=|==|!=|<|>)\s*"
                         r"(?P<value>\S+)\s*$")
_WORD = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

Lookup = Callable[[tuple[str, ...]], dict | None]  # key chunks -> latest payload


def _field_kind(t: Any) -> tuple[str, tuple | None]:
    """``number``, ``bool`` or ``word`` (with the allowed words of a Literal), or ``other``."""
    if isinstance(t, mi.UnionType):
        members = [m for m in t.types if not isinstance(m, mi.NoneType)]
        return _field_kind(members[0]) if len(members) == 1 else ("other", None)
    if isinstance(t, mi.FloatType | mi.IntType):
        return "number", None
    if isinstance(t, mi.BoolType):
        return "bool", None
    if isinstance(t, mi.LiteralType):
        return "word", tuple(t.values)
    if isinstance(t, mi.StrType):
        return "word", None
    return "other", None


@dataclass(frozen=True)
class Comparison:
    source: str
    name: str | None
    field: str
    op: str
    value: float | bool | str

    @property
    def key_parts(self) -> tuple[str, ...]:
        parts = SOURCES[self.source][0]
        return tuple(self.name if p.startswith("{") else p for p in parts)

    @property
    def ref(self) -> str:
        return ".".join(p for p in (self.source, self.name, self.field) if p)

    def current(self, lookup: Lookup) -> Any:
        payload = lookup(self.key_parts)
        return None if payload is None else payload.get(self.field)

    def holds(self, lookup: Lookup) -> bool:
        current = self.current(lookup)
        if current is None:  # no telemetry yet, or a null (time to empty while charging)
            return False
        if isinstance(self.value, bool) != isinstance(current, bool):
            return False
        return bool(_OPS[self.op](current, self.value))


@dataclass(frozen=True)
class Condition:
    """``comparison (and comparison)*``: holds when every comparison holds."""

    text: str
    comparisons: tuple[Comparison, ...]

    def holds(self, lookup: Lookup) -> bool:
        return all(c.holds(lookup) for c in self.comparisons)

    def describe(self, lookup: Lookup) -> str:
        """The current values, for progress lines: ``battery.soc = 0.412``."""
        out = []
        for c in self.comparisons:
            v = c.current(lookup)
            out.append(f"{c.ref} = {v:.4g}" if isinstance(v, float) else f"{c.ref} = {v}")
        return ", ".join(out)


def parse_condition(text: str) -> Condition:
    """Parse a condition; raise ValueError saying what is wrong. Field names and value types
    are checked against the payload Structs of SPEC §5."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError("empty condition")
    comparisons = []
    for part in re.split(r"\s+and\s+", text.strip()):
        m = _COMPARISON.match(part)
        if m is None:
            raise ValueError(f"cannot read {part.strip()!r}: expected <source>.<field> <op> <value> "
                             f"with op one of {' '.join(_OPS)}")
        comparisons.append(_comparison(m["ref"], m["op"], m["value"]))
    return Condition(text.strip(), tuple(comparisons))


def _comparison(ref: str, op: str, raw: str) -> Comparison:
    source, _, rest = ref.partition(".")
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r} (sources: {', '.join(sorted(SOURCES))})")
    name: str | None = None
    if source in _NAMED:
        name, _, fld = rest.rpartition(".")  # a name may contain dots; a field never does
        if not name or not fld:
            raise ValueError(f"{source} needs a name and a field: {source}.<name>.<field>")
    else:
        fld = rest
        if not fld or "." in fld:
            raise ValueError(f"{source} has no names: {source}.<field>")
    struct = SOURCES[source][1]
    fields = {f.name: f for f in mi.type_info(struct).fields}
    if fld not in fields:
        raise ValueError(f"unknown field {fld!r} of {source} (fields: {', '.join(fields)})")
    kind, words = _field_kind(fields[fld].type)
    value: float | bool | str
    if kind == "number":
        try:
            value = float(raw)
        except ValueError:
            raise ValueError(f"{source}.{fld} is a number; cannot compare it with {raw!r}") from None
        if not math.isfinite(value):
            raise ValueError(f"{raw!r} is not a finite number")
    elif kind == "bool":
        if raw not in ("true", "false"):
            raise ValueError(f"{source}.{fld} is true or false; cannot compare it with {raw!r}")
        value = raw == "true"
    elif kind == "word":
        if not _WORD.match(raw):
            raise ValueError(f"{source}.{fld} is text; compare it with a word, got {raw!r}")
        if words is not None and raw not in words:
            raise ValueError(f"{source}.{fld} is one of {', '.join(words)}; got {raw!r}")
        value = raw
    else:
        raise ValueError(f"{source}.{fld} cannot be compared")
    if kind != "number" and op not in ("==", "!="):
        raise ValueError(f"{source}.{fld} can only be compared with == or !=")
    return Comparison(source, name, fld, op, value)


# -- loading and validation -----------------------------------------------------------------


def load_scenario(path: str | Path, rover: Rover | None = None) -> Scenario:
    return parse_scenario(read_text(path, ScenarioError), source=str(path), rover=rover)


def rover_id_of(text: str) -> str | None:
    """The ``rover`` a scenario text names, if it can be read (to find its definition first)."""
    try:
        data = yaml.load(text, Loader=YamlLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError:
        return None
    rover = data.get("rover") if isinstance(data, dict) else None
    return rover if isinstance(rover, str) else None


def parse_scenario(text: str, source: str = "<scenario>", rover: Rover | None = None) -> Scenario:
    """Validate scenario YAML; raise :class:`ScenarioError` listing every problem. With
    ``rover`` the names of loads, rails, panels and radios are checked too."""
    data, problems = parse_yaml(text, source, Scenario, ScenarioError)
    if isinstance(data, dict):
        if rover is not None and data.get("rover") not in (None, rover.id):
            problems.append(f"rover: the scenario is for {data.get('rover')!r}, "
                            f"the rover definition is {rover.id!r}")
        steps = data.get("steps")
        if isinstance(steps, list):
            if not steps:
                problems.append("steps: a scenario needs at least one step")
            for i, step in enumerate(steps):
                if isinstance(step, dict):
                    _step_problems(step, f"steps[{i}]", rover, problems)
    if problems:
        raise ScenarioError(source, problems)
    return msgspec.convert(data, Scenario)


def _names(rover: Rover) -> dict[str, list[str]]:
    return {
        "load": [ld.name for ld in rover.loads],
        "rail": [r.name for r in rover.rails] + [rover.solar.rail.name],
        "switchable rail": [r.name for r in rover.rails],
        "solar": [p.name for p in rover.solar.panels],
        "radio": [r.name for r in rover.radios],
    }


def _check_name(kind: str, name: str, rover: Rover | None, path: str, problems: list[str]) -> None:
    if rover is None:
        return
    known = _names(rover)[kind]
    if name not in known:
        what = {"solar": "panel", "switchable rail": "switchable rail"}.get(kind, kind)
        problems.append(f"{path}: rover {rover.id} has no {what} {name!r} "
                        f"(known: {', '.join(known) or 'none'})")


def _step_problems(step: dict, path: str, rover: Rover | None, problems: list[str]) -> None:
    if "at_s" in step and "after_s" in step:
        problems.append(f"{path}: give at_s or after_s, not both")
    if not any(k in step for k in ("at_s", "after_s", "when")):
        problems.append(f"{path}: give a trigger: at_s, after_s or when")
    if "timeout_s" in step and "when" not in step:
        problems.append(f"{path}.timeout_s: only a step with a when condition can time out")
    actions = [a for a in ACTIONS if step.get(a) is not None]
    if len(actions) > 1:
        problems.append(f"{path}: give one action per step, got {', '.join(actions)}")
    if not actions and not step.get("note"):
        problems.append(f"{path}: give an action ({', '.join(ACTIONS)}), or a note for a checkpoint")
    if isinstance(step.get("when"), str):
        try:
            cond = parse_condition(step["when"])
        except ValueError as exc:
            problems.append(f"{path}.when: {exc}")
        else:
            for c in cond.comparisons:
                if c.name is not None:
                    kind = {"load": "load", "rail": "rail", "solar": "solar", "radio": "radio"}[c.source]
                    _check_name(kind, c.name, rover, f"{path}.when", problems)
    for action in ("inject", "clear"):
        a = step.get(action)
        if isinstance(a, dict) and isinstance(a.get("component"), str) and isinstance(a.get("kind"), str):
            fk = _fault_problems(a, f"{path}.{action}", rover, problems)
            if fk is not None and action == "inject":
                value = a.get("value")
                payload = b"" if value is None else json.dumps(value).encode()
                try:
                    parse_params(fk, payload)
                except (BadInput, TypeError) as exc:
                    problems.append(f"{path}.inject.value: {exc}")
    if "sun_angle" in step and step["sun_angle"] is not None:
        _number_or_ramp(step["sun_angle"], f"{path}.sun_angle", -360.0, 360.0, problems)
    pos = step.get("position")
    if isinstance(pos, dict):
        if "distance_m" in pos:
            _number_or_ramp(pos["distance_m"], f"{path}.position.distance_m", 0.0, 1e9, problems)
        if "angle_deg" in pos:
            _number_or_ramp(pos["angle_deg"], f"{path}.position.angle_deg", -360.0, 360.0, problems)
        if isinstance(pos.get("radio"), str):
            _check_name("radio", pos["radio"], rover, f"{path}.position.radio", problems)
    clk = step.get("clock")
    if isinstance(clk, dict) and clk.get("time_scale") is None and clk.get("paused") is None:
        problems.append(f"{path}.clock: give time_scale (> 0) or paused (true or false)")
    rail = step.get("rail")
    if isinstance(rail, dict):
        if rail.get("on") is None and not rail.get("reset"):
            problems.append(f"{path}.rail: give on: true|false or reset: true")
        if isinstance(rail.get("name"), str):
            _check_name("switchable rail", rail["name"], rover, f"{path}.rail.name", problems)


def _fault_problems(a: dict, path: str, rover: Rover | None, problems: list[str]) -> FaultKey | None:
    parts = [p for p in a["component"].split("/") if p]
    try:
        fk = parse_fault_key([*parts, a["kind"]])
    except BadInput as exc:
        problems.append(f"{path}: {exc}")
        return None
    if fk.name is not None:
        _check_name(fk.component, fk.name, rover, f"{path}.component", problems)
    return fk


def _number_or_ramp(value: Any, path: str, lo: float, hi: float, problems: list[str]) -> None:
    def number(v: Any, where: str) -> None:
        if isinstance(v, bool) or not isinstance(v, int | float):
            problems.append(f"{where}: expected a number, got {type(v).__name__}")
        elif not math.isfinite(v) or not lo <= v <= hi:
            problems.append(f"{where}: must be within {lo:g}..{hi:g}, got {v}")

    if isinstance(value, dict):
        for k in value:
            if k not in ("from", "to", "over_s"):
                problems.append(f"{path}.{k}: unknown field (a ramp has from, to, over_s)")
        for k in ("from", "to", "over_s"):
            if k not in value:
                problems.append(f"{path}.{k}: missing required field")
        for k in ("from", "to"):
            if k in value:
                number(value[k], f"{path}.{k}")
        over = value.get("over_s")
        if "over_s" in value and (isinstance(over, bool) or not isinstance(over, int | float)
                                  or not math.isfinite(over) or over <= 0):
            problems.append(f"{path}.over_s: must be a number > 0, got {over!r}")
    else:
        number(value, path)


# -- playing ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Write:
    """A put (``payload`` bytes) or a delete (``payload`` None) the player asks for."""

    key: str
    payload: bytes | None
    step: int
    answer: str | None = None  # the event kind that accepts it (fault_injected ...), if any
    final: bool = True  # False for the intermediate values of a ramp


@dataclass
class StepResult:
    """What happened to one step."""

    index: int
    label: str
    armed_t_s: float | None = None  # when its time gate opened (relative to the start)
    fired_t_s: float | None = None  # relative to the start
    status: str = "waiting"  # waiting, armed, fired, ramping, done, timed out, not fired
    outcome: str = ""  # accepted, rejected, sent, no answer ... (set by the shell)
    detail: str = ""


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
        what = "reset" if step.rail.reset else ("on" if step.rail.on else "off")
        return f"rail {step.rail.name} {what}"
    return "checkpoint"


def describe_trigger(step: Step) -> str:
    parts = []
    if step.at_s is not None:
        parts.append(f"at {step.at_s:g} s")
    if step.after_s is not None:
        parts.append(f"{step.after_s:g} s after the previous step")
    if step.when is not None:
        parts.append(f"when {step.when}" + (f" (within {step.timeout_s:g} s)" if step.timeout_s else ""))
    return ", then ".join(parts)


class Player:
    """The scenario's clock-driven state machine. Call :meth:`tick` with every clock tick's
    ``t_s``; it returns the writes to make now. Times in results are relative to the first
    tick (the scenario's start)."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.rover = scenario.rover
        self.conditions = [parse_condition(s.when) if s.when else None for s in scenario.steps]
        self.results = [StepResult(i, s.name or describe_action(s)) for i, s in enumerate(scenario.steps)]
        self.t0: float | None = None
        self.t_rel = 0.0
        self._ramps: dict[int, float] = {}  # step -> start (relative)
        self.finished = False
        self.end_reason = ""

    def _gate(self, i: int) -> float | None:
        """When step ``i``'s time gate opens (relative), None while it cannot be known."""
        step = self.scenario.steps[i]
        if step.at_s is not None:
            return step.at_s
        if step.after_s is not None:
            if i == 0:
                return step.after_s
            prev = self.results[i - 1].fired_t_s
            return None if prev is None else prev + step.after_s
        return 0.0

    def tick(self, t_s: float, lookup: Lookup) -> list[Write]:
        if self.finished:
            return []
        if self.t0 is None:
            self.t0 = t_s
        t = self.t_rel = t_s - self.t0
        writes: list[Write] = []
        for i, step in enumerate(self.scenario.steps):
            r = self.results[i]
            if r.status not in ("waiting", "armed"):
                continue
            gate = self._gate(i)
            if gate is None or t < gate:
                continue
            if r.status == "waiting":
                r.status, r.armed_t_s = "armed", gate
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

    def _check_end(self, t: float) -> None:
        duration = self.scenario.duration_s
        if duration is not None and t >= duration:
            self.finish(f"duration of {duration:g} s reached")
            return
        if duration is None and all(r.status in ("fired", "done", "timed out") for r in self.results):
            self.finish("every step has played")
        elif duration is None and not self._ramps and not self._drop_blocked():
            self.finish("no remaining step can fire")

    def _drop_blocked(self) -> bool:
        """Mark the steps chained to a step that will never fire; True if any can still fire."""
        for i, r in enumerate(self.results):
            if r.status in ("waiting", "armed"):
                step = self.scenario.steps[i]
                blocked = (step.after_s is not None and i > 0
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
            if r.status in ("waiting", "armed"):
                r.status = "not fired"
            elif r.status == "ramping":
                r.status = "fired"
                r.detail = (r.detail + "; " if r.detail else "") + "ramp cut short"

    def writes_of(self, i: int, since_s: float, final: bool = True) -> list[Write]:
        """The writes of step ``i``'s action, ``since_s`` after it fired (for ramps)."""
        rover, step = self.rover, self.scenario.steps[i]
        if step.inject is not None:
            key = keys.fault(rover, step.inject.component.strip("/"), step.inject.kind)
            value = step.inject.value
            payload = b"" if value is None else json.dumps(value).encode()
            return [Write(key, payload, i, "fault_injected")]
        if step.clear is not None:
            return [Write(keys.fault(rover, step.clear.component.strip("/"), step.clear.kind), None, i,
                          "fault_cleared")]
        if step.sun_angle is not None:
            body = {"angle_deg": _at(step.sun_angle, since_s)}
            return [Write(keys.input_sun_angle(rover), json.dumps(body).encode(), i, None, final)]
        if step.position is not None:
            p = step.position
            body = {"distance_m": _at(p.distance_m, since_s), "angle_deg": _at(p.angle_deg, since_s)}
            return [Write(keys.input_radio_position(rover, p.radio), json.dumps(body).encode(), i, None,
                          final)]
        if step.umbilical is not None:
            body = {"connected": step.umbilical}
            return [Write(keys.input_umbilical(rover), json.dumps(body).encode(), i)]
        if step.clock is not None:
            body = {k: v for k, v in msgspec.structs.asdict(step.clock).items() if v is not None}
            return [Write(keys.clock_control(rover), json.dumps(body).encode(), i, "clock")]
        if step.rail is not None:
            body = {k: v for k, v in msgspec.structs.asdict(step.rail).items()
                    if k != "name" and v is not None}
            return [Write(keys.cmd_rail(rover, step.rail.name), json.dumps(body).encode(), i, "command")]
        return []
