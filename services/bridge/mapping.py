"""The bridge's mapping file: its format, its validation, where the shipped one is.

Longer than 450 lines: the format and its validation are read together, each field of a
mapping beside the problems it can have (topics, converters, services), in one module the
CLI and the deployment reach through the bridge's public face.

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
from services.bridge.srv import SERVICE_TYPES, request_fields, response_fields

__all__ = [
    "DEFAULT_MAPPING",
    "LOCAL_MAPPING",
    "MAX_DOMAIN",
    "JOINT_STATE",
    "OTHERWISE",
    "CONVERTERS",
    "CREW_VIEWS",
    "FLAVOURS",
    "KINDS",
    "SERVICE_ANSWERS",
    "PLACEHOLDERS",
    "ROS_TOPIC",
    "BridgeOptions",
    "Mapping",
    "MappingFile",
    "load_mapping",
    "parse_mapping",
    "resolve_mapping",
    "ros_name",
    "service_response",
]

FLAVOURS = ("ros2dds", "rmw_zenoh", "json", "ros2")
KINDS = ("topic", "service")
CREW_VIEWS = ("symptoms", "full")
# What a service's response fields may carry of the twin's answer to the write it made:
# accepted (bool: the owner applied it) and reason (string: the twin's answer in words).
SERVICE_ANSWERS = {"accepted": "bool", "reason": "string"}
PLACEHOLDERS = keys.PLACEHOLDERS  # component placeholders; {rover} is always there
_PLACEHOLDER = re.compile(r"\{([a-z_]*)\}")
REPO = Path(__file__).resolve().parents[2]  # the source tree (an installed package: site-packages)
# The shipped mapping, package data: in the source tree the link resolves to config/bridge/.
DEFAULT_MAPPING = Path(__file__).with_name("default.yaml").resolve()
LOCAL_MAPPING = "config/bridge/default.yaml"  # the mapping of the working directory (the image's)


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
    crew_view: Annotated[str, doc("symptoms: /diagnostics and the battery's health show what the "
                                  "rover's own sensors and protection report (the twin's alarms, "
                                  "silent telemetry), never an instructor's fault (SPEC §12b); "
                                  "full: every fault in effect with its parameters, for "
                                  "integration work")] = "symptoms"
    outputs: Outputs = Outputs()


class Mapping(Strict, frozen=True):
    """One line of the mapping: a twin key and a dashboard topic, or a ROS 2 service of the
    dashboard's that writes a twin key and answers with the twin's answer."""

    topic: Annotated[str, doc("absolute ROS 2 topic (or service name); may hold {rover} and the "
                              "key's component placeholder (a name is made ROS-safe: mapp-1 -> "
                              "mapp_1)")]
    type: Annotated[str, doc("ROS 2 message type, pkg/msg/Name (a service: pkg/srv/Name)")]
    key: Annotated[str, doc("twin key lunaris/{rover}/...; {load} {rail} {radio} {panel} in place "
                            "of a name run over every such component: one topic each (a "
                            "command on {rail}: the rails that can be switched)")]
    kind: Annotated[str, doc("topic, or service: the dashboard calls it; the call writes the key "
                             "(actor crew) and is answered with the twin's answer")] = "topic"
    direction: Annotated[str, doc("out: twin -> dashboard; in: dashboard -> twin input or command "
                                  "(a topic only)")] = "out"
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
    request: Annotated[dict[str, str], doc("service: payload field <- request field ({on: data})")] = {}
    payload: Annotated[dict[str, Any], doc(
        "service or inbound topic: payload fields every write carries ({reset: true})")] = {}
    write: Annotated[str, doc("service: put (default), or delete (a delete of the key: "
                              "input/drive/traverse stops the rover)")] = "put"
    response: Annotated[dict[str, str] | None, doc(
        "service: response field <- accepted (bool: the twin applied the write) or reason "
        "(string: the twin's answer in words). Default {success: accepted, message: reason} "
        "when the response has those fields")] = None


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


def service_response(m: Mapping) -> dict[str, str]:
    """A service mapping's response fields and what of the twin's answer each carries
    (``{"success": "accepted", "message": "reason"}``)."""
    if m.response is not None:
        return dict(m.response)
    have = response_fields(m.type) if m.type in SERVICE_TYPES else {}
    return {name: what for name, what in (("success", "accepted"), ("message", "reason"))
            if have.get(name) == SERVICE_ANSWERS[what]}


def resolve_mapping(mapping_file: str | None) -> Path:
    """The mapping file: the default one (:data:`LOCAL_MAPPING` of the working
    directory, as in the container image, where an operator may mount a mapping of their own;
    else the shipped one, :data:`DEFAULT_MAPPING`), or a path as given (relative to the working
    directory) or, failing that, relative to the source tree."""
    if mapping_file is None:
        local = Path(LOCAL_MAPPING)
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
            first = seen.setdefault((_role(m), m.topic), i)
            if first != i:
                problems.append(f"mappings[{i}].topic: {m.topic} is already mapped by "
                                f"mappings[{first}]")
        # a service and a topic of one name would share their keys (ros2dds, json)
        for (role, topic), i in seen.items():
            other = [j for (r, t), j in seen.items() if t == topic and r != role]
            if role == "service" and other:
                problems.append(f"mappings[{i}].topic: the service {topic} has the name of the "
                                f"topic of mappings[{min(other)}]")
    if problems:
        raise ConfigError(source, problems)
    return msgspec.convert(data, MappingFile)


def _role(m: Mapping) -> str:
    """A mapping's place among the names: a service, an outbound or an inbound topic."""
    return "service" if m.kind == "service" else m.direction


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
    if o.crew_view not in CREW_VIEWS:
        problems.append(f"bridge.crew_view: expected {' or '.join(CREW_VIEWS)}, got {o.crew_view!r}")
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


def _placeholder_problems(key: str, topic: str, key_item: str | None, clash: str) -> list[str]:
    """What is wrong with the placeholders of a mapping's key and topic (or service name):
    unknown ones, ones in the topic the key lacks, and the key's component missing from the
    topic (every component would then ``clash``: share one topic or one service)."""
    problems = []
    unknown = (set(_placeholders(key)) | set(_placeholders(topic))) - {"rover", *PLACEHOLDERS}
    if unknown:
        problems.append(f"key: unknown placeholder(s) {', '.join(sorted(unknown))}")
    extra = set(_placeholders(topic)) - {"rover"} - ({key_item} if key_item else set())
    if extra:
        problems.append(f"topic: {', '.join('{' + e + '}' for e in sorted(extra))} "
                        "does not appear in the key")
    if key_item and f"{{{key_item}}}" not in topic:
        problems.append(f"topic: must contain {{{key_item}}} like the key, or every {key_item} {clash}")
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
    if m.kind not in KINDS:
        problems.append(f"kind: expected {' or '.join(KINDS)}, got {m.kind!r}")
        return problems
    if m.kind == "service":
        return problems + _service_problems(m)
    service_only: list[tuple[str, Any, Any]] = [
        ("request", m.request, {}), ("write", m.write, "put"), ("response", m.response, None)]
    for name, value, unset in service_only:
        if value != unset:
            problems.append(f"{name}: only a service (kind: service) has a {name}")
    if m.payload and m.direction != "in":
        problems.append("payload: only an inbound topic or a service writes a payload")
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
    key_item = shape.placeholder if item is not None and item.startswith("{") else None
    problems += _placeholder_problems(m.key, m.topic, key_item, "would publish on the same topic")
    if m.otherwise != "error" and (item is None or key_item is not None):
        problems.append("otherwise: only for a key that names one component (radio/lander)")
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
        problems += _payload_problems(m.payload, fields, name, set(used))
        missing = [f.name for f in fields.values() if f.required and f.name not in used
                   and f.name not in m.payload]
        if missing:
            problems.append(f"fields: the input {name} needs {', '.join(missing)}")
        if m.default is not None:
            problems.append("default: only outbound values can be null")
    return problems


def _payload_problems(payload: dict[str, Any], fields: dict[str, Any], name: str,
                      given: set[str]) -> list[str]:
    """Problems of the constant fields a write carries (``payload:``)."""
    problems = []
    for f, value in payload.items():
        if f not in fields:
            problems.append(f"payload.{f}: {name} has no field {f!r} (fields: {', '.join(fields)})")
        elif f in given:
            problems.append(f"payload.{f}: also taken from the message")
        else:
            kind = _field_kind(fields[f])
            if (kind == "bool") != isinstance(value, bool) or (
                    kind == "number" and not isinstance(value, int | float)) or (
                    kind not in ("bool", "number") and not isinstance(value, str)):
                problems.append(f"payload.{f}: {name}.{f} is a {kind}, not {value!r}")
    return problems


_ROS_KINDS = {"bool": "bool", "string": "word", **{t: "number" for t in INT_RANGES},
              "float32": "number", "float64": "number"}


def _service_problems(m: Mapping) -> list[str]:
    """Problems of a service entry (``kind: service``), each starting with its field."""
    problems: list[str] = []
    unused: list[tuple[str, Any, Any]] = [
        ("field", m.field, None), ("fields", m.fields, None), ("convert", m.convert, None),
        ("rate_hz", m.rate_hz, None), ("default", m.default, None), ("integer", m.integer, None),
        ("joint_names", m.joint_names, None), ("options", m.options, {}), ("scale", m.scale, 1.0),
        ("direction", m.direction, "out")]
    for name, value, unset in unused:
        if value != unset:
            problems.append(f"{name}: not used by a service (request, payload and response say "
                            "what it carries)")
    if m.type not in SERVICE_TYPES:
        problems.append(f"type: unknown ROS 2 service type {m.type!r} (known: "
                        f"{', '.join(SERVICE_TYPES)})")
    found = keys.family_of_template(m.key)
    if found is None or found[0].direction != "in":
        problems.append(f"key: a service writes a key the twin reads (lunaris/{{rover}}/...: "
                        f"{', '.join(f.name for f in keys.families('in'))}), not {m.key!r}")
        return problems
    shape, item = found
    key_item = shape.placeholder if item is not None and item.startswith("{") else None
    problems += _placeholder_problems(m.key, m.topic, key_item, "would have the same service")
    if m.otherwise not in OTHERWISE:
        problems.append(f"otherwise: expected {', '.join(OTHERWISE)}, got {m.otherwise!r}")
    elif m.otherwise != "error" and (item is None or key_item is not None):
        problems.append("otherwise: only for a key that names one component (radio/lander)")
    fields = _payload_fields(shape.payload)
    name = shape.payload.__name__
    if m.write == "delete":
        if shape.name not in keys.DELETABLE:
            problems.append(f"write: {shape.name} takes a put, not a delete "
                            f"(deletable: {', '.join(keys.DELETABLE)})")
        if m.request or m.payload:
            problems.append("write: a delete carries no payload: no request or payload fields")
    elif m.write != "put":
        problems.append(f"write: expected put or delete, got {m.write!r}")
    elif m.type in SERVICE_TYPES:
        asked = request_fields(m.type)
        for f, field_name in m.request.items():
            if f not in fields:
                problems.append(f"request.{f}: {name} has no field {f!r} (fields: "
                                f"{', '.join(fields)})")
            elif field_name not in asked:
                problems.append(f"request.{f}: the {m.type} request has no field {field_name!r} "
                                f"(fields: {', '.join(asked) or 'none'})")
            elif _ROS_KINDS.get(asked[field_name]) != _field_kind(fields[f]):
                problems.append(f"request.{f}: {name}.{f} is a {_field_kind(fields[f])}, the "
                                f"request's {field_name} a {asked[field_name]}")
        problems += _payload_problems(m.payload, fields, name, set(m.request))
        missing = [f.name for f in fields.values() if f.required
                   and f.name not in m.request and f.name not in m.payload]
        if missing:
            problems.append(f"request: the write {name} needs {', '.join(missing)}")
        elif not m.request and not m.payload:
            problems.append(f"request: the write would carry nothing; give request or payload "
                            f"fields ({name}: {', '.join(fields)})")
    if m.type in SERVICE_TYPES:
        have = response_fields(m.type)
        for f, what in (m.response or {}).items():
            if f not in have:
                problems.append(f"response.{f}: the {m.type} response has no field {f!r} "
                                f"(fields: {', '.join(have) or 'none'})")
            elif what not in SERVICE_ANSWERS:
                problems.append(f"response.{f}: expected {' or '.join(SERVICE_ANSWERS)}, "
                                f"got {what!r}")
            elif have[f] != SERVICE_ANSWERS[what]:
                problems.append(f"response.{f}: {what} is a {SERVICE_ANSWERS[what]}, the "
                                f"response's {f} a {have[f]}")
    return problems
