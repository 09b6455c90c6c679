"""The dashboard bridge, without Zenoh: mapping file, values, ROS 2 messages, rmw_zenoh names.

The crew's dashboard is a ROS 2 application. The bridge (SPEC §7) maps twin keys onto the
dashboard's topics, both ways, as a YAML mapping file describes (``config/bridge/default.yaml``
documents the format). This module is everything about that which is pure:

- **The mapping file**: :func:`parse_mapping` validates the whole file and names every problem
  (``mappings[3].field: BatteryState has no field 'volts'``) as rover definitions do;
  :func:`expand` turns each mapping into one :class:`Binding` per rover and per component
  (``{load}``, ``{rail}``, ``{radio}``, ``{panel}`` placeholders run over the rover's
  components), checking the resulting ROS 2 names.
- **Values**: a field of a twin payload, times ``scale``, rounded half away from zero for the
  integer message types (``voltage_v`` x 1000 -> integer mV) and clamped to the type's range.
- **Messages** as plain dicts of ROS 2 fields (what the ``json`` flavour publishes), turned into
  CDR by ``rosbags`` (:func:`encode_cdr`) - never by a hand-written serialiser.
  :func:`battery_state_message` follows the ``sensor_msgs/msg/BatteryState`` conventions (SI
  units, current negative while discharging, charge and capacity in Ah, percentage 0..1);
  :func:`diagnostic_array_message` reports each component of the rover with the ROS levels
  OK / WARN / ERROR / STALE.
- **rmw_zenoh** names (ros2/rmw_zenoh ``docs/design.md``): the topic key
  ``<domain>/<topic>/<pkg>::msg::dds_::<Name>_/<RIHS01 hash>``, the liveliness tokens of a node
  (``NN``), its publishers (``MP``) and subscriptions (``MS``), and the 33-byte attachment every
  sample carries.
"""

from __future__ import annotations

import hashlib
import math
import re
import struct
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any, NamedTuple

import msgspec
import msgspec.inspect as mi
import numpy as np
from rosbags.typesys import Stores, get_typestore

from common import keys
from common.config import Battery, ConfigError, Rover, parse_yaml, read_text
from common.messages import KEY_PAYLOADS, BadInput, BatteryState, is_telemetry
from common.runtime import ActiveFault

__all__ = [
    "ARRAY_TYPES",
    "ATTACHMENT_LEN",
    "CONVERTERS",
    "DIAG_ERROR",
    "DIAG_OK",
    "DIAG_STALE",
    "DIAG_WARN",
    "FLAVOURS",
    "HEALTH",
    "INT_RANGES",
    "SCALAR_TYPES",
    "SHAPES",
    "Binding",
    "BridgeOptions",
    "Mapping",
    "MappingFile",
    "PLACEHOLDERS",
    "RoverNames",
    "Shape",
    "attachment",
    "battery_state_message",
    "component_of_fault",
    "components",
    "data_key",
    "dds_type_name",
    "decode_cdr",
    "diagnostic_array_message",
    "diagnostic_statuses",
    "encode_cdr",
    "entity_token",
    "expand",
    "gid_of",
    "in_payload",
    "level_name",
    "load_mapping",
    "mangle",
    "node_token",
    "nominal_voltage_v",
    "out_message",
    "out_value",
    "parse_mapping",
    "qos_keyexpr",
    "rmw_topic_key",
    "ros_name",
    "rover_names",
    "shape_of",
    "stamp",
    "type_hash",
    "typestore",
]

FLAVOURS = ("ros2dds", "rmw_zenoh", "json")
PLACEHOLDERS = ("load", "rail", "radio", "panel")  # component placeholders; {rover} is always there
_PLACEHOLDER = re.compile(r"\{([a-z_]*)\}")


# == the mapping file ========================================================================


class _Strict(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    pass


class Ros2DdsOutput(_Strict):
    """Key = topic without the leading ``/``: what ``zenoh-bridge-ros2dds`` forwards to DDS."""

    enabled: bool = True


class RmwZenohOutput(_Strict):
    """A ROS 2 node on ``rmw_zenoh``: keyed topics, attachments, liveliness tokens."""

    enabled: bool = True
    domain_id: int = 0  # ROS_DOMAIN_ID
    node: str = "lunaris_bridge"  # the node that owns the bridge's publishers
    namespace: str = "/"


class JsonOutput(_Strict):
    """Key = ``prefix/`` + topic without the leading ``/``; the ROS message fields as JSON."""

    enabled: bool = True
    prefix: str = "json"


class Outputs(_Strict):
    ros2dds: Ros2DdsOutput = Ros2DdsOutput()
    rmw_zenoh: RmwZenohOutput = RmwZenohOutput()
    json: JsonOutput = JsonOutput()


class BridgeOptions(_Strict):
    ros_distro: str = "jazzy"  # jazzy: RIHS01 type hashes; humble: TypeHashNotSupported
    topic_prefix: str = ""  # before every topic when the bridge serves one rover
    fleet_topic_prefix: str = "/{rover}"  # instead, when it serves several
    stamp: str = "wall"  # header stamps: wall clock (ROS default) or sim (the twin's t_s)
    diagnostics_period_s: float = 1.0  # the DiagnosticArray is also republished this often
    stale_after_s: float = 3.0  # a component silent this long is STALE
    outputs: Outputs = Outputs()


class Mapping(_Strict):
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


class MappingFile(_Strict):
    mappings: list[Mapping]
    bridge: BridgeOptions = BridgeOptions()


# -- twin keys the bridge understands ---------------------------------------------------------


class Shape(NamedTuple):
    """A family of twin keys: chunks after ``lunaris/<rover>/`` (a ``{placeholder}`` chunk
    matches that placeholder or one component name), its payload Struct and direction."""

    chunks: tuple[str, ...]
    payload: type[msgspec.Struct]
    direction: str

    @property
    def placeholder(self) -> str | None:
        return next((c[1:-1] for c in self.chunks if c.startswith("{")), None)

    @property
    def pattern(self) -> str:
        """Zenoh key expression for every rover and component."""
        return "/".join([keys.ROOT, "*", *("*" if c.startswith("{") else c for c in self.chunks)])


SHAPES: tuple[Shape, ...] = tuple(
    Shape(chunks, struct, "out" if is_telemetry(struct) else "in")
    for chunks, struct in KEY_PAYLOADS.items()
)


def shape_of(key_template: str) -> tuple[Shape, str | None] | None:
    """The shape of ``lunaris/{rover}/...`` and the component it names (a literal name, a
    ``{placeholder}``, or None for keys without one); None when no shape fits."""
    parts = key_template.split("/")
    if len(parts) < 3 or parts[0] != keys.ROOT or parts[1] != "{rover}":
        return None
    rest = parts[2:]
    for shape in SHAPES:
        if len(shape.chunks) != len(rest):
            continue
        item: str | None = None
        for want, got in zip(shape.chunks, rest, strict=True):
            if want.startswith("{"):
                if got.startswith("{") and got != want:
                    break
                item = got
            elif want != got:
                break
        else:
            return shape, item
    return None


# -- ROS 2 message types ------------------------------------------------------------------------

INT_RANGES: dict[str, tuple[int, int]] = {
    "int8": (-(2**7), 2**7 - 1), "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1),
}
# std_msgs types with one `data` field -> its ROS type
SCALAR_TYPES: dict[str, str] = {
    "std_msgs/msg/Bool": "bool",
    "std_msgs/msg/Float32": "float32", "std_msgs/msg/Float64": "float64",
    "std_msgs/msg/Int8": "int8", "std_msgs/msg/UInt8": "uint8",
    "std_msgs/msg/Int16": "int16", "std_msgs/msg/UInt16": "uint16",
    "std_msgs/msg/Int32": "int32", "std_msgs/msg/UInt32": "uint32",
    "std_msgs/msg/Int64": "int64", "std_msgs/msg/UInt64": "uint64",
}
ARRAY_TYPES: dict[str, str] = {
    "std_msgs/msg/Float32MultiArray": "float32", "std_msgs/msg/Float64MultiArray": "float64",
    "std_msgs/msg/Int32MultiArray": "int32", "std_msgs/msg/Int64MultiArray": "int64",
}


class Converter(NamedTuple):
    type: str
    shape: tuple[str, ...]
    options: frozenset[str]


CONVERTERS: dict[str, Converter] = {
    "battery_state": Converter("sensor_msgs/msg/BatteryState", ("battery", "state"),
                               frozenset({"technology", "location", "serial_number"})),
    "diagnostics": Converter("diagnostic_msgs/msg/DiagnosticArray", ("event",), frozenset()),
}


@cache
def typestore(distro: str = "jazzy") -> Any:
    """The rosbags type store of a ROS 2 distribution (message classes, CDR, type hashes)."""
    return get_typestore({"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}[distro])


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
    t = field.type
    if isinstance(t, mi.UnionType):  # float | None
        members = [m for m in t.types if not isinstance(m, mi.NoneType)]
        t = members[0] if len(members) == 1 else t
    if isinstance(t, mi.BoolType):
        return "bool"
    if isinstance(t, mi.IntType | mi.FloatType):
        return "number"
    return "other"


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

    found = shape_of(m.key)
    if found is None:
        problems.append(f"key: {m.key!r} is not a twin key the bridge knows (lunaris/{{rover}}/"
                        f"...: {', '.join('/'.join(s.chunks) for s in SHAPES)})")
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
        if tech is not None and f"POWER_SUPPLY_TECHNOLOGY_{tech}" not in _constants(
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


@cache
def _constants(distro: str, typename: str) -> dict[str, Any]:
    consts, _ = typestore(distro).fielddefs[typename]
    return {name: value for name, _, value in consts}


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
    found = shape_of(key_template)
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
        found = shape_of(m.key)
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


# == values ====================================================================================


def _round_half_away(x: float) -> int:
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def _ros_kind(m: Mapping) -> str:
    return SCALAR_TYPES.get(m.type) or ARRAY_TYPES.get(m.type) or ""


def _scaled(m: Mapping, value: Any) -> bool | int | float | None:
    if value is None:
        value = m.default
        if value is None:
            return None
    kind = _ros_kind(m)
    if kind == "bool":
        return bool(value)
    x = float(value) * m.scale
    if not math.isfinite(x):
        return x if kind.startswith("float") else None
    if kind in INT_RANGES:
        lo, hi = INT_RANGES[kind]
        return min(max(_round_half_away(x), lo), hi)
    return float(_round_half_away(x)) if m.integer else x


def out_value(m: Mapping, payload: msgspec.Struct) -> bool | int | float | None:
    """The value of a one-value mapping: ``payload.field x scale``, rounded half away from zero
    for integer types (or ``integer: true``) and clamped to the type's range. None (publish
    nothing) when the field is null and the mapping has no ``default``."""
    return _scaled(m, getattr(payload, m.field))


def out_message(m: Mapping, payload: msgspec.Struct) -> dict | None:
    """A std_msgs one-value or MultiArray message from a twin payload; None to publish nothing."""
    if m.fields:
        values = [_scaled(m, getattr(payload, f)) for f in m.fields]
        if any(v is None for v in values):
            return None
        return _multi_array(m.fields, values)
    value = out_value(m, payload)
    return None if value is None else {"data": value}


def _multi_array(names: list[str], values: list) -> dict:
    # One dimension whose label names the fields in order ("distance_m,angle_deg").
    n = len(values)
    return {"layout": {"dim": [{"label": ",".join(names), "size": n, "stride": n}],
                       "data_offset": 0},
            "data": values}


def in_payload(m: Mapping, msg: dict) -> dict[str, Any]:
    """The twin input (a JSON object) for an inbound dashboard message; :class:`BadInput` if
    the message does not carry what the mapping expects or a value is not finite."""
    if m.fields:
        data = list(msg.get("data", []))
        if len(data) != len(m.fields):
            raise BadInput(f"{m.type} on {m.topic}: expected {len(m.fields)} values "
                           f"({', '.join(m.fields)}), got {len(data)}")
        pairs = list(zip(m.fields, data, strict=True))
    else:
        if "data" not in msg:
            raise BadInput(f"{m.type} on {m.topic}: no data field")
        pairs = [(m.field, msg["data"])]
    out: dict[str, Any] = {}
    for name, value in pairs:
        if isinstance(value, bool):
            out[name] = value
            continue
        if not isinstance(value, int | float):
            raise BadInput(f"{name}: expected a number, got {type(value).__name__}")
        x = float(value) * m.scale
        if not math.isfinite(x):
            raise BadInput(f"{name}: {x} is not a finite number")
        out[name] = x
    return out


def stamp(t_ns: int) -> dict[str, int]:
    """A ``builtin_interfaces/msg/Time`` from nanoseconds."""
    return {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}


# == sensor_msgs/msg/BatteryState ===============================================================

# power_supply_health, first match wins: the ROS codes (Linux power-supply class) closest to
# each twin fault; any other fault is UNSPEC_FAILURE, none is GOOD.
HEALTH: list[tuple[str, str]] = [
    ("thermal_cutoff", "OVERHEAT"),
    ("over_temperature", "OVERHEAT"),
    ("depleted", "DEAD"),
    ("under_temperature", "COLD"),
]
_CURRENT_EPS_A = 1e-3  # below this the pack is neither charging nor discharging
_FULL_SOC = 0.999


def nominal_voltage_v(battery: Battery) -> float:
    """Pack voltage [V] that turns energy into charge: ``cells_series`` times the mean of the
    per-cell OCV curve over state of charge (trapezoid rule), so ``Q = E / V_nom``."""
    soc, volts = battery.ocv_curve.soc, battery.ocv_curve.volts
    mean = sum((s1 - s0) * (v0 + v1) / 2.0 for s0, s1, v0, v1 in
               zip(soc, soc[1:], volts, volts[1:], strict=False)) / (soc[-1] - soc[0])
    return battery.cells_series * mean


def battery_state_message(state: BatteryState, battery: Battery, stamp_ns: int,
                          frame_id: str = "", options: dict[str, str] | None = None,
                          distro: str = "jazzy") -> dict:
    """``sensor_msgs/msg/BatteryState`` from the twin's ``battery/state``.

    ROS conventions (REP-103 SI units and the message's own comments):

    - ``voltage`` [V], ``temperature`` [degC];
    - ``current`` [A] is **negative while discharging**: the twin's ``current_a`` is positive
      when discharging, so its sign flips;
    - ``charge``, ``capacity``, ``design_capacity`` in [Ah]: energy over the pack's nominal
      voltage (:func:`nominal_voltage_v`), ``/ 3600``; ``capacity`` is what the pack holds now
      (after a capacity-loss fault), ``design_capacity`` what the rover definition says;
    - ``percentage`` 0..1 (the state of charge);
    - ``power_supply_status``: DISCHARGING / CHARGING by the sign of the current, FULL at rest
      when full, NOT_CHARGING otherwise (and whenever the pack is off the bus);
    - ``power_supply_health`` from the active faults (:data:`HEALTH`): OVERHEAT, DEAD, COLD,
      UNSPEC_FAILURE for any other fault, GOOD with none;
    - ``cell_voltage`` and ``cell_temperature``: one NaN per series cell, the message's way of
      saying the number of cells is known but not their values;
    - ``present`` is always true: a pack off the bus (``disconnected``) is still in the rover,
      and says so through its health and status.
    """
    options = options or {}
    c = _constants(distro, "sensor_msgs/msg/BatteryState")
    v_nom = nominal_voltage_v(battery)
    faults = set(state.faults)
    current_a = state.current_a
    if not state.operational:
        status = "NOT_CHARGING"
    elif current_a > _CURRENT_EPS_A:
        status = "DISCHARGING"
    elif current_a < -_CURRENT_EPS_A:
        status = "CHARGING"
    else:
        status = "FULL" if state.soc >= _FULL_SOC else "NOT_CHARGING"
    health = next((h for name, h in HEALTH if name in faults),
                  "UNSPEC_FAILURE" if faults else "GOOD")
    nan_cells = [math.nan] * battery.cells_series
    return {
        "header": {"stamp": stamp(stamp_ns), "frame_id": frame_id},
        "voltage": state.voltage_v,
        "temperature": state.temperature_c,
        "current": -current_a,
        "charge": state.energy_j / v_nom / 3600.0,
        "capacity": state.capacity_j / v_nom / 3600.0,
        "design_capacity": battery.capacity_j / v_nom / 3600.0,
        "percentage": min(max(state.soc, 0.0), 1.0),
        "power_supply_status": c[f"POWER_SUPPLY_STATUS_{status}"],
        "power_supply_health": c[f"POWER_SUPPLY_HEALTH_{health}"],
        "power_supply_technology": c[f"POWER_SUPPLY_TECHNOLOGY_{options.get('technology', 'LION')}"],
        "present": True,
        "cell_voltage": nan_cells,
        "cell_temperature": list(nan_cells),
        "location": options.get("location", ""),
        "serial_number": options.get("serial_number", ""),
    }


# == diagnostic_msgs/msg/DiagnosticArray =========================================================

DIAG_OK, DIAG_WARN, DIAG_ERROR, DIAG_STALE = 0, 1, 2, 3
_LEVEL_NAMES = {DIAG_OK: "OK", DIAG_WARN: "WARN", DIAG_ERROR: "ERROR", DIAG_STALE: "STALE"}
_LEVEL_OF_SEVERITY = {"info": DIAG_OK, "warning": DIAG_WARN, "critical": DIAG_ERROR}


def components(rover: Rover) -> list[str]:
    """The rover's components as fault paths name them: ``battery``, ``rail/12V`` ..."""
    return (["battery"] + [f"rail/{r}" for r in rover_names(rover).rail]
            + [f"load/{x.name}" for x in rover.loads]
            + [f"solar/{p.name}" for p in rover.solar.panels] + ["umbilical"]
            + [f"radio/{r.name}" for r in rover.radios])


def data_key(rover: str, component: str) -> str:
    """The telemetry key whose samples show that a component is alive."""
    kind, _, name = component.partition("/")
    return {
        "battery": lambda: keys.battery_state(rover),
        "rail": lambda: keys.rail_state(rover, name),
        "load": lambda: keys.load_power(rover, name),
        "solar": lambda: keys.solar_power(rover, name),
        "umbilical": lambda: keys.umbilical_state(rover),
        "radio": lambda: keys.radio_link(rover, name),
    }[kind]()


def component_of_fault(fault_key: str) -> tuple[str, str]:
    """``lunaris/r/fault/load/cam/short`` (injected) or ``lunaris/r/rail/12V/tripped``
    (derived) -> (component, fault name): ``("load/cam", "short")``, ``("rail/12V", "tripped")``."""
    _, parts = keys.split(fault_key)
    if parts and parts[0] == "fault":
        parts = parts[1:]
    return "/".join(parts[:-1]), parts[-1] if parts else ""


def diagnostic_statuses(rover: str, component_names: list[str], active: list[ActiveFault],
                        age_s: dict[str, float | None], stale_after_s: float) -> list[dict]:
    """One ``DiagnosticStatus`` per component, in the rover's order.

    The level is STALE when the component's telemetry is older than ``stale_after_s`` (or never
    came: ``age_s`` None), else the worst of its active faults - a ``critical`` fault is ERROR,
    a ``warning`` (every injected fault, most derived ones) WARN - and OK without any. The
    message names the faults; each one is also a ``KeyValue`` (fault name -> origin, severity,
    since when and parameters)."""
    by_component: dict[str, list[ActiveFault]] = {}
    for f in active:
        by_component.setdefault(component_of_fault(f.key)[0], []).append(f)
    names = list(component_names) + sorted(set(by_component) - set(component_names))
    statuses = []
    for comp in names:
        faults = by_component.get(comp, [])
        level = max((_LEVEL_OF_SEVERITY.get(f.severity, DIAG_WARN) for f in faults),
                    default=DIAG_OK)
        fault_names = [component_of_fault(f.key)[1] for f in faults]
        message = ", ".join(fault_names) if faults else "OK"
        age = age_s.get(comp)
        if comp in age_s and (age is None or age > stale_after_s):
            level = DIAG_STALE
            silent = "no data yet" if age is None else f"no data for {age:.1f} s"
            message = silent + (f"; {message}" if faults else "")
        statuses.append({
            "level": level,
            "name": f"{rover}/{comp}",
            "message": message,
            "hardware_id": rover,
            "values": [{"key": name, "value": _fault_text(f)}
                       for name, f in zip(fault_names, faults, strict=True)],
        })
    return statuses


def _fault_text(f: ActiveFault) -> str:
    params = msgspec.json.encode(f.params).decode() if f.params else ""
    return f"{f.origin} {f.severity} since t={f.since_t_s:.1f} s {params}".rstrip()


def diagnostic_array_message(statuses: list[dict], stamp_ns: int, frame_id: str = "") -> dict:
    return {"header": {"stamp": stamp(stamp_ns), "frame_id": frame_id}, "status": statuses}


def level_name(level: int) -> str:
    return _LEVEL_NAMES.get(level, str(level))


# == CDR (rosbags) ==============================================================================

_NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "float32": np.float32,
          "float64": np.float64, **{t: getattr(np, t) for t in INT_RANGES}}


def _to_ros(store: Any, typename: str, value: dict) -> Any:
    """A rosbags message object from a dict of its fields (missing fields: zero values)."""
    _, fields = store.fielddefs[typename]
    kwargs = {}
    for name, (node, spec) in fields:
        kwargs[name] = _field_to_ros(store, node, spec, value.get(name))
    return store.types[typename](**kwargs)


def _field_to_ros(store: Any, node: int, spec: Any, value: Any) -> Any:
    if node == 1:  # BASE: (type, string bound)
        base = spec[0]
        if base == "string":
            return "" if value is None else str(value)
        if base == "bool":
            return bool(value)
        if base in ("float32", "float64"):
            return 0.0 if value is None else float(value)
        return 0 if value is None else int(value)
    if node == 2:  # NAME: a nested message
        return _to_ros(store, spec, value or {})
    # ARRAY (3) or SEQUENCE (4): ((node, spec), length)
    (sub_node, sub_spec), length = spec
    items = list(value or [])
    if node == 3 and len(items) < length:
        items += [None] * (length - len(items))
    if sub_node == 1 and sub_spec[0] != "string":
        return np.array([0 if v is None else v for v in items], dtype=_NUMPY[sub_spec[0]])
    return [_field_to_ros(store, sub_node, sub_spec, v) for v in items]


def _from_ros(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list):
        return [_from_ros(v) for v in value]
    if hasattr(value, "__msgtype__"):
        return {name: _from_ros(getattr(value, name)) for name in value.__dataclass_fields__
                if name != "__msgtype__" and not name.isupper()}
    return value


def encode_cdr(typename: str, msg: dict, distro: str = "jazzy") -> bytes:
    """ROS 2 CDR (little endian, with its 4-byte encapsulation header) of a message dict."""
    store = typestore(distro)
    return bytes(store.serialize_cdr(_to_ros(store, typename, msg), typename))


def decode_cdr(typename: str, payload: bytes, distro: str = "jazzy") -> dict:
    """A message dict from CDR; :class:`BadInput` when the bytes are not that message."""
    try:
        return _from_ros(typestore(distro).deserialize_cdr(bytes(payload), typename))
    except Exception as exc:  # rosbags raises assorted errors on truncated or foreign bytes
        raise BadInput(f"not a CDR {typename}: {type(exc).__name__}: {exc}") from None


# == rmw_zenoh ==================================================================================

ATTACHMENT_LEN = 33
GID_LEN = 16


def dds_type_name(typename: str) -> str:
    """``std_msgs/msg/Bool`` -> ``std_msgs::msg::dds_::Bool_`` (the DDS name rmw_zenoh uses)."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def type_hash(typename: str, distro: str = "jazzy") -> str:
    """REP-2016 type hash (``RIHS01_<sha256>``) as Jazzy and later advertise it; Humble's
    rmw_zenoh has none and writes ``TypeHashNotSupported``."""
    if distro == "humble":
        return "TypeHashNotSupported"
    return typestore(distro).hash_rihs01(typename)


def rmw_topic_key(domain_id: int, topic: str, typename: str, distro: str = "jazzy") -> str:
    """``<domain>/<topic without its outer '/'>/<dds type>/<type hash>``."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(typename)}/{type_hash(typename, distro)}"


def mangle(name: str) -> str:
    """A ROS name as one key chunk: every ``/`` becomes ``%`` (``/`` alone becomes ``%``)."""
    return name.replace("/", "%") or "%"


def qos_keyexpr(transient_local: bool, depth: int) -> str:
    """rmw_zenoh's compact QoS chunk: ``rel:dur:hist,depth:dl_s,dl_ns:ls_s,ls_ns:liv,lease_s,
    lease_ns`` where a field equal to rmw_zenoh's default (RELIABLE, VOLATILE, KEEP_LAST, 42,
    infinite durations, AUTOMATIC) is left empty. TRANSIENT_LOCAL is durability 1."""
    durability = "1" if transient_local else ""
    depth_s = "" if depth == 42 else str(depth)
    return f":{durability}:,{depth_s}:,:,:,,"


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, node: str,
               enclave: str = "/") -> str:
    """``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>``."""
    return "/".join(["@ros2_lv", str(domain_id), zid, str(node_id), str(node_id), "NN",
                     mangle(enclave), mangle(namespace), node])


def entity_token(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str,
                 namespace: str, node: str, topic: str, typename: str, qos: str,
                 distro: str = "jazzy", enclave: str = "/") -> str:
    """A publisher (``MP``) or subscription (``MS``) token: the node's chunks, then the mangled
    topic, the DDS type name, the type hash and the QoS chunk."""
    assert kind in ("MP", "MS", "SS", "SC")
    return "/".join(["@ros2_lv", str(domain_id), zid, str(node_id), str(entity_id), kind,
                     mangle(enclave), mangle(namespace), node, mangle(topic),
                     dds_type_name(typename), type_hash(typename, distro), qos])


def gid_of(token: str) -> bytes:
    """A 16-byte GID derived from the entity's liveliness token, as rmw_zenoh derives its own
    (it uses XXH3-128; any stable 128-bit hash of the token serves: the GID only has to be
    unique per entity and constant while it lives)."""
    return hashlib.blake2b(token.encode(), digest_size=GID_LEN).digest()


def attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The 33 bytes rmw_zenoh attaches to every sample: sequence number (int64, little
    endian, from 1, one per publisher), source timestamp [ns since the epoch] (int64, little
    endian), the GID length (one byte, 16) and the GID."""
    if len(gid) != GID_LEN:
        raise ValueError(f"gid must be {GID_LEN} bytes, got {len(gid)}")
    return struct.pack("<qqB", sequence, timestamp_ns, GID_LEN) + gid
