"""Training scenarios: the YAML format and its validation.

Pure: no Zenoh, no clock. :func:`parse_scenario` validates a whole file and
reports every problem with its path (as :mod:`common.config` does for rovers);
:class:`common.scenario_player.Player` plays it.

A scenario::

    scenario: {name: Dust storm, description: ...}
    rover: mapp-1
    start: reset              # optional: first the rover back to its rover file, or
                              # {snapshot: NAME}: a saved snapshot restored
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

      - when: drive.odometer_m > 200
        traverse: {speed_m_per_s: 0.1, waypoints: [{x_m: 5, y_m: 0, z_m: 0}]}   # or: stop
      - after_s: 0
        traverse: {file: ../traverses/mapp-crater-rim.yaml}   # a traverse file (common.traverse)

      - name: crew isolates the camera                # an expectation of the crew, scored
        after_s: 0
        expect: {when: "rail.5V_CH2.state == off", within_s: 60, label: isolate the shorted camera}

A step has a time gate (``at_s`` or ``after_s``, optional), a condition (``when``,
optional; at least one of the two), and one action: ``inject``, ``clear``,
``sun_angle``, ``position``, ``umbilical``, ``clock``, ``rail`` or ``traverse`` (what
``input/drive/traverse`` takes, or ``{file: PATH}`` naming a traverse file, relative to the
scenario's folder; ``stop`` deletes it, and the rover stops). A step with
both waits for its time, then for its condition; ``after_s: 0`` with a ``when``
therefore waits for the condition only once the previous step has fired. A step
with a ``note`` and no action is a checkpoint: it marks, in the run's report,
when something the instructor expects (a trip, the crew's response) happened.

A step ``expect: {when, within_s, label}`` is an expectation of the crew (SPEC §12d), scored
rather than played: from when its time gate opens (``at_s``, ``after_s``, or, with neither,
when the previous step fires) the crew has ``within_s`` seconds of simulated time to make
``when`` hold; it is **met** at the first tick it holds (at once if it already does), or
**missed** when the time is up or the scenario ends first. It holds nothing up: the step after
it counts its ``after_s`` from when the expectation was armed, and the scenario goes on while
the crew has its time. Its condition is ``expect.when`` (a step-level ``when`` or ``timeout_s``
beside it is refused); ``label`` names it in the scores (default: the step's name, or the
condition). The runner journals each outcome (a ``scenario`` event) and the report and the
console show them (:mod:`common.response`).

Conditions are the language of :mod:`common.conditions`
(``battery.soc < 0.4 and rail.5V_CH2.state == on``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec

from common import keys
from common.conditions import parse_condition
from common.config import Rover
from common.datafile import (
    ID_PATTERN,
    ConfigError,
    Name,
    Strict,
    check_structure,
    load_yaml,
    parse_yaml,
    read_text,
)
from common.faults import FaultKey, parse_fault_key, parse_params
from common.messages import BadInput, DriveTraverse
from common.traverse import TraverseError, load_traverse, plan

__all__ = [
    "ACTIONS",
    "ExpectAction",
    "Scenario",
    "ScenarioError",
    "Step",
    "condition_problems",
    "describe_start",
    "fault_name_problem",
    "load_scenario",
    "parse_scenario",
    "rover_id_of",
]

NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]
Positive = Annotated[float, msgspec.Meta(gt=0.0)]


class ScenarioInfo(Strict, frozen=True):
    name: str
    description: str = ""


class InjectAction(Strict, frozen=True):
    component: str  # battery, umbilical, load/<name>, rail/<name>, solar/<panel>, radio/<name>
    kind: str
    value: Any = None  # a number for one-parameter kinds, or a mapping of parameters


class ClearAction(Strict, frozen=True):
    component: str
    kind: str


class PositionAction(Strict, frozen=True):
    radio: Name
    distance_m: Any  # metres, or a ramp {from, to, over_s}
    angle_deg: Any = 0.0  # degrees, or a ramp


class ClockAction(Strict, frozen=True):
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    paused: bool | None = None


class RailAction(Strict, frozen=True):
    name: Name
    on: bool | None = None
    reset: bool | None = None


class ExpectAction(Strict, frozen=True):
    """An expectation of the crew, scored met (at what time) or missed (SPEC §12d)."""

    when: Annotated[str, msgspec.Meta(description=(
        "the condition (as `when:` below) the crew is to make hold"))]
    within_s: Annotated[float, msgspec.Meta(gt=0.0, description=(
        "the crew's time from when the step is armed [s of simulated time]"))]
    label: Annotated[str, msgspec.Meta(max_length=200, description=(
        "what the crew is expected to do, in the scores (default: the step's name)"))] = ""


class Step(Strict, frozen=True):
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
    traverse: Any = None  # what input/drive/traverse takes, or "stop"
    expect: Annotated[ExpectAction | None, msgspec.Meta(description=(
        "an expectation of the crew instead of an action: armed by the time gate (at_s, "
        "after_s, or with neither when the previous step fires), met at the first tick `when` "
        "holds, missed after `within_s`; it holds nothing up (the next step's after_s counts "
        "from when it was armed)"))] = None

    @property
    def label(self) -> str:
        """An expectation's words in the scores: its label, the step's name, or its condition."""
        if self.expect is None:
            return self.name
        return self.expect.label or self.name or f"expect {self.expect.when}"


class StartFromSnapshot(Strict, frozen=True):
    snapshot: Annotated[str, msgspec.Meta(pattern=keys.SNAPSHOT_NAME.pattern)]


class Scenario(Strict, frozen=True):
    scenario: ScenarioInfo
    rover: Annotated[str, msgspec.Meta(pattern=ID_PATTERN)]
    steps: list[Step]
    start: Literal["reset"] | StartFromSnapshot | None = None
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    duration_s: Positive | None = None


ACTIONS = ("inject", "clear", "sun_angle", "position", "umbilical", "clock", "rail", "traverse",
           "expect")
STOP = "stop"


def describe_start(start: Literal["reset"] | StartFromSnapshot | None) -> str:
    """How a scenario starts, in words."""
    if start == "reset":
        return "from a reset: the rover back to its rover file"
    if isinstance(start, StartFromSnapshot):
        return f"from the snapshot {start.snapshot!r}"
    return "from the twin as it is"


class ScenarioError(ConfigError):
    """A scenario with problems; ``problems`` lists every one of them."""


# -- loading and validation -----------------------------------------------------------------


def load_scenario(path: str | Path, rover: Rover | None = None) -> Scenario:
    return parse_scenario(read_text(path, ScenarioError), source=str(path), rover=rover)


def rover_id_of(text: str) -> str | None:
    """The ``rover`` a scenario text names, if it can be read (to find its definition first)."""
    try:
        data = load_yaml(text, "<scenario>")
    except ConfigError:
        return None  # not YAML: parse_scenario says so with the file's name
    rover = data.get("rover") if isinstance(data, dict) else None
    return rover if isinstance(rover, str) else None


def parse_scenario(text: str, source: str = "<scenario>", rover: Rover | None = None) -> Scenario:
    """Validate scenario YAML; raise :class:`ScenarioError` listing every problem. With
    ``rover`` the names of loads, rails, panels and radios are checked too."""
    data, problems = parse_yaml(text, source, Scenario, ScenarioError)
    base = Path(source).parent if Path(source).is_file() else Path.cwd()  # of traverse files
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
                    _step_problems(step, f"steps[{i}]", rover, problems, base)
    if problems:
        raise ScenarioError(source, problems, data)
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


def _step_problems(step: dict, path: str, rover: Rover | None, problems: list[str],
                   base: Path) -> None:
    if "at_s" in step and "after_s" in step:
        problems.append(f"{path}: give at_s or after_s, not both")
    expecting = step.get("expect") is not None
    if not expecting and not any(k in step for k in ("at_s", "after_s", "when")):
        problems.append(f"{path}: give a trigger: at_s, after_s or when")
    if expecting:
        for k in ("when", "timeout_s"):
            if k in step:
                problems.append(f"{path}.{k}: an expect step's condition is expect.when and its "
                                "deadline expect.within_s; give no step-level when or timeout_s")
    elif "timeout_s" in step and "when" not in step:
        problems.append(f"{path}.timeout_s: only a step with a when condition can time out")
    actions = [a for a in ACTIONS if step.get(a) is not None]
    if len(actions) > 1:
        problems.append(f"{path}: give one action per step, got {', '.join(actions)}")
    if not actions and not step.get("note"):
        problems.append(f"{path}: give an action ({', '.join(ACTIONS)}), or a note for a checkpoint")
    if isinstance(step.get("when"), str):
        _condition_problems(step["when"], f"{path}.when", rover, problems)
    expect = step.get("expect")
    if isinstance(expect, dict) and isinstance(expect.get("when"), str):
        _condition_problems(expect["when"], f"{path}.expect.when", rover, problems)
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
            if rover is not None and rover.drive is not None and any(
                    r.name == pos["radio"] and r.site is not None for r in rover.radios):
                problems.append(f"{path}.position.radio: radio {pos['radio']} of {rover.id} follows "
                                "the rover's drive (it has a site): move the rover with a traverse step")
    clk = step.get("clock")
    if isinstance(clk, dict) and clk.get("time_scale") is None and clk.get("paused") is None:
        problems.append(f"{path}.clock: give time_scale (> 0) or paused (true or false)")
    if isinstance(step.get("traverse"), dict) and "file" in step["traverse"]:
        step["traverse"] = _traverse_file(step["traverse"], f"{path}.traverse", base, problems)
    if step.get("traverse") is not None:
        _traverse_problems(step["traverse"], f"{path}.traverse", rover, problems)
    rail = step.get("rail")
    if isinstance(rail, dict):
        if rail.get("on") is None and not rail.get("reset"):
            problems.append(f"{path}.rail: give on: true|false or reset: true")
        if isinstance(rail.get("name"), str):
            _check_name("switchable rail", rail["name"], rover, f"{path}.rail.name", problems)


def _condition_problems(text: str, path: str, rover: Rover | None, problems: list[str]) -> None:
    """A condition's grammar, and the names it uses against the rover's."""
    try:
        cond = parse_condition(text)
    except ValueError as exc:
        problems.append(f"{path}: {exc}")
        return
    for c in cond.comparisons:
        if c.source == "drive":
            _check_drives(rover, path, problems)
        if c.name is not None:
            kind = {"load": "load", "rail": "rail", "solar": "solar", "radio": "radio"}[c.source]
            _check_name(kind, c.name, rover, path, problems)


def condition_problems(text: str, rover: Rover | None = None) -> list[str]:
    """What is wrong with a ``when:`` condition, in words: its grammar, and the names it uses
    against the rover's (an armed fault's condition is checked as a step's is)."""
    problems: list[str] = []
    _condition_problems(text, "when", rover, problems)
    return problems


def fault_name_problem(fk: FaultKey, rover: Rover) -> str | None:
    """Why the component a fault key names is not the rover's, in words; None when it is."""
    problems: list[str] = []
    if fk.name is not None:
        _check_name(fk.component, fk.name, rover, "component", problems)
    return problems[0] if problems else None


def _check_drives(rover: Rover | None, path: str, problems: list[str]) -> None:
    if rover is not None and rover.drive is None:
        problems.append(f"{path}: rover {rover.id} has no drive section: it does not drive")


def _traverse_file(value: dict, path: str, base: Path, problems: list[str]) -> Any:
    """The traverse of ``{file: PATH}``, as ``input/drive/traverse`` takes it; or None with
    the problems noted."""
    if set(value) != {"file"} or not isinstance(value["file"], str):
        problems.append(f"{path}: a traverse from a file is {{file: PATH}} alone, got {value!r}")
        return None
    try:
        traverse = load_traverse(base / value["file"])
    except TraverseError as exc:
        problems += [f"{path}.file: {exc.source}: {p}" for p in exc.problems]
        return None
    return msgspec.to_builtins(traverse.command())


def _traverse_problems(value: Any, path: str, rover: Rover | None, problems: list[str]) -> None:
    """A traverse step: ``stop``, or what ``input/drive/traverse`` takes. Its speeds and the
    grades between its waypoints are checked against the rover's drive; the first leg starts
    wherever the rover is when the step fires, so it is checked then, by the drive."""
    _check_drives(rover, path, problems)
    if value == STOP:
        return
    if not isinstance(value, dict):
        problems.append(f"{path}: expected {STOP} or a traverse (waypoints, speed_m_per_s, "
                        f"return_to_start), got {value!r}")
        return
    found: list[str] = []
    check_structure(value, DriveTraverse, found)
    problems += [f"{path}.{p}" for p in found]
    if found or rover is None or rover.drive is None:
        return
    cmd = msgspec.convert(value, DriveTraverse)
    first = cmd.waypoints[0] if cmd.waypoints else None
    start = (first.x_m, first.y_m, first.z_m) if first is not None else (0.0, 0.0, 0.0)
    problems += [f"{path}.{p}" for p in plan(cmd, rover.drive, start)[1]]


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
