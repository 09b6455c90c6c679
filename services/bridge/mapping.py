"""The bridge's mapping file: its format, its validation, and its expansion over rovers.

:func:`parse_mapping` validates a whole mapping file and names every problem
(``mappings[3].field: BatteryState has no field 'volts'``) as rover definitions do;
:func:`expand` turns each mapping into one :class:`Binding` per rover and per component
(``{load}``, ``{rail}``, ``{radio}``, ``{panel}`` placeholders run over the rover's
components), checking the resulting ROS 2 names. The twin keys a mapping may name are the
families of :mod:`common.keys`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any, NamedTuple

import msgspec
import msgspec.inspect as mi

from common import keys
from common.config import Rover
from common.datafile import ConfigError, Strict, field_kind, parse_yaml, read_text
from services.bridge.cdr import ARRAY_TYPES, INT_RANGES, SCALAR_TYPES, constants, typestore

__all__ = [
    "CONVERTERS",
    "FLAVOURS",
    "PLACEHOLDERS",
    "Binding",
    "BridgeOptions",
    "Mapping",
    "MappingFile",
    "RoverNames",
    "expand",
    "load_mapping",
    "parse_mapping",
    "ros_name",
    "rover_names",
]

FLAVOURS = ("ros2dds", "rmw_zenoh", "json")
PLACEHOLDERS = keys.PLACEHOLDERS  # component placeholders; {rover} is always there
_PLACEHOLDER = re.compile(r"\{([a-z_]*)\}")


# == the mapping file ========================================================================


class Ros2DdsOutput(Strict):
    """Key = topic without the leading ``/``: what ``zenoh-bridge-ros2dds`` forwards to DDS."""

    enabled: bool = True


class RmwZenohOutput(Strict):
    """A ROS 2 node on ``rmw_zenoh``: keyed topics, attachments, liveliness tokens."""

    enabled: bool = True
    domain_id: int = 0  # ROS_DOMAIN_ID
    node: str = "lunaris_bridge"  # the node that owns the bridge's publishers
    namespace: str = "/"


class JsonOutput(Strict):
    """Key = ``prefix/`` + topic without the leading ``/``; the ROS message fields as JSON."""

    enabled: bool = True
    prefix: str = "json"


class Outputs(Strict):
    ros2dds: Ros2DdsOutput = Ros2DdsOutput()
    rmw_zenoh: RmwZenohOutput = RmwZenohOutput()
    json: JsonOutput = JsonOutput()


class BridgeOptions(Strict):
    ros_distro: str = "jazzy"  # jazzy: RIHS01 type hashes; humble: TypeHashNotSupported
    topic_prefix: str = ""  # before every topic when the bridge serves one rover
    fleet_topic_prefix: str = "/{rover}"  # instead, when it serves several
    stamp: str = "wall"  # header stamps: wall clock (ROS default) or sim (the twin's t_s)
    diagnostics_period_s: float = 1.0  # the DiagnosticArray is also republished this often
    stale_after_s: float = 3.0  # a component silent this long is STALE
    outputs: Outputs = Outputs()


class Mapping(Strict):
    """One line of the mapping: a twin key and a dashboard topic."""

    topic: str  # absolute ROS 2 topic; may hold {rover} and the key's component placeholder
    type: str  # ROS 2 message type, pkg/msg/Name
    key: str  # twin key, lunaris/{rover}/...; {load} {rail} {radio} {panel} run over components
    direction: str = "out"  # out: twin -> dashboard; in: dashboard -> twin
    field: str | None = None  # the payload field of a one-value message (std_msgs data)
    fields: list[str] | None = None  # the payload fields of a MultiArray, in order
    scale: float = 1.0  # out: ROS value = twin value x scale; in: twin value = ROS value x scale
    integer: bool | None = None  # round half away from zero; default: true for integer types
    default: float | None = None  # published when the field is null; by default nothing is
    convert: str | None = None  # a whole-message converter: battery_state, diagnostics
    frame_id: str = ""  # header.frame_id of messages that have a header
    options: dict[str, str] = {}  # converter options (battery_state: technology, location, ...)
    label: str | None = None  # how the dashboard names the value (lunaris pdm)
    unit: str | None = None
    group: str | None = None  # pdm: part of the PDM device distribution


class MappingFile(Strict):
    mappings: list[Mapping]
    bridge: BridgeOptions = BridgeOptions()

class Converter(NamedTuple):
    type: str
    shape: tuple[str, ...]
    options: frozenset[str]


CONVERTERS: dict[str, Converter] = {
    "battery_state": Converter("sensor_msgs/msg/BatteryState", ("battery", "state"),
                               frozenset({"technology", "location", "serial_number"})),
    "diagnostics": Converter("diagnostic_msgs/msg/DiagnosticArray", ("event",), frozenset()),
}

# -- parsing and validation ---------------------------------------------------------------------

_ROS_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_ROS_TOPIC = re.compile(rf"^(/{_ROS_TOKEN})+$")
_ROS_NODE = re.compile(rf"^{_ROS_TOKEN}$")


def ros_name(value: str) -> str:
    """A twin name made fit for a ROS 2 topic: every character but letters, digits and ``_``
    becomes ``_`` (``mapp-1`` -> ``mapp_1``)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", value)


def load_mapping(path: str | Path) -> MappingFile:
    """Read and validate a mapping file; raise :class:`ConfigError` listing every problem."""
    return parse_mapping(read_text(path), source=str(path))


def parse_mapping(text: str, source: str = "<mapping>") -> MappingFile:
    """Validate mapping YAML text; raise :class:`ConfigError` listing every problem."""
    data, problems = parse_yaml(text, source, MappingFile)
    if not isinstance(data, dict):
        raise ConfigError(source, problems)
    options = _convert(data.get("bridge", {}), BridgeOptions)
    if options is not None:
        problems += _option_problems(options)
    raw_mappings = data.get("mappings")
    if isinstance(raw_mappings, list):
        if not raw_mappings:
            problems.append("mappings: expected at least one mapping")
        distro = options.ros_distro if options is not None and options.ros_distro in (
            "jazzy", "humble") else "jazzy"
        seen: dict[tuple[str, str], int] = {}
        for i, raw in enumerate(raw_mappings):
            m = _convert(raw, Mapping)
            if m is None:
                continue
            problems += [f"mappings[{i}].{p}" for p in _mapping_problems(m, distro)]
            first = seen.setdefault((m.direction, m.topic), i)
            if first != i:
                problems.append(f"mappings[{i}].topic: {m.topic} is already mapped by "
                                f"mappings[{first}]")
    if problems:
        raise ConfigError(source, problems)
    return msgspec.convert(data, MappingFile)


def _convert(raw: Any, typ: type) -> Any:
    try:
        return msgspec.convert(raw, typ)
    except (msgspec.ValidationError, TypeError):
        return None  # already reported by the structural check


def _option_problems(o: BridgeOptions) -> list[str]:
    problems = []
    if o.ros_distro not in ("jazzy", "humble"):
        problems.append(f"bridge.ros_distro: expected jazzy or humble, got {o.ros_distro!r}")
    if o.stamp not in ("wall", "sim"):
        problems.append(f"bridge.stamp: expected wall or sim, got {o.stamp!r}")
    for name in ("topic_prefix", "fleet_topic_prefix"):
        prefix = getattr(o, name)
        problems += [f"bridge.{name}: {p}" for p in _topic_problems(prefix, allow_empty=True)]
        if set(_placeholders(prefix)) - {"rover"}:
            problems.append(f"bridge.{name}: only {{rover}} may appear in a prefix")
    if "{rover}" not in o.fleet_topic_prefix:
        problems.append("bridge.fleet_topic_prefix: must contain {rover}, or the rovers of a "
                        "fleet would publish on the same topics")
    for name in ("diagnostics_period_s", "stale_after_s"):
        if not getattr(o, name) > 0.0:
            problems.append(f"bridge.{name}: must be > 0, got {getattr(o, name)}")
    out = o.outputs
    if not (out.ros2dds.enabled or out.rmw_zenoh.enabled or out.json.enabled):
        problems.append("bridge.outputs: every output is disabled")
    if not 0 <= out.rmw_zenoh.domain_id <= 232:
        problems.append(f"bridge.outputs.rmw_zenoh.domain_id: expected 0..232, "
                        f"got {out.rmw_zenoh.domain_id}")
    if not _ROS_NODE.match(out.rmw_zenoh.node):
        problems.append(f"bridge.outputs.rmw_zenoh.node: {out.rmw_zenoh.node!r} is not a ROS 2 "
                        "node name")
    if out.rmw_zenoh.namespace != "/":
        problems += [f"bridge.outputs.rmw_zenoh.namespace: {p}"
                     for p in _topic_problems(out.rmw_zenoh.namespace)]
    prefix = out.json.prefix
    if out.json.enabled and out.ros2dds.enabled and not prefix:
        problems.append("bridge.outputs.json.prefix: the json and ros2dds outputs would share "
                        "their keys; give json a prefix")
    elif prefix and not re.fullmatch(r"[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*", prefix):
        problems.append(f"bridge.outputs.json.prefix: {prefix!r} is not a key prefix")
    return problems


def _placeholders(template: str) -> list[str]:
    return _PLACEHOLDER.findall(template)


def _topic_problems(topic: str, allow_empty: bool = False) -> list[str]:
    if allow_empty and topic == "":
        return []
    sample = _PLACEHOLDER.sub("x", topic)
    if not sample.startswith("/"):
        return [f"{topic!r} must start with '/' (an absolute ROS 2 name)"]
    if not _ROS_TOPIC.match(sample):
        return [f"{topic!r} is not a ROS 2 name (tokens of letters, digits and '_', "
                "not starting with a digit, separated by '/')"]
    return []


def _payload_fields(payload: type[msgspec.Struct]) -> dict[str, Any]:
    return {f.name: f for f in mi.type_info(payload).fields}


def _field_kind(field: Any) -> str:
    kind, _ = field_kind(field.type)
    return kind if kind != "word" else "other"


def _mapping_problems(m: Mapping, distro: str) -> list[str]:
    """Problems of one mapping, each starting with the field it is about."""
    problems: list[str] = []
    problems += [f"topic: {p}" for p in _topic_problems(m.topic)]
    if m.direction not in ("out", "in"):
        problems.append(f"direction: expected out or in, got {m.direction!r}")
    store = typestore(distro)
    if m.type not in store.fielddefs:
        problems.append(f"type: unknown ROS 2 message type {m.type!r} (pkg/msg/Name)")
    if not math.isfinite(m.scale) or m.scale == 0.0:
        problems.append(f"scale: must be a finite non-zero number, got {m.scale}")

    found = keys.family_of_template(m.key)
    if found is None:
        problems.append(f"key: {m.key!r} is not a twin key the bridge knows (lunaris/{{rover}}/"
                        f"...: {', '.join(f.name for f in keys.FAMILIES)})")
        return problems
    shape, item = found
    unknown = set(_placeholders(m.key)) - {"rover", *PLACEHOLDERS}
    unknown |= set(_placeholders(m.topic)) - {"rover", *PLACEHOLDERS}
    if unknown:
        problems.append(f"key: unknown placeholder(s) {', '.join(sorted(unknown))}")
    key_item = shape.placeholder if item is not None and item.startswith("{") else None
    extra = set(_placeholders(m.topic)) - {"rover"} - ({key_item} if key_item else set())
    if extra:
        problems.append(f"topic: {', '.join('{' + e + '}' for e in sorted(extra))} "
                        "does not appear in the key")
    if key_item and f"{{{key_item}}}" not in m.topic:
        problems.append(f"topic: must contain {{{key_item}}} like the key, or every {key_item} "
                        "would publish on the same topic")
    if m.direction in ("out", "in") and shape.direction != m.direction:
        problems.append(f"direction: {m.key} is {'an input' if shape.direction == 'in' else 'telemetry'}"
                        f", so the direction is {shape.direction}")

    if m.convert is not None:
        conv = CONVERTERS.get(m.convert)
        if conv is None:
            problems.append(f"convert: unknown converter {m.convert!r} "
                            f"(known: {', '.join(sorted(CONVERTERS))})")
            return problems
        if m.type != conv.type:
            problems.append(f"type: the {m.convert} converter makes {conv.type}, not {m.type}")
        if shape.chunks != conv.shape:
            problems.append(f"key: the {m.convert} converter reads lunaris/{{rover}}/"
                            f"{'/'.join(conv.shape)}")
        for name, value, unset in (("field", m.field, None), ("fields", m.fields, None),
                                   ("scale", m.scale, 1.0), ("integer", m.integer, None),
                                   ("default", m.default, None)):
            if value != unset:
                problems.append(f"{name}: not used with convert: {m.convert}")
        for opt in sorted(set(m.options) - conv.options):
            problems.append(f"options.{opt}: unknown option of {m.convert} "
                            f"(known: {', '.join(sorted(conv.options)) or 'none'})")
        tech = m.options.get("technology")
        if tech is not None and f"POWER_SUPPLY_TECHNOLOGY_{tech}" not in constants(
                distro, "sensor_msgs/msg/BatteryState"):
            problems.append(f"options.technology: unknown technology {tech!r} (LION, LIPO, ...)")
        return problems
    if m.options:
        problems.append("options: only converters take options")

    fields = _payload_fields(shape.payload)
    name = shape.payload.__name__
    if m.type in SCALAR_TYPES:
        if m.fields is not None:
            problems.append(f"fields: {m.type} carries one value; use field")
        if m.field is None:
            problems.append(f"field: which field of {name} goes in {m.type}?")
        elif m.field not in fields:
            problems.append(f"field: {name} has no field {m.field!r} "
                            f"(fields: {', '.join(fields)})")
        else:
            kind = _field_kind(fields[m.field])
            want_bool = SCALAR_TYPES[m.type] == "bool"
            if kind == "other" or (kind == "bool") != want_bool:
                problems.append(f"field: {name}.{m.field} is {'not ' if want_bool else ''}"
                                f"a {'boolean' if want_bool else 'number'}; {m.type} "
                                f"carries a {'boolean' if want_bool else 'number'}")
    elif m.type in ARRAY_TYPES:
        if m.field is not None:
            problems.append(f"field: {m.type} carries several values; use fields")
        if not m.fields:
            problems.append(f"fields: which fields of {name} go in {m.type}, in order?")
        for f in m.fields or []:
            if f not in fields:
                problems.append(f"fields: {name} has no field {f!r} (fields: {', '.join(fields)})")
            elif _field_kind(fields[f]) != "number":
                problems.append(f"fields: {name}.{f} is not a number")
    elif m.type in store.fielddefs:
        problems.append(f"type: {m.type} needs a converter (convert: ...); plain mappings take "
                        "std_msgs one-value and MultiArray types")
    integer_type = SCALAR_TYPES.get(m.type, ARRAY_TYPES.get(m.type, "")) in INT_RANGES
    if integer_type and m.integer is False:
        problems.append(f"integer: {m.type} holds integers; the value is always rounded")
    if m.direction == "in":
        used = m.fields or ([m.field] if m.field else [])
        missing = [f.name for f in fields.values() if f.required and f.name not in used]
        if missing:
            problems.append(f"fields: the input {name} needs {', '.join(missing)}")
        if m.default is not None:
            problems.append("default: only outbound values can be null")
    return problems



# -- expansion over rovers and components ------------------------------------------------------


class RoverNames(NamedTuple):
    """The component names a mapping's placeholders run over."""

    id: str
    load: tuple[str, ...] = ()
    rail: tuple[str, ...] = ()
    radio: tuple[str, ...] = ()
    panel: tuple[str, ...] = ()


def rover_names(rover: Rover) -> RoverNames:
    """Components of a rover definition; the solar rail is a rail of the PDM too."""
    return RoverNames(
        rover.id,
        load=tuple(x.name for x in rover.loads),
        rail=tuple([x.name for x in rover.rails] + [rover.solar.rail.name]),
        radio=tuple(x.name for x in rover.radios),
        panel=tuple(x.name for x in rover.solar.panels),
    )


class Binding(NamedTuple):
    """One mapping for one rover and one component: a concrete key and topic."""

    index: int  # the mapping's position in the file
    mapping: Mapping
    rover: str
    item: str | None  # the component ({load} ...) this binding is for
    key: str  # twin key
    topic: str  # absolute ROS 2 topic

    @property
    def label(self) -> str:
        template = self.mapping.label or self.topic
        return _fill(template, self.rover, self.item, self.mapping.key, lambda v: v)


def _fill(template: str, rover: str, item: str | None, key_template: str, clean) -> str:
    found = keys.family_of_template(key_template)
    placeholder = found[0].placeholder if found else None
    out = template.replace("{rover}", clean(rover))
    if placeholder and item is not None:
        out = out.replace(f"{{{placeholder}}}", clean(item))
    return out


def expand(mf: MappingFile, rovers: Iterable[RoverNames], source: str = "<mapping>") -> list[Binding]:
    """Every binding of the mapping for these rovers; raise :class:`ConfigError` naming each
    component a mapping names that a rover lacks, and each topic two bindings would share."""
    rovers = list(rovers)
    prefix = mf.bridge.topic_prefix if len(rovers) <= 1 else mf.bridge.fleet_topic_prefix
    problems: list[str] = []
    out: list[Binding] = []
    owner: dict[tuple[str, str], str] = {}
    for i, m in enumerate(mf.mappings):
        found = keys.family_of_template(m.key)
        assert found is not None, "parse_mapping checked the key"
        shape, item = found
        placeholder = shape.placeholder
        for rover in rovers:
            if placeholder is None:
                items: tuple[str | None, ...] = (None,)
            elif item is not None and item.startswith("{"):
                items = getattr(rover, placeholder)
            else:
                have = getattr(rover, placeholder)
                if item not in have:
                    problems.append(f"mappings[{i}].key: rover {rover.id} has no {placeholder} "
                                    f"{item!r} ({placeholder}s: {', '.join(have) or 'none'})")
                    continue
                items = (item,)
            for it in items:
                key = _fill(m.key, rover.id, it, m.key, lambda v: v)
                topic = _fill(prefix + m.topic, rover.id, it, m.key, ros_name)
                if not _ROS_TOPIC.match(topic):
                    problems.append(f"mappings[{i}].topic: {topic!r} (rover {rover.id}) is not a "
                                    "ROS 2 name: a token starts with a digit?")
                    continue
                where = f"mappings[{i}] for {rover.id}" + (f" {it}" if it else "")
                first = owner.setdefault((m.direction, topic), where)
                if first != where:
                    problems.append(f"mappings[{i}].topic: {topic} of {where} is also the topic "
                                    f"of {first}")
                    continue
                out.append(Binding(i, m, rover.id, it, key, topic))
    if problems:
        raise ConfigError(source, problems)
    return out
