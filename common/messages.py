"""Payloads of SPEC §5: one msgspec Struct per message, one JSON codec.

Telemetry Structs are what the services publish. Input and command Structs are
decoded strictly at the service boundary: unknown fields, wrong types, NaN,
infinity and out-of-range values raise :class:`BadInput` with a message that
names the field. JSON has no NaN or infinity, and msgspec refuses a number
that overflows to one (``1e999``). A payload with one parameter may also be a bare JSON number
(``60`` for ``input/sun_angle``), see :func:`decode_input`.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal, TypeVar

import msgspec

__all__ = [
    "ActiveFault",
    "ActiveFaults",
    "BadInput",
    "BatteryState",
    "Clock",
    "ClockControl",
    "Event",
    "EventKind",
    "Severity",
    "SnapshotInfo",
    "LoadPower",
    "Percentiles",
    "PowerSummary",
    "Prediction",
    "PredictionRequest",
    "RadioLink",
    "RadioPosition",
    "RailCommand",
    "RailState",
    "SolarPower",
    "SunAngle",
    "UmbilicalInput",
    "UmbilicalState",
    "decode",
    "decode_input",
    "decode_parameters",
    "encode",
    "is_telemetry",
]

T = TypeVar("T", bound=msgspec.Struct)

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
    epoch: int = 0  # counts the session's resets and restores
    cause: str = ""  # what started this epoch: "reset" or "restore:<snapshot>"


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
    heat_w: float = 0.0
    polarisation_v: list[float] = []  # the equivalent circuit's branch voltages (rc_pairs)


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


class RailState(_Msg):
    t_s: float
    voltage_v: float
    current_a: float
    power_w: float
    current_limit_a: float | None
    state: RailStateName
    reason: str = ""


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


class UmbilicalState(_Msg):
    t_s: float
    connected: bool
    power_w: float


class RadioLink(_Msg):
    t_s: float
    in_range: bool
    x_m: float
    y_m: float
    faults: list[str] = []


# What an event says happened: a refused input, a fault's life, an accepted command or
# input, a change of the clock, a bug in a service.
EventKind = Literal["rejected", "fault_injected", "fault_cleared", "fault_raised",
                    "fault_resolved", "command", "input", "clock", "session", "internal_error"]


class Event(_Msg):
    t_s: float
    severity: Severity
    source: str
    kind: EventKind
    key: str
    message: str
    params: dict[str, Any] | None = None


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


class SnapshotInfo(_Msg):
    """One saved snapshot of a rover, as ``get lunaris/<rover>/snapshots`` lists it."""

    name: str
    t_s: float  # the rover's sim time when it was saved
    saved_at: float  # wall time when it was saved [s since the epoch]
    services: list[str]  # the services that hold their part of it


# -- inputs and commands (decoded strictly) -----------------------------------------------


class _Input(msgspec.Struct, forbid_unknown_fields=True):
    pass


class ClockControl(_Input):
    time_scale: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)] | None = None
    paused: bool | None = None


class SunAngle(_Input):
    angle_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]


class RadioPosition(_Input):
    distance_m: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
    angle_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]


class UmbilicalInput(_Input):
    connected: bool


class RailCommand(_Input):
    on: bool | None = None
    reset: bool | None = None


class PredictionRequest(_Input):
    """The parameters of a ``prediction`` query: ``?hours=8;samples=1000`` (``seed`` for a
    repeatable answer)."""

    hours: Annotated[float, msgspec.Meta(gt=0.0, le=168.0)] = 8.0
    samples: Annotated[int, msgspec.Meta(ge=1, le=10_000)] = 1000
    seed: Annotated[int, msgspec.Meta(ge=0)] | None = None


def decode_parameters(text: str, typ: type[T]) -> T:
    """A query's selector parameters (``hours=8;samples=1000``) as an input Struct; raise
    :class:`BadInput` naming the problem (an unknown or repeated name, a value that is not a
    number or out of range)."""
    raw: dict[str, Any] = {}
    for item in (p for p in text.replace("&", ";").split(";") if p.strip()):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise BadInput(f"parameter {item!r} is not name=value")
        if name in raw:
            raise BadInput(f"parameter {name!r} given twice")
        raw[name] = _number(name, value.strip())
    try:
        return msgspec.convert(raw, typ)
    except msgspec.ValidationError as exc:
        raise BadInput(str(exc)) from None


def _number(name: str, value: str) -> int | float:
    try:
        number: int | float = int(value)
    except ValueError:
        try:
            number = float(value)
        except ValueError:
            raise BadInput(f"parameter {name!r} must be a number, got {value!r}") from None
    if isinstance(number, float) and not math.isfinite(number):
        raise BadInput(f"parameter {name!r} must be finite, got {value!r}")
    return number


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


def decode_input(payload: bytes, typ: type[T], *, bare: str | None = None) -> T:
    """Decode an input strictly, raising :class:`BadInput` naming the problem.

    ``bare`` names the field a bare JSON number (or boolean) stands for. An empty
    payload decodes to the Struct's defaults when every field has one.
    """
    text = bytes(payload).strip()
    if not text:
        try:
            return typ()
        except TypeError:
            raise BadInput("empty payload; expected a JSON object") from None
    try:
        raw = msgspec.json.decode(text)
    except msgspec.DecodeError as exc:
        raise BadInput(f"malformed JSON: {exc}") from None
    if bare is not None and not isinstance(raw, dict | list | str) and raw is not None:
        raw = {bare: raw}
    if not isinstance(raw, dict):
        raise BadInput(f"expected a JSON object, got {type(raw).__name__}")
    try:
        return msgspec.convert(raw, typ)
    except msgspec.ValidationError as exc:
        raise BadInput(str(exc)) from None
