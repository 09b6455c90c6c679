"""The bridge's mapping file: its format, its validation, where the shipped one is.

:func:`parse_mapping` validates a whole mapping file and names every problem
(``mappings[3].field: BatteryState has no field 'volts'``) as rover definitions do;
the twin keys a mapping may name are the families of :mod:`common.keys`.
:mod:`services.bridge.bindings` expands a mapping over the rovers it serves. The CLI and the
deployment use all this through the bridge's public face, :mod:`services.bridge`.

The shipped mapping, ``config/bridge/default.yaml``, is package data of ``services.bridge``
(``services/bridge/default.yaml``, in the source tree a link to that one file), so an
installed Lunaris finds it wherever it runs: :data:`DEFAULT_MAPPING`, :func:`resolve_mapping`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Annotated, Any, NamedTuple

import msgspec

from common import keys
from common.datafile import ConfigError, Strict, doc, field_kind, parse_yaml, read_text, struct_fields
from services.bridge.cdr import ARRAY_TYPES, INT_RANGES, SCALAR_TYPES, constants, typestore

__all__ = [
    "DEFAULT_MAPPING",
    "MAX_DOMAIN",
    "JOINT_STATE",
    "OTHERWISE",
    "CONVERTERS",
    "FLAVOURS",
    "PLACEHOLDERS",
    "ROS_TOPIC",
    "BridgeOptions",
    "Mapping",
    "MappingFile",
    "load_mapping",
    "parse_mapping",
    "resolve_mapping",
    "ros_name",
]

FLAVOURS = ("ros2dds", "rmw_zenoh", "json", "ros2")
PLACEHOLDERS = keys.PLACEHOLDERS  # component placeholders; {rover} is always there
_PLACEHOLDER = re.compile(r"\{([a-z_]*)\}")
REPO = Path(__file__).resolve().parents[2]  # the source tree (an installed package: site-packages)
# The shipped mapping, package data: in the source tree the link resolves to config/bridge/.
DEFAULT_MAPPING = Path(__file__).with_name("default.yaml").resolve()


# == the mapping file ========================================================================


class Ros2DdsOutput(Strict, frozen=True):
    """Key = topic without the leading ``/``, CDR payload: what ``zenoh-bridge-ros2dds``
    forwards to DDS. In a fleet the key starts with the rover's namespace
    (``mapp_1/battery_state``): that rover's ``zenoh-bridge-ros2dds`` runs with that namespace
    and gives its DDS domain the plain topic."""

    enabled: bool = True


class RmwZenohOutput(Strict, frozen=True):
    """A ROS 2 node on ``rmw_zenoh``: keyed topics, attachments, liveliness tokens."""

    enabled: bool = True
    domain_id: Annotated[int, doc("ROS_DOMAIN_ID of the dashboard (of the fleet's first rover; "
                                  "the next rovers take the next domains)")] = 0
    node: Annotated[str, doc("the node that owns the bridge's publishers")] = "lunaris_bridge"
    namespace: Annotated[str, doc("the node's namespace")] = "/"


class JsonOutput(Strict, frozen=True):
    """Key = ``prefix/`` + topic without the leading ``/`` (in a fleet ``prefix/<rover>/``
    + topic); the ROS message fields as JSON, for web and scripting clients."""

    enabled: bool = False
    prefix: Annotated[str, doc("before every key; keeps them apart from the ros2dds keys")] = "json"


class Ros2Output(Strict, frozen=True):
    """The bridge as a ROS 2 node itself (``rclpy``, the ``lunaris[ros2]`` extra) on the
    dashboard's own middleware: no other bridge between DDS and the twin. The ROS 2
    environment (``RMW_IMPLEMENTATION``, ``FASTDDS_BUILTIN_TRANSPORTS`` ...) is passed
    through; outbound topics are reliable, transient-local, keep-last 1."""

    enabled: bool = False
    domain_id: Annotated[int | None, doc("ROS_DOMAIN_ID of the fleet's first rover (the next "
                                         "rovers take the next domains); default: the "
                                         "ROS_DOMAIN_ID of the environment, else 0")] = None
    node: Annotated[str, doc("the node's name")] = "lunaris_bridge"
    namespace: Annotated[str, doc("the node's namespace")] = "/"


class Outputs(Strict, frozen=True):
    """The flavours of the dashboard's topics; each costs only when enabled. The default: a
    dashboard on DDS through ``zenoh-bridge-ros2dds`` and one on ``rmw_zenoh``."""

    ros2dds: Ros2DdsOutput = Ros2DdsOutput()
    rmw_zenoh: RmwZenohOutput = RmwZenohOutput()
    json: JsonOutput = JsonOutput()
    ros2: Ros2Output = Ros2Output()


class BridgeOptions(Strict, frozen=True):
    """Options of the whole bridge."""

    ros_distro: Annotated[str, doc("jazzy: rmw_zenoh keys carry RIHS01 type hashes; humble: "
                                   "TypeHashNotSupported")] = "jazzy"
    topic_prefix: Annotated[str, doc("before every topic when the fleet has one rover")] = ""
    fleet_topic_prefix: Annotated[str, doc("before every topic when the fleet has several rovers "
                                           "(default none: each rover's dashboard has its own "
                                           "ROS 2 domain and sees the plain names)")] = ""
    rover_domains: Annotated[dict[str, int], doc("ROS 2 domain of a rover, by id (default: "
                                                 "the flavour's domain_id + the rover's place "
                                                 "in the fleet)")] = {}
    fleet_namespace: Annotated[str, doc("in a fleet, the ros2dds and json keys start with this "
                                        "(the namespace of the rover's zenoh-bridge-ros2dds)")] \
        = "/{rover}"
    stamp: Annotated[str, doc("header stamps: wall (the ROS default) or sim (the twin's t_s)")] = "wall"
    diagnostics_period_s: Annotated[float, doc("the DiagnosticArray is also republished this "
                                               "often [s]")] = 1.0
    stale_after_s: Annotated[float, doc("a component whose telemetry is silent this long is "
                                        "STALE [s]")] = 3.0
    outputs: Outputs = Outputs()


class Mapping(Strict, frozen=True):
    """One line of the mapping: a twin key and a dashboard topic."""

    topic: Annotated[str, doc("absolute ROS 2 topic; may hold {rover} and the key's component "
                              "placeholder (a name is made ROS-safe: mapp-1 -> mapp_1)")]
    type: Annotated[str, doc("ROS 2 message type, pkg/msg/Name")]
    key: Annotated[str, doc("twin key lunaris/{rover}/...; {load} {rail} {radio} {panel} in place "
                            "of a name run over every such component: one topic each")]
    direction: Annotated[str, doc("out: twin -> dashboard; in: dashboard -> twin input")] = "out"
    field: Annotated[str | None, doc("the payload field of a one-value std_msgs type (its data)")] = None
    fields: Annotated[list[str] | None, doc("the payload fields of a MultiArray, in order")] = None
    scale: Annotated[float, doc("out: ROS value = twin value x scale (V -> mV: 1000); in: twin "
                                "value = ROS value x scale")] = 1.0
    integer: Annotated[bool | None, doc("round half away from zero; always so for integer "
                                        "types")] = None
    default: Annotated[float | None, doc("published while the field is null; else that sample "
                                         "is not published")] = None
    convert: Annotated[str | None, doc("a whole-message converter instead of field and scale "
                                       "(see Converters)")] = None
    frame_id: Annotated[str, doc("header.frame_id of messages that have a header")] = ""
    options: Annotated[dict[str, str], doc("converter options")] = {}
    rate_hz: Annotated[float | None, doc("out: at most this many messages a second (the latest "
                                         "value); a change of a discrete field (a state, a "
                                         "flag, the faults) is still published at once. "
                                         "Default: every sample")] = None
    otherwise: Annotated[str, doc("a key naming a component the rover lacks: error (refuse "
                                  "the rover), first (its first one of that kind), skip (no "
                                  "topic for that rover)")] = "error"
    joint_names: Annotated[list[str] | None, doc("JointState: the names of the fields' values "
                                                 "(default the field names)")] = None
    label: Annotated[str | None, doc("how the dashboard names the value (lunaris pdm)")] = None
    unit: Annotated[str | None, doc("the value's unit, as the dashboard shows it")] = None
    group: Annotated[str | None, doc("pdm: part of the PDM device distribution")] = None


class MappingFile(Strict, frozen=True):
    """A mapping file: the mappings and the bridge's options."""

    mappings: list[Mapping]
    bridge: BridgeOptions = BridgeOptions()


class Converter(NamedTuple):
    """A whole-message converter: the message it makes, the twin key it reads (``also``:
    older spellings still accepted) and its options."""

    type: str
    key: str
    options: frozenset[str]
    also: tuple[str, ...] = ()


CONVERTERS: dict[str, Converter] = {
    "battery_state": Converter("sensor_msgs/msg/BatteryState", "lunaris/{rover}/battery/state",
                               frozenset({"technology", "location", "serial_number"})),
    # every owning service's faults in effect and the components' telemetry (which says each
    # is alive, and in the crew's view what it shows); `event` was its first, untrue spelling
    "diagnostics": Converter("diagnostic_msgs/msg/DiagnosticArray",
                             "lunaris/{rover}/faults/active/*", frozenset(),
                             also=("lunaris/{rover}/event",)),
    "odometry": Converter("nav_msgs/msg/Odometry", "lunaris/{rover}/drive/state",
                          frozenset({"child_frame_id"})),
}

# -- parsing and validation ---------------------------------------------------------------------

_ROS_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
ROS_TOPIC = re.compile(rf"^(/{_ROS_TOKEN})+$")
_ROS_NODE = re.compile(rf"^{_ROS_TOKEN}$")
MAX_DOMAIN = 232  # the largest ROS_DOMAIN_ID
OTHERWISE = ("error", "first", "skip")
JOINT_STATE = "sensor_msgs/msg/JointState"


def ros_name(value: str) -> str:
    """A twin name made fit for a ROS 2 topic: every character but letters, digits and ``_``
    becomes ``_`` (``mapp-1`` -> ``mapp_1``)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", value)


def resolve_mapping(mapping_file: str | None) -> Path:
    """The mapping file: the default one (``config/bridge/default.yaml`` of the working
    directory, as in the container image, where an operator may mount a mapping of their own;
    else the shipped one, :data:`DEFAULT_MAPPING`), or a path as given (relative to the working
    directory) or, failing that, relative to the source tree."""
    if mapping_file is None:
        local = Path("config/bridge/default.yaml")
        return local.resolve() if local.is_file() else DEFAULT_MAPPING
    path = Path(mapping_file)
    if not path.is_absolute() and not path.exists() and (REPO / path).exists():
        return REPO / path
    return path


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
    for rover, domain in o.rover_domains.items():
        if not 0 <= domain <= MAX_DOMAIN:
            problems.append(f"bridge.rover_domains.{rover}: expected 0..{MAX_DOMAIN}, got {domain}")
    if "{rover}" not in o.fleet_namespace:
        problems.append("bridge.fleet_namespace: must contain {rover}, or the rovers of a fleet "
                        "would publish on the same keys")
    else:
        problems += [f"bridge.fleet_namespace: {p}" for p in _topic_problems(o.fleet_namespace)]
    for name in ("diagnostics_period_s", "stale_after_s"):
        if not getattr(o, name) > 0.0:
            problems.append(f"bridge.{name}: must be > 0, got {getattr(o, name)}")
    out = o.outputs
    if not (out.ros2dds.enabled or out.rmw_zenoh.enabled or out.json.enabled or out.ros2.enabled):
        problems.append("bridge.outputs: every output is disabled")
    for name, node in (("rmw_zenoh", out.rmw_zenoh), ("ros2", out.ros2)):
        if node.domain_id is not None and not 0 <= node.domain_id <= MAX_DOMAIN:
            problems.append(f"bridge.outputs.{name}.domain_id: expected 0..{MAX_DOMAIN}, "
                            f"got {node.domain_id}")
        if not _ROS_NODE.match(node.node):
            problems.append(f"bridge.outputs.{name}.node: {node.node!r} is not a ROS 2 node name")
        if node.namespace != "/":
            problems += [f"bridge.outputs.{name}.namespace: {p}"
                         for p in _topic_problems(node.namespace)]
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
    if not ROS_TOPIC.match(sample):
        return [f"{topic!r} is not a ROS 2 name (tokens of letters, digits and '_', "
                "not starting with a digit, separated by '/')"]
    return []


def _payload_fields(payload: type[msgspec.Struct]) -> dict[str, Any]:
    return {f.name: f for f in struct_fields(payload)}


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
    if m.rate_hz is not None and not (math.isfinite(m.rate_hz) and m.rate_hz > 0.0):
        problems.append(f"rate_hz: must be a number > 0, got {m.rate_hz}")
    if m.rate_hz is not None and m.direction == "in":
        problems.append("rate_hz: only outbound topics have a rate")
    if m.otherwise not in OTHERWISE:
        problems.append(f"otherwise: expected {', '.join(OTHERWISE)}, got {m.otherwise!r}")
    if m.joint_names is not None and m.type != JOINT_STATE:
        problems.append(f"joint_names: only {JOINT_STATE} has joint names")

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
    if m.otherwise != "error" and (item is None or key_item is not None):
        problems.append("otherwise: only for a key that names one component (radio/lander)")
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
        if m.key != conv.key and m.key not in conv.also:
            problems.append(f"key: the {m.convert} converter reads {conv.key}")
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
    elif m.type in ARRAY_TYPES or m.type == JOINT_STATE:
        if m.field is not None:
            problems.append(f"field: {m.type} carries several values; use fields")
        if not m.fields:
            problems.append(f"fields: which fields of {name} go in {m.type}, in order?")
        for f in m.fields or []:
            if f not in fields:
                problems.append(f"fields: {name} has no field {f!r} (fields: {', '.join(fields)})")
            elif _field_kind(fields[f]) != "number":
                problems.append(f"fields: {name}.{f} is not a number")
        if m.joint_names is not None and len(m.joint_names) != len(m.fields or []):
            problems.append(f"joint_names: {len(m.joint_names)} names for "
                            f"{len(m.fields or [])} fields")
        if m.type == JOINT_STATE and m.direction == "in":
            problems.append(f"direction: {JOINT_STATE} is outbound only")
    elif m.type in store.fielddefs:
        problems.append(f"type: {m.type} needs a converter (convert: ...); plain mappings take "
                        f"std_msgs one-value and MultiArray types and {JOINT_STATE}")
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
