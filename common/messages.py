"""Payloads of SPEC §5: one msgspec Struct per message, one JSON codec.

Telemetry Structs are what the services publish. Input and command Structs are
decoded strictly at the service boundary: unknown fields, wrong types, NaN,
infinity and out-of-range values raise :class:`BadInput` with a message that
names the field. JSON has no NaN or infinity, and msgspec refuses a number
that overflows to one (``1e999``). A payload with one parameter may also be a bare JSON number
(``60`` for ``input/sun_angle``), see :func:`decode_input`.

Longer than 450 lines on purpose: one Struct per payload of SPEC §5 and the one strict
reader of inputs, kept together as the single table the keys, the tools and the reference
are built from.
"""

from __future__ import annotations

import json
import math
import re
from typing import Annotated, Any, Literal, TypeVar

import msgspec
import msgspec.inspect

from common.reasons import humane, json_error, shown

__all__ = [
    "BARE_FIELD",
    "COMMANDED_OFF",
    "ActiveFault",
    "ActiveFaults",
    "ArmFault",
    "ArmedFault",
    "BadInput",
    "BatteryState",
    "BridgeDelivery",
    "Clock",
    "ClockControl",
    "DriveRoute",
    "DriveState",
    "DriveStatus",
    "DriveTraverse",
    "DustInput",
    "Event",
    "EventKind",
    "FlavourDelivery",
    "ExpectationMark",
    "Severity",
    "SessionInfo",
    "SessionStart",
    "SESSION_ID",
    "SNAPSHOT_NAME",
    "SnapshotInfo",
    "TimelineMark",
    "TRAINEE_MAX",
    "trainee_problem",
    "LoadPower",
    "Percentiles",
    "PowerSummary",
    "Prediction",
    "PredictionRequest",
    "RadioLink",
    "RadioPosition",
    "RailCommand",
    "RailState",
    "RouteWaypoint",
    "ScenarioMark",
    "SiteXY",
    "SiteXYZ",
    "SolarPower",
    "SunAngle",
    "TraverseWaypoint",
    "UmbilicalInput",
    "UmbilicalState",
    "decode",
    "decode_input",
    "read_json",
    "convert_input",
    "decode_parameters",
    "humane",
    "encode",
    "is_telemetry",
]

T = TypeVar("T", bound=msgspec.Struct)
SNAPSHOT_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")  # a snapshot's name: one key chunk
# a session's id: the UTC time it began, YYYYMMDD-HHMMSS, and .NNN for the second, third ...
# begun within one second (services.clock.model.session_id): ids sort in the order they began
SESSION_ID = re.compile(r"^\d{8}-\d{6}(\.\d{3})?$")

Severity = Literal["info", "warning", "critical"]
RailStateName = Literal["on", "off", "tripped", "shed", "failed"]


class _Msg(msgspec.Struct, omit_defaults=False):
    pass


# -- telemetry ----------------------------------------------------------------------------


class Clock(_Msg):
    t_s: float
    dt_s: float
    seq: int
    time_scale: float
    paused: bool
    epoch: int = 0  # counts the twin's resets and restores (a session begins with one)
    cause: str = ""  # what started this epoch: "reset" or "restore:<snapshot>"
    session: str = ""  # the trainee session running (its id: see SessionInfo); "" from an older clock


class BatteryState(_Msg):
    t_s: float
    energy_j: float
    capacity_j: float
    soc: float
    ocv_v: float
    voltage_v: float
    current_a: float  # positive when discharging
    power_w: float  # at the terminals, positive when discharging
    temperature_c: float
    operational: bool
    fault_code: int
    faults: list[str]
    time_to_empty_s: float | None  # null while charging or idle
    heat_w: Annotated[float, msgspec.Meta(description=(
        "the heat of the pack's own electrical losses (I^2 R) [W]; an injected heating fault is "
        "not in it: it shows only as the temperature it raises"))] = 0.0
    polarisation_v: list[float] = []  # the equivalent circuit's branch voltages (rc_pairs)
    depleted_soc: Annotated[float, msgspec.Meta(description=(
        "the state of charge at which the pack counts as empty and goes off line (0..1, the "
        "rover file's depleted_soc): time_to_empty_s is the time to reach it at the present "
        "draw"))] = 0.0
    cutoff_v: Annotated[float | None, msgspec.Meta(description=(
        "the BMS cut-off [V] (cells_series * cutoff_cell_v): when the terminal voltage under "
        "load falls below it the pack stops supplying, which a heavy draw can bring before "
        "depleted_soc; null when the rover file sets none"))] = None

class Percentiles(msgspec.Struct, omit_defaults=False):
    """The 5th, 50th and 95th percentiles of a Monte Carlo outcome; null where not reached."""

    p05: float | None
    p50: float | None
    p95: float | None


class Prediction(_Msg):
    """``get lunaris/<rover>/prediction?hours=8;samples=1000``: the Monte Carlo of the rover's
    futures from its live state (SPEC §4, §5)."""

    t_s: float  # sim time of the state the futures start from
    horizon_s: float
    samples: int
    time_to_empty_s: Percentiles  # from t_s to depleted or cut off; null: not within the horizon
    soc_at_horizon: Percentiles
    computed_in_s: float  # wall time the Monte Carlo took
    step_s: float = 0.0  # its integration step
    notes: list[str] = []  # what was assumed where the live state was not known


class LoadPower(_Msg):
    t_s: float
    power_w: float
    rail: str
    on: bool
    faults: list[str]


COMMANDED_OFF = "commanded off"  # a RailState's reason when its rail was switched off by command


class RailState(_Msg):
    t_s: float
    voltage_v: float
    current_a: float
    power_w: float
    current_limit_a: float | None
    state: RailStateName
    reason: str = ""  # why it is not on, in words (COMMANDED_OFF, the trip's cause ...)


class PowerSummary(_Msg):
    t_s: float
    load_power_w: float
    bus_power_w: float
    generation_w: float
    net_battery_power_w: float
    bus_voltage_v: float = 0.0


class SolarPower(_Msg):
    t_s: float
    power_w: float
    sun_angle_deg: float
    dust: float
    faults: list[str] = []


class SiteXY(_Msg):
    """A point on the site's map [m]: x east, y north of the site origin."""

    x_m: float
    y_m: float


class SiteXYZ(_Msg):
    """A point in the site frame [m]: x east, y north of the site origin, z up."""

    x_m: float
    y_m: float
    z_m: float


class UmbilicalState(_Msg):
    """``umbilical/state``: whether the umbilical supplies the rover, and where its cable was
    plugged in (for a map)."""

    t_s: float
    connected: bool
    power_w: float
    plugged_at: Annotated[SiteXYZ | None, msgspec.Meta(description=(
        "where the rover was when the umbilical was plugged in (site frame) [m]; null while "
        "it is not connected"))] = None
    cable_m: Annotated[float | None, msgspec.Meta(description=(
        "how far the rover may drive from where it was plugged in before it pulls the plug "
        "out [m] (the rover file's umbilical.cable_m); null: no slack"))] = None


class RadioLink(_Msg):
    """``radio/<radio>/link``: whether the rover is in range of the radio, the rover's offset
    from the radio (``x_m`` east, ``y_m`` north [m]), and, for a map, where the radio stands
    and its footprint as the rover file gives it: the link is in range inside
    ``((x - offset_x_m) / a_m)^2 + ((y - offset_y_m) / b_m)^2 <= 1``. The footprint is the
    nominal one: an injected degradation shows only as a link lost sooner."""

    t_s: float
    in_range: bool
    x_m: float
    y_m: float
    faults: list[str] = []
    site: Annotated[SiteXY | None, msgspec.Meta(description=(
        "where the radio stands (site frame) [m]; null when the rover file gives it no site"))] = None
    a_m: Annotated[float, msgspec.Meta(description=(
        "the footprint's semi-axis east-west [m], nominal"))] = 0.0
    b_m: Annotated[float, msgspec.Meta(description=(
        "the footprint's semi-axis north-south [m], nominal"))] = 0.0
    offset_x_m: Annotated[float, msgspec.Meta(description=(
        "the footprint's centre east of the radio [m]"))] = 0.0
    offset_y_m: Annotated[float, msgspec.Meta(description=(
        "the footprint's centre north of the radio [m]"))] = 0.0
    follows_drive: Annotated[bool, msgspec.Meta(description=(
        "the rover's position comes from its drive (drive/state): the position input "
        "input/radio/<radio>/position is refused"))] = False


DriveStatus = Literal["parked", "driving", "power_limited", "unpowered", "arrived"]


class DriveState(_Msg):
    """``drive/state``: where the rover is in the site frame (x east, y north, z up) and what
    its drive does. ``status``: ``parked`` (no traverse), ``driving``, ``power_limited`` (slowed
    by the drive load's max_w), ``unpowered`` (halted: the drive load has no power), ``arrived``
    (at the last waypoint)."""

    t_s: float
    x_m: float
    y_m: float
    z_m: float
    speed_m_per_s: float  # along the ground
    heading_deg: float  # compass: clockwise from north (y)
    grade_deg: float  # of the leg being driven, positive uphill
    tractive_force_n: float  # F = m g (c_rr cos(grade) + sin(grade)); 0 at a standstill
    wheel_torque_nm: float  # F r, shared by the wheels
    power_w: float  # what the drive load draws (battery side of the drivetrain)
    odometer_m: float
    waypoint: int | None  # index of the waypoint driven to; null when not on a traverse
    moving: bool
    status: DriveStatus = "parked"
    waypoints: int = 0  # in the traverse being driven (or the last one)
    remaining_m: float = 0.0  # along the traverse, to its last waypoint
    energy_j: float = 0.0  # drawn by the drive since the start (or the last reset)


class RouteWaypoint(_Msg):
    """A waypoint of the traverse being driven, site frame [m], with the speed of the leg
    that ends there [m/s]."""

    x_m: float
    y_m: float
    z_m: float
    speed_m_per_s: float


class DriveRoute(_Msg):
    """``drive/route``: the traverse the rover follows, for a map. Published when it changes
    (a traverse accepted, replaced or stopped, a reset, a restore) and cached for late
    joiners, never every tick: where the rover is along it is ``drive/state`` (``waypoint``,
    ``status``). Empty (``start`` null, no waypoints) when the rover is parked; kept once it
    has arrived."""

    t_s: float
    start: Annotated[SiteXYZ | None, msgspec.Meta(description=(
        "where the rover was when the traverse began (site frame) [m]; null when parked or "
        "not known (a snapshot older than this field)"))]
    waypoints: Annotated[list[RouteWaypoint], msgspec.Meta(description=(
        "in the order they are driven through; empty when parked"))]
    return_to_start: Annotated[bool, msgspec.Meta(description=(
        "after the last waypoint the rover comes back through them to start"))]


class FlavourDelivery(_Msg):
    """What one output flavour of the bridge delivers of one rover (SPEC §13d)."""

    flavour: Annotated[str, msgspec.Meta(description=(
        "ros2dds, rmw_zenoh, json or ros2 (the rclpy node)"))]
    readers: Annotated[int | None, msgspec.Meta(description=(
        "ros2: the most subscriptions matched by one of the rover's topics; the Zenoh "
        "flavours: 1 when some subscriber matches the rover's watched topic, else 0 (Zenoh "
        "tells whether, not how many); null: nothing to watch yet"))]
    topics: Annotated[int, msgspec.Meta(description="the rover's topics watched in this flavour")]
    topics_read: Annotated[int, msgspec.Meta(description="of them, those with a reader")]
    sent: Annotated[int, msgspec.Meta(description="messages sent since the bridge started")]
    last_send_t_s: Annotated[float | None, msgspec.Meta(description=(
        "the rover's sim time of the last message sent [s]; null: none yet"))]
    last_send_wall_s: Annotated[float | None, msgspec.Meta(description=(
        "wall time of the last message sent [s since 1970]; null: none yet"))]
    errors: Annotated[int, msgspec.Meta(description="sends that failed since the bridge started")]
    last_error: Annotated[str, msgspec.Meta(description="the last failure, in words")]
    receiving: Annotated[bool, msgspec.Meta(description="some reader sees the rover's topics")]
    silent_since_wall_s: Annotated[float | None, msgspec.Meta(description=(
        "wall time the last reader went away [s since 1970], when the flavour had readers "
        "and has none now; else null"))]


class BridgeDelivery(_Msg):
    """``bridge/delivery``: what the bridge delivers of a rover to the crew's dashboard, about
    once a second (SPEC §13d): per output flavour, its readers, messages sent, the last send,
    errors. ``receiving``: some flavour has a reader now; ``silent_since_wall_s``: when the
    dashboard that was receiving lost its last reader (null while receiving, or before any
    dashboard was ever seen)."""

    t_s: float
    wall_s: Annotated[float, msgspec.Meta(description=(
        "the bridge's wall time of this record [s since 1970]"))]
    receiving: bool
    silent_since_wall_s: float | None
    ever_received: Annotated[bool, msgspec.Meta(description=(
        "some flavour has had a reader since the bridge started"))]
    flavours: list[FlavourDelivery]


# What an event says happened: a refused input, a fault's life, an accepted command or
# input, a change of the clock, a bug in a service, events the journal never received, the
# state folder's disk full or nearly (``disk_full``: critical when the journal cannot be
# written, warning when space runs low, info when it is back).
EventKind = Literal["rejected", "fault_injected", "fault_cleared", "fault_raised",
                    "fault_resolved", "command", "input", "clock", "session", "scenario",
                    "internal_error", "state_damaged", "journal_gap", "mark", "disk_full",
                    "fault_armed", "fault_warned", "fault_fired", "fault_cancelled",
                    "delivery"]


class Event(_Msg):
    t_s: float
    severity: Severity
    source: str
    kind: EventKind
    key: str
    message: str
    params: dict[str, Any] | None = None
    source_id: str = ""  # the publishing session's Zenoh id: with seq, names an event of a rover
    seq: int = 0  # counts the events a session has published for the rover, from 1
    # who acted: crew, instructor or scenario (the write's attachment), twin (its own:
    # protection, derived faults, internal errors); "" from a journal written before
    actor: str = ""
    # the trainee session it belongs to (SessionInfo.id): the session its service was in,
    # as the clock's ticks said; "" from a journal written before sessions, or a service that
    # has heard no tick yet (the journal counts it in the session running then)
    session: str = ""


FaultOrigin = Literal["injected", "derived"]


class ActiveFault(_Msg):
    """A fault in effect: injected by an instructor, or derived by a model itself."""

    key: str  # lunaris/<rover>/fault/<component>/<kind>, or the derived fault's key
    params: dict[str, Any]
    since_t_s: float
    origin: FaultOrigin
    severity: Severity = "warning"


class ActiveFaults(_Msg):
    """``faults/active/<service>``: every fault in effect on the components one service owns
    (published on every change, cached for late joiners, and answered live to a query)."""

    t_s: float
    service: str
    faults: list[ActiveFault]
    epoch: int = 0  # the clock's epoch of t_s: a clock that lost its time learns it back here
    session: str = ""  # the session of t_s: a clock that lost its state learns it back here


class ArmedFault(_Msg):
    """A fault armed to fire later (SPEC 13b), as ``get lunaris/<rover>/faults/armed`` lists it."""

    key: Annotated[str, msgspec.Meta(description=(
        "the armed key, lunaris/<rover>/faults/armed/<component>/<kind>"))]
    fault: Annotated[str, msgspec.Meta(description=(
        "the fault it fires: <component>/<kind> as after fault/ (load/nav_camera/short)"))]
    value: Annotated[Any, msgspec.Meta(description=(
        "the fault's parameters, as a put on fault/... takes them; null for none"))]
    at_t_s: Annotated[float | None, msgspec.Meta(description="armed for this sim time [s]")]
    in_s: Annotated[float | None, msgspec.Meta(description=(
        "armed for this long after it was armed [s of sim time]"))]
    when: Annotated[str | None, msgspec.Meta(description=(
        "armed for a condition (the scenario language)"))]
    warn_s: Annotated[float, msgspec.Meta(description="the warning's lead [s of sim time]")]
    armed_t_s: Annotated[float, msgspec.Meta(description="sim time it was armed [s]")]
    due_t_s: Annotated[float | None, msgspec.Meta(description=(
        "sim time it fires [s]; null for a condition that has not held yet"))]
    warned_t_s: Annotated[float | None, msgspec.Meta(description=(
        "sim time its warning was given [s]; null before"))]
    actor: Annotated[str, msgspec.Meta(description="who armed it: the fault is fired as theirs")]


class SnapshotInfo(_Msg):
    """One saved snapshot of a rover, as ``get lunaris/<rover>/snapshots`` lists it."""

    name: str
    t_s: float  # the rover's sim time when it was saved
    saved_at: float  # wall time when it was saved [s since the epoch]
    services: list[str]  # the services that hold their part of it


class SessionInfo(_Msg):
    """One trainee session of a rover, as ``get lunaris/<rover>/sessions`` lists it (oldest
    first; the last is the running one)."""

    id: Annotated[str, msgspec.Meta(description=(
        "the session's id: the UTC wall time it began, YYYYMMDD-HHMMSS (one second later than "
        "the previous session's when two begin within a second); what "
        "faults/journal?session=<id> and lunaris report --session take"))]
    trainee: Annotated[str, msgspec.Meta(description=(
        "the trainee (or crew) named by control/session; \"\" for a session no control/session "
        "began (the twin's first)"))]
    start_t_s: Annotated[float, msgspec.Meta(description="the rover's sim time when it began [s]")]
    end_t_s: Annotated[float | None, msgspec.Meta(description=(
        "the rover's sim time when it ended [s]; null while it runs"))]
    started_wall: Annotated[float | None, msgspec.Meta(description=(
        "wall time when it began [s since the Unix epoch]; null when the journal lost the "
        "event that said"))]
    from_snapshot: Annotated[str | None, msgspec.Meta(description=(
        "the snapshot it began from; null when it began from the rover file"))] = None
    events: Annotated[int, msgspec.Meta(description="the events journalled in it")] = 0


# -- inputs and commands (decoded strictly) -----------------------------------------------


class _Input(msgspec.Struct, forbid_unknown_fields=True):
    pass


class ArmFault(_Input):
    """``faults/armed/<component>/<kind>``: a fault armed for a time or a condition (SPEC 13b);
    exactly one of ``at_t_s``, ``in_s`` and ``when`` (checked by :func:`common.armed.parse_arm`)."""

    value: Annotated[Any, msgspec.Meta(description=(
        "the fault's parameters, as a put on fault/<component>/<kind> takes them"))] = None
    at_t_s: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)] | None = None
    in_s: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)] | None = None
    when: Annotated[str, msgspec.Meta(max_length=1000)] | None = None
    # seconds of sim time between the warning and the firing; null: the default, 10
    warn_s: Annotated[float, msgspec.Meta(ge=0.0, le=1e6)] | None = 10.0


class ClockControl(_Input):
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    paused: bool | None = None


class SunAngle(_Input):
    angle_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]


class DustInput(_Input):
    """Dust laid on one panel as an input (the dashboard's), 0..1 of its output lost."""

    fraction: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]


class RadioPosition(_Input):
    """A negative distance is a position on the opposite bearing (the source report's own
    test: -5 m at 180 deg is 5 m at 0 deg)."""

    distance_m: Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]
    angle_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]


Coordinate = Annotated[float, msgspec.Meta(ge=-1e7, le=1e7)]  # site frame [m]: within 10,000 km


class TraverseWaypoint(_Input):
    x_m: Annotated[Coordinate, msgspec.Meta(description="east of the site origin [m]")]
    y_m: Annotated[Coordinate, msgspec.Meta(description="north of the site origin [m]")]
    z_m: Annotated[float, msgspec.Meta(ge=-1e5, le=1e5, description="up [m]")]
    speed_m_per_s: Annotated[
        Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] | None,
        msgspec.Meta(description="the speed of the leg that ends here [m/s]; default the "
                                 "traverse's")] = None


class DriveTraverse(_Input):
    """``input/drive/traverse``: drive through the waypoints in order, from where the rover
    is, at ``speed_m_per_s`` (default: the rover's max_speed_m_per_s); with
    ``return_to_start``, back through them to where the traverse began."""

    waypoints: list[TraverseWaypoint]
    speed_m_per_s: Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] | None = None
    return_to_start: bool = False


class UmbilicalInput(_Input):
    connected: bool


class RailCommand(_Input):
    on: bool | None = None
    reset: bool | None = None


class PredictionRequest(_Input):
    """The parameters of a ``prediction`` query: ``?hours=8;samples=1000`` (``seed`` for a
    repeatable answer; ``timeout_s``: how long the asker waits, after which the battery
    service stops computing it)."""

    hours: Annotated[float, msgspec.Meta(gt=0.0, le=168.0)] = 8.0
    samples: Annotated[int, msgspec.Meta(ge=1, le=10_000)] = 1000
    seed: Annotated[int, msgspec.Meta(ge=0)] | None = None
    timeout_s: Annotated[float, msgspec.Meta(gt=0.0, le=600.0)] = 60.0


def decode_parameters(text: str, typ: type[T]) -> T:
    """A query's selector parameters (``hours=8;samples=1000``) as an input Struct; raise
    :class:`BadInput` naming the problem (an unknown or repeated name, a value that is not a
    number or out of range)."""
    raw: dict[str, Any] = {}
    for item in (p for p in text.replace("&", ";").split(";") if p.strip()):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise BadInput(f"{shown(item)} is not name=value")
        if name in raw:
            raise BadInput(f"{name} is given twice")
        raw[name] = _number(name, value.strip())
    return convert_input(raw, typ)


def _number(name: str, value: str) -> int | float:
    try:
        number: int | float = int(value)
    except ValueError:
        try:
            number = float(value)
        except ValueError:
            raise BadInput(f"{name} must be a number (got {shown(value)})") from None
    if isinstance(number, float) and not math.isfinite(number):
        raise BadInput(f"{name} must be a finite number (got {shown(value)})")
    return number


# The field a bare JSON number or boolean stands for, for the inputs and commands of one
# parameter (``60`` on ``input/sun_angle``); the services, the CLI and the console read it here.
BARE_FIELD: dict[type[msgspec.Struct], str] = {
    SunAngle: "angle_deg",
    DustInput: "fraction",
    UmbilicalInput: "connected",
    RailCommand: "on",
}


class ExpectationMark(_Input):
    """An expectation of a scenario scored (SPEC §12d), as the journal keeps it: the params of
    its ``scenario`` event hold it under ``expectation``. Times are the rover's sim time [s]."""

    index: Annotated[int, msgspec.Meta(ge=0, le=10_000)]  # the step, from 0
    label: Annotated[str, msgspec.Meta(max_length=200)]
    condition: Annotated[str, msgspec.Meta(max_length=1000)]
    within_s: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
    met: bool
    at_t_s: float | None = None  # when it was met; null when missed
    armed_t_s: float | None = None  # when the crew's time began; null: never armed
    start_t_s: float | None = None  # when the scenario started
    detail: Annotated[str, msgspec.Meta(max_length=1000)] = ""


class ScenarioMark(_Input):
    """``control/scenario``: a scenario's progress, put by the player so that the journal (and
    the debrief) marks when it started, each step that fired, each expectation scored and how
    it ended."""

    scenario: Annotated[str, msgspec.Meta(min_length=1, max_length=200)]
    what: Literal["start", "step", "end", "expect"]
    message: Annotated[str, msgspec.Meta(max_length=1000)]
    step: Annotated[int, msgspec.Meta(ge=0, le=10_000)] | None = None
    expectation: ExpectationMark | None = None  # with what: expect


TRAINEE_MAX = 64  # characters of a trainee's name
_TRAINEE_PUNCTUATION = " -_.'&"
TRAINEE_WORDS = "a trainee's name is letters, digits, spaces and - _ . ' &"


def trainee_problem(name: str) -> str | None:
    """Why ``name`` cannot name a trainee, in words (None: it can): letters of any script,
    digits, spaces and ``- _ . ' &``, 1 to 64 of them, not only spaces."""
    if not name.strip():
        return "give the trainee's name (or the crew's)"
    bad = [c for c in dict.fromkeys(name) if not (c.isalnum() or c in _TRAINEE_PUNCTUATION)]
    if bad:
        said = ", ".join(dict.fromkeys(repr(c) if c.isprintable() else "a control character" for c in bad))
        return f"{TRAINEE_WORDS}; this one has {said}"
    if name != name.strip():
        return f"{TRAINEE_WORDS}, without spaces before or after"
    return None


class SessionStart(_Input):
    """``control/session``: end the running session and begin a trainee's: the twin reset to
    its rover file, or to a snapshot (restored all or nothing)."""

    trainee: Annotated[str, msgspec.Meta(max_length=TRAINEE_MAX, description=(
        "who is trained in the new session: " + TRAINEE_WORDS))]
    from_snapshot: Annotated[str, msgspec.Meta(description=(
        "a snapshot to begin from (lunaris snapshot list); absent: the rover file"))] | None = None

    def __post_init__(self) -> None:
        problem = trainee_problem(self.trainee)
        if problem is not None:
            raise ValueError(problem)
        if self.from_snapshot is not None and not SNAPSHOT_NAME.match(self.from_snapshot):
            raise ValueError(f"from_snapshot {shown(self.from_snapshot)} names no snapshot: a "
                             "snapshot name is letters, digits, '-', '_' and '.', at most 64")


class TimelineMark(_Input):
    """``control/mark``: an instructor's mark on the session's timeline (a ``mark`` event)."""

    text: Annotated[str, msgspec.Meta(min_length=1, max_length=500, description=(
        "what the instructor notes, as the debrief will show it"))]

    def __post_init__(self) -> None:
        if not self.text.strip():
            raise ValueError("give the mark's text")
        if any(not c.isprintable() for c in self.text):
            raise ValueError("a mark's text is one line of printable characters")


def is_telemetry(struct: type[msgspec.Struct]) -> bool:
    """Published by the twin (as opposed to an input or command sent to it)."""
    return issubclass(struct, _Msg)


# -- codec --------------------------------------------------------------------------------

_encoder = msgspec.json.Encoder()
_decoders: dict[type, msgspec.json.Decoder] = {}


class BadInput(ValueError):
    """An input that is rejected; the message says why, in words a person understands."""


def encode(msg: msgspec.Struct) -> bytes:
    return _encoder.encode(msg)


def decode(payload: bytes, typ: type[T]) -> T:
    """Decode a telemetry payload (trusted: written by :func:`encode`)."""
    dec = _decoders.get(typ)
    if dec is None:
        dec = _decoders[typ] = msgspec.json.Decoder(typ)
    return dec.decode(payload)


MAX_INPUT_BYTES = 65536  # an input is a few numbers; anything this large is not one
_MAX_DEPTH = 32  # an input nests an object or two; deeper is not an input


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise BadInput(f"the field {shown(key)} appears twice")
        out[key] = value
    return out


def _no_constant(name: str) -> Any:
    raise BadInput(f"{name} is not a number (JSON has no NaN or infinity)")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise BadInput(f"the number {_abridged(text)} is too large (it overflows to infinity)")
    return value


MAX_INT_DIGITS = 100  # no input takes a longer integer (Python refuses beyond 4,300)


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise BadInput(f"the number {_abridged(text)} has {digits:,} digits: far too long for "
                       f"an input (at most {MAX_INT_DIGITS})")
    return int(text)


def _abridged(text: str) -> str:
    return text if len(text) <= 24 else f"{text[:10]}...{text[-6:]}"


def _no_surrogate(value: Any) -> None:
    """Refuse text holding a lone surrogate (``"\\ud800"``): JSON lets it be written, but it is
    no character, and nothing can encode it again."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError as exc:
                code = ord(item[exc.start])
                raise BadInput(f"a text holds \\u{code:04x}, half of a character (a lone "
                               "surrogate): not valid Unicode") from None
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)


def _depth(text: bytes) -> int:
    depth = deepest = 0
    in_string = escaped = False
    for byte in text:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            deepest = max(deepest, depth)
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return deepest


def read_json(payload: bytes, *, bare: bool = False) -> Any:
    """JSON from an untrusted input, strictly: UTF-8 text (no encoded or escaped lone
    surrogates), no NaN or infinity, no integer longer than ``MAX_INT_DIGITS``, no key twice in
    an object, at most ``_MAX_DEPTH`` levels deep and ``MAX_INPUT_BYTES`` long. Anything else is
    :class:`BadInput` saying in plain words what is wrong (``bare``: a bare number or boolean
    would do, and the words say so)."""
    data = bytes(payload)
    if len(data) > MAX_INPUT_BYTES:
        raise BadInput(f"the payload is {len(data):,} bytes: too large for an input "
                       f"(at most {MAX_INPUT_BYTES:,})")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BadInput(f"not text: byte {exc.start + 1} is not UTF-8 ({exc.reason})") from None
    if _depth(data) > _MAX_DEPTH:
        raise BadInput(f"nested more than {_MAX_DEPTH} levels deep: an input is an object of a "
                       "few values")
    try:
        value = json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_no_constant,
                           parse_float=_finite, parse_int=_bounded_int)
    except json.JSONDecodeError as exc:
        raise BadInput(json_error(text, exc.msg, exc.pos, bare)) from None
    except RecursionError:
        raise BadInput(f"nested more than {_MAX_DEPTH} levels deep: an input is an object of a "
                       "few values") from None
    except ValueError as exc:  # BadInput is one; anything else the parser raises is bad input too
        if isinstance(exc, BadInput):
            raise
        raise BadInput(f"not valid JSON: {exc}") from None
    _no_surrogate(value)
    return value


def decode_input(payload: bytes, typ: type[T], *, bare: str | None = None) -> T:
    """Decode an input strictly, raising :class:`BadInput` saying in plain words what is wrong
    (``fraction must be at most 1 (got 30)``).

    ``bare`` names the field a bare JSON number (or boolean) stands for. An empty
    payload decodes to the Struct's defaults when every field has one.
    """
    text = bytes(payload).strip()
    if not text:
        try:
            return typ()
        except TypeError:
            raise BadInput("the payload is empty: give a JSON object"
                           + (f" or a bare value of {bare}" if bare else "")) from None
    raw = read_json(text, bare=bare is not None)
    if bare is not None and not isinstance(raw, dict | list | str) and raw is not None:
        raw = {bare: raw}
    if not isinstance(raw, dict):
        wanted = "a number, true/false or a JSON object" if bare else "a JSON object"
        raise BadInput(f"{shown(raw)} is not {wanted}")
    return convert_input(raw, typ)


def convert_input(raw: Any, typ: type[T]) -> T:
    """``raw`` (decoded JSON) as the input Struct ``typ``; :class:`BadInput` in plain words."""
    try:
        return msgspec.convert(raw, typ)
    except msgspec.ValidationError as exc:
        raise BadInput(humane(str(exc), raw, list(typ.__struct_fields__), _choices(typ))) from None


def _choices(typ: type[msgspec.Struct]) -> dict[str, list[Any]]:
    """The values of each field of ``typ`` that takes one of a fixed set (a Literal)."""
    out: dict[str, list[Any]] = {}
    info = msgspec.inspect.type_info(typ)
    for f in getattr(info, "fields", ()):
        t = f.type
        options = t.types if isinstance(t, msgspec.inspect.UnionType) else (t,)
        for option in options:
            if isinstance(option, msgspec.inspect.LiteralType):
                out[f.name] = list(option.values)
    return out
