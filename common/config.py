"""Rover definitions: the YAML of SPEC §3 as typed, validated msgspec Structs.

Loading checks the whole file and reports every problem at once, each with its
path (``battery.ocv_curve.volts: expected 11 values, got 10``), so a vehicle
engineer fixes a file in one pass. Validation is driven by the Struct
annotations below (types, ranges, name patterns) plus the cross-field rules in
:func:`_semantic_problems`; nothing here knows about Zenoh.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Annotated, Any

import msgspec
import msgspec.inspect as mi
import yaml

__all__ = [
    "Battery",
    "ConfigError",
    "Load",
    "OcvCurve",
    "Panel",
    "Radio",
    "Rail",
    "Rover",
    "RoverInfo",
    "Solar",
    "SolarRail",
    "Thermal",
    "Umbilical",
    "YamlLoader",
    "budget_warnings",
    "check_structure",
    "load_rover",
    "parse_rover",
    "parse_yaml",
    "read_text",
]

# A name becomes a chunk of a key expression: no '/', wildcards or spaces.
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.-]+$")]
Fraction = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Positive = Annotated[float, msgspec.Meta(gt=0.0)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]
Efficiency = Annotated[float, msgspec.Meta(gt=0.0, le=1.0)]


class _Strict(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    pass


class RoverInfo(_Strict):
    id: Annotated[str, msgspec.Meta(pattern=r"^[a-z0-9][a-z0-9_-]*$")]
    name: str


class OcvCurve(_Strict):
    """Per-cell open-circuit voltage [V] against state of charge [0..1]."""

    soc: list[Fraction]
    volts: list[NonNegative]


class Thermal(_Strict):
    initial_c: float
    environment_c: float
    heat_capacity_j_per_k: Positive
    conductance_w_per_k: NonNegative
    max_c: float
    cutoff_c: float
    min_c: float


class Battery(_Strict):
    capacity_j: Positive
    initial_soc: Fraction
    cells_series: Annotated[int, msgspec.Meta(ge=1)]
    ocv_curve: OcvCurve
    internal_resistance_ohm: NonNegative
    max_discharge_a: Positive
    max_charge_w: NonNegative
    thermal: Thermal
    depleted_soc: Fraction = 0.0
    # Charging back above depleted_soc + this brings the pack back on line, so a
    # pack at the threshold does not chatter on and off.
    depleted_hysteresis_soc: Fraction = 0.05


class Rail(_Strict):
    name: Name
    voltage_v: Positive
    current_limit_a: Positive
    efficiency: Efficiency
    essential: bool = False
    shed_below_soc: Fraction | None = None
    # Restored when the state of charge climbs back to this; default shed + 0.05.
    restore_above_soc: Fraction | None = None
    initially_on: bool = True


class Load(_Strict):
    name: Name
    rail: Name
    nominal_w: NonNegative
    max_w: NonNegative
    std_w: NonNegative = 0.0


class Panel(_Strict):
    name: Name
    area_m2: NonNegative
    efficiency: Fraction
    degradation: Fraction = 0.0  # ageing and radiation damage


class SolarRail(_Strict):
    name: Name
    voltage_v: Positive
    efficiency: Efficiency
    current_limit_a: Positive | None = None


class Solar(_Strict):
    irradiance_w_per_m2: NonNegative
    sun_angle_deg: float
    rail: SolarRail
    panels: list[Panel] = []


class Umbilical(_Strict):
    connected: bool = False
    power_w: NonNegative = 0.0


class Radio(_Strict):
    name: Name
    a_m: Positive
    b_m: Positive
    offset_x_m: float = 0.0
    offset_y_m: float = 0.0


class Rover(_Strict):
    rover: RoverInfo
    battery: Battery
    solar: Solar
    tick_hz: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)] = 10.0
    rails: list[Rail] = []
    loads: list[Load] = []
    umbilical: Umbilical = Umbilical()
    radios: list[Radio] = []

    @property
    def id(self) -> str:
        return self.rover.id


def budget_warnings(rover: Rover) -> list[str]:
    """What is valid but likely wrong: a rail whose loads, all at ``max_w``, draw more than its
    current limit, so it can trip in normal operation."""
    warnings = []
    for rail in rover.rails:
        peak_w = sum(ld.max_w for ld in rover.loads if ld.rail == rail.name)
        if peak_w / rail.voltage_v > rail.current_limit_a:
            warnings.append(
                f"rails.{rail.name}: its loads can draw {peak_w / rail.voltage_v:.1f} A "
                f"(sum of max_w {peak_w:g} W at {rail.voltage_v:g} V), above current_limit_a "
                f"{rail.current_limit_a:g} A: it may trip in normal operation")
    return warnings


class ConfigError(ValueError):
    """A rover definition with problems; ``problems`` lists every one of them."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = problems
        lines = "\n".join(f"  {p}" for p in problems)
        super().__init__(f"{source}: {len(problems)} problem(s)\n{lines}")


def read_text(path: str | Path, error: type[ConfigError] = ConfigError) -> str:
    """A data file's text; an unreadable file is a problem like any other."""
    try:
        return Path(path).read_text()
    except OSError as exc:
        raise error(str(path), [f"cannot read file: {exc.strerror}"]) from None


def parse_yaml(text: str, source: str, struct: type[msgspec.Struct],
               error: type[ConfigError] = ConfigError) -> tuple[Any, list[str]]:
    """Parse a Lunaris data file (rover, bridge mapping, scenario) and check it against
    ``struct``: the data and every structural problem found. Invalid YAML raises ``error``."""
    try:
        data = yaml.load(text, Loader=YamlLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise error(source, [f"not valid YAML: {exc}"]) from None
    problems: list[str] = []
    check_structure(data, struct, problems)
    return data, problems


def load_rover(path: str | Path) -> Rover:
    """Read and validate a rover YAML file; raise :class:`ConfigError` listing every problem."""
    return parse_rover(read_text(path), source=str(path))


def parse_rover(text: str, source: str = "<rover>") -> Rover:
    """Validate rover YAML text; raise :class:`ConfigError` listing every problem."""
    data, problems = parse_yaml(text, source, Rover)
    if isinstance(data, dict):
        problems.extend(_semantic_problems(data))
    if problems:
        raise ConfigError(source, problems)
    return msgspec.convert(data, Rover)


class YamlLoader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 scalars, for every Lunaris data file: ``5.3e5`` is a number
    (YAML 1.1 makes it a string) and only ``true``/``false`` are booleans (YAML 1.1 also
    reads ``on``, ``off``, ``yes``, ``no`` as booleans, which would turn a key ``on:`` into
    ``True:``)."""


_BOOL = "tag:yaml.org,2002:bool"
YamlLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != _BOOL]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
YamlLoader.add_implicit_resolver(_BOOL, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                                 list("tTfF"))
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


# -- structural validation, driven by the Struct annotations -------------------------------


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a mapping"}.get(type(value), type(value).__name__)


def _check_bounds(value: float, t: Any, path: str, problems: list[str]) -> None:
    where = path or "value"
    if t.ge is not None and value < t.ge:
        problems.append(f"{where}: must be >= {t.ge}, got {value}")
    if t.gt is not None and value <= t.gt:
        problems.append(f"{where}: must be > {t.gt}, got {value}")
    if t.le is not None and value > t.le:
        problems.append(f"{where}: must be <= {t.le}, got {value}")
    if t.lt is not None and value >= t.lt:
        problems.append(f"{where}: must be < {t.lt}, got {value}")


def check_structure(data: Any, struct: type[msgspec.Struct], problems: list[str]) -> None:
    """Check parsed YAML against a Struct's annotations (types, ranges, name patterns,
    unknown and missing fields), appending every problem with its path to ``problems``."""
    _check(data, mi.type_info(struct), "", problems)


def _check(value: Any, t: Any, path: str, problems: list[str]) -> None:
    where = path or "file"
    if isinstance(t, mi.UnionType):
        if value is None and any(isinstance(m, mi.NoneType) for m in t.types):
            return
        members = [m for m in t.types if not isinstance(m, mi.NoneType)]
        _check(value, members[0], path, problems)
    elif isinstance(t, mi.StructType):
        if not isinstance(value, dict):
            problems.append(f"{where}: expected a mapping, got {_kind(value)}")
            return
        known = {f.encode_name for f in t.fields}
        for key in value:
            if key not in known:
                problems.append(f"{_join(path, str(key))}: unknown field")
        for f in t.fields:
            if f.encode_name in value:
                _check(value[f.encode_name], f.type, _join(path, f.encode_name), problems)
            elif f.required:
                problems.append(f"{_join(path, f.encode_name)}: missing required field")
    elif isinstance(t, mi.ListType):
        if not isinstance(value, list):
            problems.append(f"{where}: expected a list, got {_kind(value)}")
            return
        for i, item in enumerate(value):
            _check(item, t.item_type, f"{path}[{i}]", problems)
    elif isinstance(t, mi.FloatType | mi.IntType):
        want_int = isinstance(t, mi.IntType)
        ok = isinstance(value, int) if want_int else isinstance(value, int | float)
        if isinstance(value, bool) or not ok:
            problems.append(
                f"{where}: expected {'an integer' if want_int else 'a number'}, got {_kind(value)}"
            )
            return
        if not math.isfinite(value):
            problems.append(f"{where}: must be finite, got {value}")
            return
        _check_bounds(value, t, path, problems)
    elif isinstance(t, mi.StrType):
        if not isinstance(value, str):
            problems.append(f"{where}: expected a string, got {_kind(value)}")
        elif t.pattern is not None and re.search(t.pattern, value) is None:
            problems.append(
                f"{where}: {value!r} is not a valid name (letters, digits, '_', '-', '.')"
            )
    elif isinstance(t, mi.BoolType):
        if not isinstance(value, bool):
            problems.append(f"{where}: expected true or false, got {_kind(value)}")


# -- cross-field rules ---------------------------------------------------------------------


def _semantic_problems(d: dict) -> list[str]:
    """Cross-field rules. Each group runs on whatever parts are well formed: a part that is
    missing or of the wrong type has already been reported by the structural check."""
    problems: list[str] = []
    for rule in (_battery_rules, _rail_rules, _load_rules, _name_rules):
        try:
            rule(d, problems)
        except (KeyError, TypeError, AttributeError, IndexError):
            pass
    return problems


def _battery_rules(d: dict, problems: list[str]) -> None:
    bat = d["battery"]
    th = bat["thermal"]
    if not th["min_c"] < th["max_c"] < th["cutoff_c"]:
        problems.append(
            "battery.thermal: expected min_c < max_c < cutoff_c, got "
            f"{th['min_c']}, {th['max_c']}, {th['cutoff_c']}"
        )
    curve = bat["ocv_curve"]
    soc, volts = curve["soc"], curve["volts"]
    if len(volts) != len(soc):
        problems.append(
            f"battery.ocv_curve.volts: expected {len(soc)} values, got {len(volts)}"
        )
    if any(b < a for a, b in zip(volts, volts[1:], strict=False)):
        problems.append("battery.ocv_curve.volts: must not decrease as the charge rises")
    if len(soc) < 2:
        problems.append(f"battery.ocv_curve.soc: expected at least 2 points, got {len(soc)}")
        return
    if any(b <= a for a, b in zip(soc, soc[1:], strict=False)):
        problems.append("battery.ocv_curve.soc: must be strictly increasing")
    if soc[0] != 0.0 or soc[-1] != 1.0:
        problems.append(
            f"battery.ocv_curve.soc: must run from 0.0 to 1.0, got {soc[0]}..{soc[-1]}"
        )


def _rail_rules(d: dict, problems: list[str]) -> None:
    for i, r in enumerate(d.get("rails") or []):
        shed, restore = r.get("shed_below_soc"), r.get("restore_above_soc")
        if restore is not None and shed is None:
            problems.append(f"rails[{i}].restore_above_soc: needs shed_below_soc")
        if shed is not None and restore is not None and restore <= shed:
            problems.append(
                f"rails[{i}].restore_above_soc: must be above shed_below_soc ({shed}), "
                f"got {restore}"
            )
        if shed is not None and r.get("essential"):
            problems.append(f"rails[{i}].shed_below_soc: an essential rail is never shed")


def _load_rules(d: dict, problems: list[str]) -> None:
    rail_names = [r["name"] for r in d.get("rails") or []]
    for i, ld in enumerate(d.get("loads") or []):
        if ld["rail"] not in rail_names:
            problems.append(
                f"loads[{i}].rail: no rail named {ld['rail']!r} (rails: {', '.join(rail_names)})"
            )
        if ld["nominal_w"] > ld["max_w"]:
            problems.append(
                f"loads[{i}].nominal_w: must not exceed max_w ({ld['max_w']}), "
                f"got {ld['nominal_w']}"
            )


def _name_rules(d: dict, problems: list[str]) -> None:
    rails = [r["name"] for r in d.get("rails") or []]
    solar = d.get("solar") or {}
    solar_rail = (solar.get("rail") or {}).get("name")
    _unique("rails", rails + ([solar_rail] if solar_rail else []), problems)
    _unique("loads", [ld["name"] for ld in d.get("loads") or []], problems)
    _unique("solar.panels", [p["name"] for p in solar.get("panels") or []], problems)
    _unique("radios", [r["name"] for r in d.get("radios") or []], problems)


def _unique(path: str, names: list[str], problems: list[str]) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            problems.append(f"{path}: name {name!r} is used more than once")
        seen.add(name)
