"""Twin payloads to dashboard messages and back: values, BatteryState, diagnostics.

- **Values**: a field of a twin payload, times ``scale``, rounded half away from zero for
  the integer message types (``voltage_v`` x 1000 -> integer mV) and clamped to the type's
  range; an inbound message back to a twin input.
- :func:`battery_state_message` follows the ``sensor_msgs/msg/BatteryState`` conventions (SI
  units, current negative while discharging, charge and capacity in Ah, percentage 0..1).
- :func:`diagnostic_statuses` reports each component of the rover with the ROS levels
  OK / WARN / ERROR / STALE.
- :func:`odometry_message`: the rover's site position and speed as ``nav_msgs/msg/Odometry``.

Messages are plain dicts of ROS 2 fields; :mod:`services.bridge.cdr` makes bytes of them.
"""

from __future__ import annotations

import math
from typing import Any

import msgspec

from common import keys
from common.config import Battery, Rover
from common.messages import ActiveFault, BadInput, BatteryState, DriveState
from services.bridge.bindings import rover_names
from services.bridge.cdr import ARRAY_TYPES, INT_RANGES, SCALAR_TYPES, constants
from services.bridge.mapping import JOINT_STATE, Mapping

__all__ = [
    "DIAG_ERROR",
    "DIAG_OK",
    "DIAG_STALE",
    "DIAG_WARN",
    "HEALTH",
    "battery_state_message",
    "component_of_fault",
    "components",
    "data_key",
    "diagnostic_array_message",
    "diagnostic_statuses",
    "in_payload",
    "level_name",
    "nominal_voltage_v",
    "odometry_message",
    "out_message",
    "out_value",
    "stamp",
    "topic_message",
]

# == values ====================================================================================


def _round_half_away(x: float) -> int:
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def _ros_kind(m: Mapping) -> str:
    return SCALAR_TYPES.get(m.type) or ARRAY_TYPES.get(m.type) or (
        "float64" if m.type == JOINT_STATE else "")


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
    assert m.field is not None  # a one-value mapping names its field (parse_mapping checks)
    return _scaled(m, getattr(payload, m.field))


def out_message(m: Mapping, payload: msgspec.Struct, stamp_ns: int = 0) -> dict | None:
    """A std_msgs one-value or MultiArray message, or a ``sensor_msgs/msg/JointState`` carrying
    several named values (``name`` and ``position``, stamped ``stamp_ns``), from a twin
    payload; None to publish nothing."""
    if m.fields:
        values = [_scaled(m, getattr(payload, f)) for f in m.fields]
        if any(v is None for v in values):
            return None
        if m.type == JOINT_STATE:
            return {"header": {"stamp": stamp(stamp_ns), "frame_id": m.frame_id},
                    "name": list(m.joint_names or m.fields), "position": values,
                    "velocity": [], "effort": []}
        return _multi_array(m.fields, values)
    value = out_value(m, payload)
    return None if value is None else {"data": value}


def topic_message(m: Mapping, payload: Any, battery: Battery | None, stamp_ns: int,
                  distro: str = "jazzy", stale: bool = False) -> dict | None:
    """The message an outbound topic carries for a twin payload (its converter's, or the
    mapped values'), None to publish nothing; ``battery``: the rover's, for BatteryState."""
    if m.convert == "battery_state":
        return battery_state_message(payload, battery, stamp_ns, m.frame_id, m.options, distro,
                                     stale)
    if m.convert == "odometry":
        return odometry_message(payload, stamp_ns, m.frame_id, m.options)
    return out_message(m, payload, stamp_ns)


def _multi_array(names: list[str], values: list) -> dict:
    # One dimension whose label names the fields in order ("distance_m,angle_deg").
    n = len(values)
    return {"layout": {"dim": [{"label": ",".join(names), "size": n, "stride": n}],
                       "data_offset": 0},
            "data": values}


def in_payload(m: Mapping, msg: dict) -> dict[str, Any]:
    """The twin input or command (a JSON object) for an inbound dashboard message, with the
    mapping's constant ``payload`` fields; :class:`BadInput` if the message does not carry
    what the mapping expects or a value is not finite."""
    if m.fields:
        data = list(msg.get("data", []))
        if len(data) != len(m.fields):
            raise BadInput(f"{m.type} on {m.topic}: expected {len(m.fields)} values "
                           f"({', '.join(m.fields)}), got {len(data)}")
        pairs = list(zip(m.fields, data, strict=True))
    else:
        if "data" not in msg:
            raise BadInput(f"{m.type} on {m.topic}: no data field")
        assert m.field is not None  # a one-value mapping names its field (parse_mapping checks)
        pairs = [(m.field, msg["data"])]
    out: dict[str, Any] = dict(m.payload)  # the fields every write of the mapping carries
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

# == nav_msgs/msg/Odometry ======================================================================


def odometry_message(state: DriveState, stamp_ns: int, frame_id: str = "",
                     options: dict[str, str] | None = None) -> dict:
    """``nav_msgs/msg/Odometry`` from the twin's ``drive/state`` (REP-103: x east, y north,
    z up, the ENU site frame of the twin).

    - ``pose.position`` is the rover's site position [m] in ``frame_id`` (default ``site``);
    - ``pose.orientation``: yaw from the compass heading (``yaw = 90 deg - heading``,
      counter-clockwise from east) and pitch from the grade (nose up is a negative pitch
      about the body's y axis, left);
    - ``twist.linear.x`` is the speed along the ground in the body frame ``child_frame_id``
      (option, default ``base_link``); the covariances are zero: the twin knows its truth.
    """
    options = options or {}
    yaw = math.radians(90.0 - state.heading_deg)
    pitch = -math.radians(state.grade_deg)
    cy, sy = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    return {
        "header": {"stamp": stamp(stamp_ns), "frame_id": frame_id or "site"},
        "child_frame_id": options.get("child_frame_id", "base_link"),
        "pose": {"pose": {"position": {"x": state.x_m, "y": state.y_m, "z": state.z_m},
                          "orientation": {"x": -sy * sp, "y": cy * sp, "z": sy * cp, "w": cy * cp}}},
        "twist": {"twist": {"linear": {"x": state.speed_m_per_s}}},
    }


# == sensor_msgs/msg/BatteryState ===============================================================

# power_supply_health, first match wins: the ROS codes (Linux power-supply class) closest to
# each twin fault; any other fault is UNSPEC_FAILURE, none is GOOD.
HEALTH: list[tuple[str, str]] = [
    ("thermal_cutoff", "OVERHEAT"),
    ("over_temperature", "OVERHEAT"),
    ("depleted", "DEAD"),
    ("under_voltage_cutoff", "DEAD"),  # the BMS cut the pack off at the end of its discharge
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


def battery_state_message(state: BatteryState, battery: Battery | None, stamp_ns: int,
                          frame_id: str = "", options: dict[str, str] | None = None,
                          distro: str = "jazzy", stale: bool = False) -> dict:
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
    - ``power_supply_health`` from the pack's own alarms (:data:`HEALTH`; the telemetry's
      ``faults`` carry no other, SPEC §12b): OVERHEAT, DEAD (depleted or cut off for
      under-voltage), COLD, UNSPEC_FAILURE for any other alarm, GOOD with none; UNKNOWN when
      ``stale`` (the pack's telemetry has gone silent: this is its last word, repeated);
    - ``cell_voltage`` and ``cell_temperature``: one NaN per series cell, the message's way of
      saying the number of cells is known but not their values;
    - ``present`` is always true: a pack off the bus (``disconnected``) is still in the rover,
      and says so through its health and status.

    Without the rover's ``battery`` (a view of the twin that lacks the rover file) the charges
    and the cells are unknown: NaN, and no cells.
    """
    options = options or {}
    c = constants(distro, "sensor_msgs/msg/BatteryState")
    v_nom = nominal_voltage_v(battery) if battery is not None else math.nan
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
    health = "UNKNOWN" if stale else next((h for name, h in HEALTH if name in faults),
                                          "UNSPEC_FAILURE" if faults else "GOOD")
    nan_cells = [math.nan] * (battery.cells_series if battery is not None else 0)
    return {
        "header": {"stamp": stamp(stamp_ns), "frame_id": frame_id},
        "voltage": state.voltage_v,
        "temperature": state.temperature_c,
        "current": -current_a,
        "charge": state.energy_j / v_nom / 3600.0,
        "capacity": state.capacity_j / v_nom / 3600.0,
        "design_capacity": (battery.capacity_j if battery is not None else math.nan) / v_nom / 3600.0,
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
