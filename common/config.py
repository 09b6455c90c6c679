"""Rover definitions: the YAML of SPEC §3 as typed, validated msgspec Structs.

Loading checks the whole file and reports every problem at once, each with its
path (``battery.ocv_curve.volts: expected 11 values, got 10``), so a vehicle
engineer fixes a file in one pass. Validation is driven by the Struct
annotations below (types, ranges, name patterns; the machinery is
:mod:`common.datafile`) plus the cross-field rules in :func:`_semantic_problems`.
Each field's ``doc`` is its entry in the generated reference
(``docs/reference/rover-file.md``). Nothing here knows about Zenoh.

Longer than 450 lines on purpose: it is the one description of the rover file, every
section with its fields, units, ranges and cross-field rules side by side, which is what
the reference is generated from.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Annotated, Any

import msgspec

from common.datafile import (
    ConfigError,
    Efficiency,
    Fraction,
    Id,
    Name,
    NonNegative,
    Positive,
    Strict,
    doc,
    parse_yaml,
    read_text,
)

__all__ = [
    "Battery",
    "ConfigError",
    "Drive",
    "DriveStart",
    "Load",
    "OcvCurve",
    "Panel",
    "Radio",
    "RadioSite",
    "Rail",
    "Rover",
    "RcPair",
    "ResistanceCurve",
    "RoverInfo",
    "Solar",
    "SolarRail",
    "Thermal",
    "Umbilical",
    "Uncertainty",
    "load_rover",
    "parse_rover",
]


class RoverInfo(Strict, frozen=True):
    """Who the rover is."""

    id: Annotated[Id, doc("used in every key expression (lunaris/<id>/...)")]
    name: Annotated[str, doc("a name for people")]


class OcvCurve(Strict, frozen=True):
    """Per-cell open-circuit voltage against state of charge, linearly interpolated."""

    soc: Annotated[list[Fraction], doc("state of charge points, strictly increasing from 0.0 to 1.0")]
    volts: Annotated[list[NonNegative], doc("per-cell open-circuit voltage at each point [V], "
                                           "never decreasing")]


class Thermal(Strict, frozen=True):
    """Lumped thermal model of the pack: C dT/dt = I^2 R + injected heat - G (T - T_env)."""

    initial_c: Annotated[float, doc("pack temperature at the start [degC]")]
    environment_c: Annotated[float, doc("what the pack exchanges heat with [degC]")]
    heat_capacity_j_per_k: Annotated[Positive, doc("C [J/K]")]
    conductance_w_per_k: Annotated[NonNegative, doc("G [W/K]")]
    max_c: Annotated[float, doc("over-temperature alarm above this [degC]")]
    cutoff_c: Annotated[float, doc("the pack disconnects itself above this [degC]; back on "
                                   "below max_c")]
    min_c: Annotated[float, doc("under-temperature alarm below this [degC]")]


class ResistanceCurve(Strict, frozen=True):
    """A resistance against state of charge: linear between points, held flat outside them."""

    soc: Annotated[list[Fraction], doc("state of charge points, strictly increasing")]
    ohm: Annotated[list[NonNegative], doc("resistance at each point [ohm, whole pack]")]


class RcPair(Strict, frozen=True):
    """A polarisation branch of the equivalent circuit (a resistance in parallel with a
    capacitance, whole pack): dv/dt = I / C - v / (R C)."""

    capacitance_f: Annotated[Positive, doc("C [F]")]
    resistance_ohm: Annotated[Positive | None, doc(
        "R [ohm]; give this or resistance_curve")] = None
    resistance_curve: Annotated[ResistanceCurve | None, doc(
        "R against state of charge [ohm]; give this or resistance_ohm")] = None


class Uncertainty(Strict, frozen=True):
    """What the prediction (lunaris predict) does not know: each is the relative standard
    deviation of a factor drawn once per Monte Carlo sample, 1 + frac * N(0, 1)."""

    capacity_frac: Annotated[Fraction, doc("of the capacity (same state of charge)")] = 0.0
    resistance_frac: Annotated[Fraction, doc("of every resistance of the circuit")] = 0.0
    generation_frac: Annotated[Fraction, doc("of the generation (panels and umbilical) "
                                             "held over the horizon")] = 0.0


class Battery(Strict, frozen=True):
    """The pack: an open-circuit voltage behind a series resistance and, optionally,
    polarisation branches (SPEC §4)."""

    capacity_j: Annotated[Positive, doc("usable energy when full [J]")]
    initial_soc: Annotated[Fraction, doc("state of charge at the start, 0..1")]
    cells_series: Annotated[int, msgspec.Meta(ge=1), doc("cells in series")]
    ocv_curve: OcvCurve
    max_discharge_a: Annotated[Positive, doc("BMS discharge current limit [A]: a demand above "
                                             "it is met only in part")]
    max_charge_w: Annotated[NonNegative, doc("charging power limit [W]")]
    thermal: Thermal
    depleted_soc: Annotated[Fraction, doc("at or below this state of charge the pack is "
                                          "non-operational")] = 0.0
    depleted_hysteresis_soc: Annotated[Fraction, doc(
        "a depleted pack comes back on line once charged this far above depleted_soc, so it "
        "does not chatter on and off")] = 0.05
    internal_resistance_ohm: Annotated[NonNegative | None, doc(
        "whole-pack series resistance R0 [ohm]; required unless resistance_curve is given")] = None
    resistance_curve: Annotated[ResistanceCurve | None, doc(
        "R0 against state of charge [ohm, whole pack]; replaces internal_resistance_ohm")] = None
    rc_pairs: Annotated[list[RcPair], doc(
        "polarisation branches in series with R0 (none: the first release's model)")] = []
    cutoff_cell_v: Annotated[Positive | None, doc(
        "BMS under-voltage cut-off per cell [V]: when the terminal voltage under load falls "
        "below cells_series times this, the pack stops supplying until its open-circuit "
        "voltage has recovered and the demand allows (none: no cut-off)")] = None
    uncertainty: Uncertainty = Uncertainty()

    @property
    def series_resistance(self) -> float | ResistanceCurve:
        """R0: the curve when given, else the constant (0 when neither: a file that parsed
        always has one)."""
        if self.resistance_curve is not None:
            return self.resistance_curve
        return self.internal_resistance_ohm or 0.0


class Rail(Strict, frozen=True):
    """A converter of the PDM from the battery bus."""

    name: Name
    voltage_v: Annotated[Positive, doc("output voltage [V]")]
    current_limit_a: Annotated[Positive, doc("the rail trips above this current [A]; it stays "
                                             "off until reset")]
    efficiency: Annotated[Efficiency, doc("bus draw = rail power / efficiency")]
    essential: Annotated[bool, doc("never shed")] = False
    shed_below_soc: Annotated[Fraction | None, doc(
        "shed below this state of charge (not for essential rails)")] = None
    restore_above_soc: Annotated[Fraction | None, doc(
        "restored when the state of charge climbs back to this; default shed_below_soc + 0.05")] = None
    initially_on: Annotated[bool, doc("switched on at the start")] = True


class Load(Strict, frozen=True):
    """A consumer on a rail: a normal sample around nominal_w each tick, clipped to [0, max_w]."""

    name: Name
    rail: Annotated[Name, doc("the rail it draws from")]
    nominal_w: Annotated[NonNegative, doc("mean power [W], at most max_w")]
    max_w: Annotated[NonNegative, doc("largest power it draws [W]")]
    std_w: Annotated[NonNegative, doc("standard deviation of the power [W]")] = 0.0


class Panel(Strict, frozen=True):
    """A solar panel: irradiance * area * efficiency * max(0, cos(angle)) * (1 - dust) *
    (1 - degradation)."""

    name: Name
    area_m2: Annotated[NonNegative, doc("area [m^2]")]
    efficiency: Annotated[Fraction, doc("cell efficiency, 0..1")]
    degradation: Annotated[Fraction, doc("ageing and radiation damage, 0..1")] = 0.0


class SolarRail(Strict, frozen=True):
    """The panels' own rail: generation reaches the bus through its efficiency."""

    name: Name
    voltage_v: Annotated[Positive, doc("rail voltage [V]")]
    efficiency: Annotated[Efficiency, doc("bus power = panel power * efficiency")]
    current_limit_a: Annotated[Positive | None, doc("shown on the PDM; never trips")] = None


class Solar(Strict, frozen=True):
    """Generation: the panels and the sun."""

    irradiance_w_per_m2: Annotated[NonNegative, doc("solar irradiance [W/m^2] (1361 with no "
                                                    "atmosphere)")]
    sun_angle_deg: Annotated[float, doc("initial angle between the sun and the panel normal [deg]")]
    rail: SolarRail
    panels: list[Panel] = []


class Umbilical(Strict, frozen=True):
    """A wired supply from the lander or a charging station: a cable. A rover that drives
    farther than cable_m from where it was plugged in pulls it out (the twin unplugs it, with
    an event); a traverse does not start while it is plugged in, unless the cable follows the
    rover (follows_rover)."""

    connected: Annotated[bool, doc("plugged in at the start")] = False
    power_w: Annotated[NonNegative, doc("what the connection can supply [W]")] = 0.0
    cable_m: Annotated[NonNegative | None, doc(
        "the cable's reach from where it was plugged in [m, straight line in the site frame]; "
        "none: no slack, the rover cannot drive while plugged in")] = None
    follows_rover: Annotated[bool, doc(
        "the cable pays out behind the rover (a tether): a traverse may start while plugged "
        "in, and the rover is unplugged once farther than cable_m from where it was plugged "
        "in (needs cable_m); false: a traverse is refused while plugged in")] = False


class RadioSite(Strict, frozen=True):
    """Where a radio stands in the site frame (x east, y north). With a drive section, the
    distance and bearing from here to the rover replace the radio's position input."""

    x_m: Annotated[float, doc("east of the site origin [m]")]
    y_m: Annotated[float, doc("north of the site origin [m]")]


class Radio(Strict, frozen=True):
    """A radio the rover talks to: in range inside an ellipse around it."""

    name: Name
    a_m: Annotated[Positive, doc("ellipse semi-axis along x [m]")]
    b_m: Annotated[Positive, doc("ellipse semi-axis along y [m]")]
    offset_x_m: Annotated[float, doc("ellipse centre offset along x [m]")] = 0.0
    offset_y_m: Annotated[float, doc("ellipse centre offset along y [m]")] = 0.0
    load: Annotated[Name | None, doc(
        "the load that powers the rover's end of this link: while it has no power (its rail "
        "off, tripped, failed or shed, or the load's circuit open) the radio is out of range; "
        "none: always powered")] = None
    site: Annotated[RadioSite | None, doc(
        "where the radio stands in the site frame; on a rover with a drive section the radio "
        "then follows the rover's position (drive/state) and refuses the position input")] = None


class DriveStart(Strict, frozen=True):
    """Where the rover is at the start and after a session reset, in the site frame."""

    x_m: Annotated[float, doc("east of the site origin [m]")] = 0.0
    y_m: Annotated[float, doc("north of the site origin [m]")] = 0.0
    z_m: Annotated[float, doc("up [m]")] = 0.0
    heading_deg: Annotated[float, doc("compass heading, clockwise from north [deg]")] = 0.0


class Drive(Strict, frozen=True):
    """The rover moves: drive power and position from physics (SPEC §4, Drive). On a leg of
    grade theta at speed v: F = m g (c_rr cos(theta) + sin(theta)), wheel torque F r, and the
    drive load draws max(0, F v) / drivetrain_efficiency + idle_w, at most its max_w (the rover
    then slows down)."""

    load: Annotated[Name, doc("the load whose power the drive sets while this section exists")]
    mass_kg: Annotated[Positive, doc("mass of the loaded vehicle [kg]")]
    wheel_radius_m: Annotated[Positive, doc("wheel radius [m]")]
    rolling_resistance: Annotated[Fraction, doc("rolling resistance coefficient c_rr on regolith")]
    drivetrain_efficiency: Annotated[Efficiency, doc("wheel power / battery-side power")]
    idle_w: Annotated[NonNegative, doc("motor controllers on, wheels still [W]; drawn moving too")]
    max_speed_m_per_s: Annotated[Positive, doc("fastest commanded speed [m/s]")]
    gravity_m_per_s2: Annotated[Positive, doc("surface gravity [m/s^2] (the Moon: 1.625)")] = 1.625
    start: Annotated[DriveStart, doc("where the rover is at the start and after a reset")] = DriveStart()
    regen_efficiency: Annotated[Fraction, doc(
        "fraction of the braking wheel power (F v < 0, steep downhill) returned to the bus; "
        "0: no regeneration, the drive draws idle_w")] = 0.0
    max_grade_deg: Annotated[float, msgspec.Meta(gt=0.0, lt=90.0), doc(
        "the steepest leg a traverse may have; a steeper traverse is refused [deg]")] = 30.0


class Rover(Strict, frozen=True):
    """A rover definition: one file per rover in config/rovers/."""

    rover: RoverInfo
    battery: Battery
    solar: Solar
    tick_hz: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0), doc("clock rate [Hz]")] = 10.0
    rails: list[Rail] = []
    loads: list[Load] = []
    umbilical: Umbilical = Umbilical()
    radios: list[Radio] = []
    drive: Annotated[Drive | None, doc("optional: the rover moves (see Drive)")] = None

    @property
    def id(self) -> str:
        return self.rover.id


def load_rover(path: str | Path) -> Rover:
    """Read and validate a rover YAML file; raise :class:`ConfigError` listing every problem."""
    return parse_rover(read_text(path), source=str(path))


def parse_rover(text: str, source: str = "<rover>") -> Rover:
    """Validate rover YAML text; raise :class:`ConfigError` listing every problem."""
    data, problems = parse_yaml(text, source, Rover)
    if isinstance(data, dict):
        problems.extend(_semantic_problems(data))
    if problems:
        raise ConfigError(source, problems, data)
    return msgspec.convert(data, Rover)


# -- cross-field rules ---------------------------------------------------------------------


def _typed(value: object, typ: type) -> Any:
    """A part of the file as its Struct, or None when it is not well formed (the structural
    check has reported why): each cross-field rule runs on the parts that are."""
    try:
        return msgspec.convert(value, typ)
    except msgspec.ValidationError:
        return None


def _semantic_problems(d: dict) -> list[str]:
    problems: list[str] = []
    raw_battery = d.get("battery")
    battery: dict = raw_battery if isinstance(raw_battery, dict) else {}
    thermal = _typed(battery.get("thermal"), Thermal)
    if thermal is not None:
        _thermal_rules(thermal, problems)
    curve = _typed(battery.get("ocv_curve"), OcvCurve)
    if curve is not None:
        _curve_rules(curve, problems)
    if raw_battery is not None and isinstance(raw_battery, dict):
        _circuit_rules(battery, curve, problems)
    # Names are read from every entry that has one, well formed or not: a load on a rail
    # that does not exist is reported beside whatever else is wrong in the file.
    rail_names = _names(d.get("rails"))
    load_names = _names(d.get("loads"))
    for i, raw in enumerate(_list(d.get("rails"))):
        rail = _typed(raw, Rail)
        if rail is not None:
            _rail_rules(i, rail, problems)
    for i, raw in enumerate(_list(d.get("loads"))):
        _load_rules(i, raw, rail_names, problems)
    solar = _typed(d.get("solar"), Solar)
    raw_solar = d.get("solar")
    solar_rail = raw_solar.get("rail") if isinstance(raw_solar, dict) else None
    if isinstance(solar_rail, dict) and isinstance(solar_rail.get("name"), str):
        rail_names = [*rail_names, solar_rail["name"]]
    _unique("rails", rail_names, problems)
    _unique("loads", load_names, problems)
    if solar is not None:
        _unique("solar.panels", [p.name for p in solar.panels], problems)
    _unique("radios", _names(d.get("radios")), problems)
    for i, raw in enumerate(_list(d.get("radios"))):
        load = raw.get("load") if isinstance(raw, dict) else None
        if isinstance(load, str) and load not in load_names:
            problems.append(f"radios[{i}].load: no load named {load!r} "
                            f"(loads: {', '.join(load_names) or 'none'})")
    umbilical = _typed(d.get("umbilical"), Umbilical)
    if umbilical is not None and umbilical.follows_rover and umbilical.cable_m is None:
        problems.append("umbilical.follows_rover: a cable that follows the rover needs its "
                        "length, cable_m")
    drive = _typed(d.get("drive"), Drive)
    if drive is not None:
        loads = [x for x in (_typed(x, Load) for x in _list(d.get("loads"))) if x is not None]
        _drive_rules(drive, load_names, loads, problems)
    return problems


def _names(value: object) -> list[str]:
    """The names of a list section's entries that have one (a string)."""
    return [x["name"] for x in _list(value) if isinstance(x, dict) and isinstance(x.get("name"), str)]


def _list(value: object) -> list:
    return value if isinstance(value, list) else []


def _thermal_rules(th: Thermal, problems: list[str]) -> None:
    if not th.min_c < th.max_c < th.cutoff_c:
        problems.append("battery.thermal: expected min_c < max_c < cutoff_c, got "
                        f"{th.min_c:g}, {th.max_c:g}, {th.cutoff_c:g}")


def _curve_rules(curve: OcvCurve, problems: list[str]) -> None:
    soc, volts = curve.soc, curve.volts
    if len(volts) != len(soc):
        problems.append(f"battery.ocv_curve.volts: expected {len(soc)} values, got {len(volts)}")
    if any(b < a for a, b in zip(volts, volts[1:], strict=False)):
        problems.append("battery.ocv_curve.volts: must not decrease as the charge rises")
    if len(soc) < 2:
        problems.append(f"battery.ocv_curve.soc: expected at least 2 points, got {len(soc)}")
        return
    if any(b <= a for a, b in zip(soc, soc[1:], strict=False)):
        problems.append("battery.ocv_curve.soc: must be strictly increasing")
    if soc[0] != 0.0 or soc[-1] != 1.0:
        problems.append(f"battery.ocv_curve.soc: must run from 0.0 to 1.0, got {soc[0]}..{soc[-1]}")


def _circuit_rules(battery: dict, ocv: OcvCurve | None, problems: list[str]) -> None:
    """R0 given once; each branch's resistance given once; every resistance curve well formed;
    a cut-off the full pack can stay above."""
    has_r0 = battery.get("internal_resistance_ohm") is not None
    has_curve = battery.get("resistance_curve") is not None
    if not has_r0 and not has_curve:
        problems.append("battery.internal_resistance_ohm: missing required field "
                        "(or give battery.resistance_curve)")
    elif has_r0 and has_curve:
        problems.append("battery.resistance_curve: replaces internal_resistance_ohm; give one "
                        "of them, not both")
    r_curve = _typed(battery.get("resistance_curve"), ResistanceCurve)
    if r_curve is not None:
        _resistance_curve_rules("battery.resistance_curve", r_curve, problems)
    for i, raw in enumerate(_list(battery.get("rc_pairs"))):
        pair = _typed(raw, RcPair)
        if pair is None:
            continue
        where = f"battery.rc_pairs[{i}]"
        if (pair.resistance_ohm is None) == (pair.resistance_curve is None):
            problems.append(f"{where}: give resistance_ohm or resistance_curve (exactly one), got "
                            f"{'both' if pair.resistance_ohm is not None else 'neither'}")
        if pair.resistance_curve is not None:
            _resistance_curve_rules(f"{where}.resistance_curve", pair.resistance_curve, problems)
            if not all(r > 0.0 for r in pair.resistance_curve.ohm):
                problems.append(f"{where}.resistance_curve.ohm: a branch resistance must be > 0")
    cutoff = battery.get("cutoff_cell_v")
    if ocv is not None and ocv.volts and isinstance(cutoff, int | float) and not isinstance(cutoff, bool) \
            and cutoff >= max(ocv.volts):
        problems.append(f"battery.cutoff_cell_v: must be below the full cell's open-circuit voltage "
                        f"({max(ocv.volts):g} V), got {cutoff:g}: the pack could never supply")


def _resistance_curve_rules(where: str, curve: ResistanceCurve, problems: list[str]) -> None:
    if len(curve.ohm) != len(curve.soc):
        problems.append(f"{where}.ohm: expected {len(curve.soc)} values, got {len(curve.ohm)}")
    if not curve.soc:
        problems.append(f"{where}.soc: expected at least 1 point, got 0")
    elif any(b <= a for a, b in zip(curve.soc, curve.soc[1:], strict=False)):
        problems.append(f"{where}.soc: must be strictly increasing")


def _rail_rules(i: int, r: Rail, problems: list[str]) -> None:
    shed, restore = r.shed_below_soc, r.restore_above_soc
    if restore is not None and shed is None:
        problems.append(f"rails[{i}].restore_above_soc: needs shed_below_soc")
    if shed is not None and restore is not None and restore <= shed:
        problems.append(f"rails[{i}].restore_above_soc: must be above shed_below_soc ({shed}), "
                        f"got {restore}")
    if shed is not None and r.essential:
        problems.append(f"rails[{i}].shed_below_soc: an essential rail is never shed")


def _load_rules(i: int, raw: object, rail_names: list[str], problems: list[str]) -> None:
    rail = raw.get("rail") if isinstance(raw, dict) else None
    if isinstance(rail, str) and rail not in rail_names:
        problems.append(f"loads[{i}].rail: no rail named {rail!r} "
                        f"(rails: {', '.join(rail_names) or 'none'})")
    ld = _typed(raw, Load)
    if ld is not None and ld.nominal_w > ld.max_w:
        problems.append(f"loads[{i}].nominal_w: must not exceed max_w ({ld.max_w}), "
                        f"got {ld.nominal_w}")


def _drive_rules(drive: Drive, load_names: list[str], loads: list[Load],
                 problems: list[str]) -> None:
    """``loads``: the loads that are well formed (the idle power is checked against the drive
    load's max_w when that load is one of them)."""
    if drive.load not in load_names:
        problems.append(f"drive.load: no load named {drive.load!r} "
                        f"(loads: {', '.join(load_names) or 'none'})")
        return
    load = next((ld for ld in loads if ld.name == drive.load), None)
    if load is not None and drive.idle_w >= load.max_w:
        problems.append(f"drive.idle_w: must be below the max_w of load {load.name} "
                        f"({load.max_w:g} W), or the rover could never move; got {drive.idle_w:g}")


def _unique(path: str, names: list[str], problems: list[str]) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            problems.append(f"{path}: name {name!r} is used more than once")
        seen.add(name)


def fingerprint(rover: Rover) -> str:
    """What a rover file says, in 16 hex digits: saved beside a service's state, so that a
    state saved with another version of the file is not resumed against this one (a pack's
    energy against another capacity, an input the file no longer sets)."""
    return hashlib.sha256(msgspec.json.encode(rover)).hexdigest()[:16]
