"""The fault catalogue of SPEC §6, each kind's typed parameters, and the ``fault_code`` table.

A fault key is ``lunaris/<rover>/fault/<component>/<kind>`` where ``<component>``
is ``battery``, ``umbilical`` or ``<type>/<name>`` for ``load``, ``rail``,
``solar`` and ``radio``. Each kind has its parameter Struct, named after it
(``Dust(fraction)``, ``Heating(heat_w)``, ``Short(resistance_ohm)``, ``Disconnect()`` ...),
all members of one tagged union, :data:`Fault`, whose tags are the kinds' names: the
catalogue (:data:`CATALOGUE`) is built from the Structs, so a kind is named in one place.
An injection's payload is decoded once, at the boundary (:func:`parse_params`: one-parameter
kinds also accept a bare JSON number; parameterless kinds accept only an empty payload or
``{}``), and from there on a fault is a value of :data:`Fault`: the fault book
(:mod:`common.fault_book`) keeps it, and hands a model the faults in effect on each of its
components, which the model applies with ``match`` (``case Dust(fraction=f): ...``).

On the wire a fault's parameters are a JSON object without the tag (``{"fraction": 0.3}``,
``msgspec.structs.asdict``): the kind is the last chunk of its key.

The catalogue speaks two ways: to engineers (each kind's ``description``, the model's own
terms, in the reference) and to instructors (each kind's plain ``name`` and ``effect``; each
parameter's ``label``, ``unit`` and ``hint``, carried by the field itself as msgspec metadata:
``title``, ``extra={"unit": ...}`` and ``description``). :func:`parameters` reads a kind's
parameters with their words and limits, for the console's forms and the CLI's help.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Annotated, Any, NamedTuple, TypeAlias

import msgspec
import msgspec.inspect as mi

from common import keys
from common.messages import ActiveFault, BadInput, decode_input
from common.reasons import shown

__all__ = [
    "CATALOGUE",
    "DERIVED",
    "FAULT_CODES",
    "NAMED_COMPONENTS",
    "RETIRED_CODES",
    "CapacityLoss",
    "Degraded",
    "Disconnect",
    "Dust",
    "Fail",
    "Failure",
    "Fault",
    "FaultKey",
    "FaultParams",
    "Heating",
    "KindSpec",
    "NoParams",
    "Open",
    "Parameter",
    "Resistance",
    "Short",
    "Stuck",
    "battery_fault_code",
    "held_power_w",
    "check_component",
    "injected",
    "kind_of",
    "params_from_dict",
    "parse_fault_key",
    "parameters",
    "parse_params",
    "supplies_device",
]


class FaultParams(msgspec.Struct, forbid_unknown_fields=True, frozen=True, tag_field="kind"):
    """The parameters of one fault kind; the Struct's tag is the kind's name."""


class NoParams(FaultParams, frozen=True):
    """Base of the kinds that take no parameters."""


def _words(label: str, unit: str, hint: str) -> msgspec.Meta:
    """A parameter in an instructor's words: its label, the unit it is typed in, and a hint
    on what it means (read back by :func:`parameters`)."""
    return msgspec.Meta(title=label, description=hint, extra={"unit": unit})


class CapacityLoss(FaultParams, frozen=True, tag="capacity_loss"):
    fraction: Annotated[float, msgspec.Meta(ge=0.0, le=1.0), _words(
        "Capacity lost", "fraction", "0 to 1: 0.2 takes a fifth of the capacity away")]


class Resistance(FaultParams, frozen=True, tag="resistance"):
    factor: Annotated[float, msgspec.Meta(ge=1.0, le=1e6), _words(
        "Internal resistance times", "×", "1 is as new, 3 triples it: the voltage sags more "
        "under load")]


class Heating(FaultParams, frozen=True, tag="heating"):
    heat_w: Annotated[float, msgspec.Meta(ge=0.0, le=1e9), _words(
        "Extra heat", "W", "what the failed thermal control adds, 0 or more")]


class Disconnect(NoParams, frozen=True, tag="disconnect"):
    pass


class Short(FaultParams, frozen=True, tag="short"):
    resistance_ohm: Annotated[float, msgspec.Meta(gt=0.0, le=1e9), _words(
        "Resistance of the short", "Ω", "above 0: the smaller, the larger the current "
        "(0.05 if not given)")] = 0.05


class Open(NoParams, frozen=True, tag="open"):
    pass


class Stuck(FaultParams, frozen=True, tag="stuck"):
    power_w: Annotated[float, msgspec.Meta(ge=0.0, le=1e9), _words(
        "Power drawn", "W", "0 or more: drawn whatever the load is told")]


class Fail(NoParams, frozen=True, tag="fail"):
    pass


class Dust(FaultParams, frozen=True, tag="dust"):
    fraction: Annotated[float, msgspec.Meta(ge=0.0, le=1.0), _words(
        "Dust cover", "fraction", "0 to 1: 0.25 takes a quarter of the panel's output away")]


class Failure(NoParams, frozen=True, tag="failure"):
    pass


class Degraded(FaultParams, frozen=True, tag="degraded"):
    range_scale: Annotated[float, msgspec.Meta(ge=0.0, le=1.0), _words(
        "Range kept", "fraction", "0 to 1: 0.5 leaves half the usual range")]


# Every fault of the catalogue: what the fault book keeps and the models match on.
Fault: TypeAlias = (CapacityLoss | Resistance | Heating | Disconnect | Short | Open | Stuck | Fail
                    | Dust | Failure | Degraded)


class KindSpec(NamedTuple):
    params: type[FaultParams]
    bare: str | None  # the field a bare JSON number stands for
    description: str  # what the model does, in its own terms (the reference)
    name: str  # what an instructor calls it: "Short circuit"
    effect: str  # what it does, in an instructor's words, one line

    @property
    def kind(self) -> str:
        """The kind's name: its Struct's tag."""
        return kind_of(self.params)


def kind_of(params: FaultParams | type[FaultParams]) -> str:
    """The name of a fault kind (``dust``), from its Struct or a value of it."""
    tag = params.__struct_config__.tag
    assert isinstance(tag, str)
    return tag


def _kinds(*specs: KindSpec) -> dict[str, KindSpec]:
    return {spec.kind: spec for spec in specs}


CATALOGUE: dict[str, dict[str, KindSpec]] = {
    "battery": _kinds(
        KindSpec(CapacityLoss, "fraction", "usable capacity shrinks",
                 "Capacity loss", "part of the pack's capacity is gone: it holds less energy"),
        KindSpec(Resistance, "factor", "internal resistance multiplied",
                 "High internal resistance",
                 "the pack's voltage sags more under load and it warms more (age, cold)"),
        KindSpec(Heating, "heat_w", "extra internal heat",
                 "Overheating", "extra heat in the pack, as from a failed thermal control: it "
                 "warms up and, too hot, switches itself off"),
        KindSpec(Disconnect, None, "pack off the bus",
                 "Disconnected", "the pack is off the power bus: nothing runs on the battery"),
    ),
    "load": _kinds(
        KindSpec(Short, "resistance_ohm", "draws V_rail^2 / R (the device behind it gets nothing)",
                 "Short circuit", "draws far more than it should: normally trips its rail"),
        KindSpec(Open, None, "draws nothing (the device behind it gets nothing)",
                 "Open circuit", "a broken wire: the load draws nothing and stops working"),
        KindSpec(Stuck, "power_w", "draws a constant power",
                 "Stuck power draw", "the load draws a fixed power, whatever it is told"),
    ),
    "rail": _kinds(KindSpec(Fail, None, "converter dead",
                            "Converter failure", "the rail and everything on it go off")),
    "solar": _kinds(
        KindSpec(Dust, "fraction", "output scaled by 1 - fraction",
                 "Dust", "the panel's output drops by the share the dust covers"),
        KindSpec(Disconnect, None, "no output", "Disconnected", "the panel gives no power"),
    ),
    "umbilical": _kinds(KindSpec(Disconnect, None, "no supply",
                                 "No supply", "the umbilical supplies nothing, plugged in or not")),
    "radio": _kinds(
        KindSpec(Failure, None, "never in range",
                 "Failure", "the link is lost wherever the rover is"),
        KindSpec(Degraded, "range_scale", "ellipse axes scaled",
                 "Reduced range", "the radio reaches less far: the link is lost sooner"),
    ),
}


class Parameter(NamedTuple):
    """One parameter of a fault kind: its field, its words, and the limits it is checked
    against (``ge``, ``gt``, ``le``, ``lt``)."""

    name: str  # the payload's field: heat_w
    label: str  # "Extra heat"
    unit: str  # "W"
    hint: str  # "what the failed thermal control adds, 0 or more"
    limits: dict[str, float]
    default: float | None  # None: required


def parameters(params: type[FaultParams]) -> list[Parameter]:
    """The parameters of a fault kind (its Struct), with their words and limits; none for the
    kinds that take none."""
    info = mi.type_info(params)
    assert isinstance(info, mi.StructType)  # a FaultParams is a Struct
    out = []
    for f in info.fields:
        t: Any = f.type
        words: dict[str, Any] = {}
        extra: dict[str, Any] = {}
        if isinstance(t, mi.Metadata):
            words, extra, t = t.extra_json_schema or {}, t.extra or {}, t.type
        limits = {k: getattr(t, k) for k in ("ge", "gt", "le", "lt") if getattr(t, k, None) is not None}
        out.append(Parameter(f.name, words.get("title", ""), extra.get("unit", ""),
                             words.get("description", ""), limits,
                             None if f.default is mi.NODEFAULT else f.default))
    return out


NAMED_COMPONENTS = frozenset({"load", "rail", "solar", "radio"})


class FaultKey(NamedTuple):
    component: str  # battery, umbilical, load, rail, solar, radio
    name: str | None  # the load, rail, panel or radio; None for battery and umbilical
    kind: str

    @property
    def path(self) -> str:
        """``load/nav_camera/short`` - the part of the key after ``fault/``."""
        return "/".join(p for p in (self.component, self.name, self.kind) if p)


def check_component(parts: list[str]) -> str:
    """The component type a fault key's chunks after ``fault/`` name; :class:`BadInput` when
    it is missing or not in the catalogue (so no service owns it)."""
    if not parts:
        raise BadInput("no component in the fault key")
    if parts[0] not in CATALOGUE:
        raise BadInput(f"unknown component {parts[0]!r} (known: {', '.join(sorted(CATALOGUE))})")
    return parts[0]


def parse_fault_key(parts: list[str]) -> FaultKey:
    """Parse the chunks after ``fault/``; raise :class:`BadInput` for an unknown component,
    kind or key shape."""
    component = check_component(parts)
    named = component in NAMED_COMPONENTS
    want = 3 if named else 2
    if len(parts) != want:
        shape = f"fault/{component}/<name>/<kind>" if named else f"fault/{component}/<kind>"
        raise BadInput(f"a {component} fault key has the shape {shape}")
    kind = parts[-1]
    if kind not in CATALOGUE[component]:
        known = ", ".join(sorted(CATALOGUE[component]))
        raise BadInput(f"unknown {component} fault kind {kind!r} (known: {known})")
    return FaultKey(component, parts[1] if named else None, kind)


def parse_params(key: FaultKey, payload: bytes) -> Fault:
    """Decode and validate the parameters of an injection into its kind's Struct."""
    spec = CATALOGUE[key.component][key.kind]
    if issubclass(spec.params, NoParams):
        text = bytes(payload).strip()
        if text not in (b"", b"{}"):
            raise BadInput(f"{key.component} {key.kind} takes no parameters (got {shown(text[:60])})")
        return spec.params()  # type: ignore[return-value]  # a member of Fault
    return decode_input(payload, spec.params, bare=spec.bare)  # type: ignore[return-value]


def params_from_dict(key: FaultKey, params: dict) -> Fault:
    """The typed parameters of a fault from their JSON object (a persisted fault, a record
    read back from ``faults/active/<service>``)."""
    try:
        return msgspec.convert(params, CATALOGUE[key.component][key.kind].params)  # type: ignore[return-value]
    except msgspec.ValidationError as exc:
        raise BadInput(f"{key.path}: {exc}") from None


def injected(record: Iterable[ActiveFault], component: str, name: str | None = None) -> list[Fault]:
    """The injected faults a record of faults in effect (``faults/active/<service>``, the
    fault book's) holds for one component (``load``, ``nav_camera``), typed; derived faults
    and other components' are left out."""
    out = []
    for fault in record:
        if fault.origin != "injected":
            continue
        _, parts = keys.split(fault.key)
        parts = parts[1:]  # after fault/
        if parts[:1] != [component] or (name is not None and parts[1:2] != [name]):
            continue
        fk = parse_fault_key(parts)
        out.append(params_from_dict(fk, fault.params))
    return out


def held_power_w(faults: Iterable[FaultParams], rail_voltage_v: float) -> float | None:
    """The power the faults in effect on one load hold it at while its rail is on [W]; None
    when they hold it at nothing (no fault: it draws its samples). Several on one load: a
    short dominates (``V^2 / R``), then an open circuit (0 W), then stuck (its ``power_w``).
    A kind that is not a load's raises ValueError. The loads model applies it; the battery's
    prediction from the live twin holds a faulty load at it (one rule for both)."""
    short_ohm = stuck_w = None
    is_open = False
    for fault in faults:
        match fault:
            case Short(resistance_ohm=ohm):
                short_ohm = ohm
            case Open():
                is_open = True
            case Stuck(power_w=power_w):
                stuck_w = power_w
            case _:
                raise ValueError(f"a load has no fault kind {kind_of(fault)!r}")
    if short_ohm is not None:
        return rail_voltage_v ** 2 / short_ohm
    return 0.0 if is_open else stuck_w


def supplies_device(load_on: bool, faults: Iterable[FaultParams]) -> bool:
    """Whether the device behind a load (a radio, the drive's motors) has power: its rail is
    on, and no fault cuts it off (an open circuit, or a short across it; a ``stuck`` load
    misreports its power, the device still runs)."""
    if not load_on:
        return False
    for fault in faults:
        match fault:
            case Open() | Short():
                return False
    return True


# -- derived faults: raised by the models themselves ----------------------------------------
# These, and only these, are what telemetry's ``faults`` fields and ``fault_code`` carry (SPEC
# §12b): what the rover's own sensors and protection would report. The injected faults live
# in the fault book (``faults/active/<service>``, ``get faults``), which the crew never reads.

DERIVED: dict[str, dict[str, str]] = {
    "battery": {
        "thermal_cutoff": "pack above cutoff_c: it disconnected itself (back on below max_c)",
        "no_output": "the pack supplies nothing though none of its protections switched it off "
                     "(its connection to the bus is open): bus at 0 V",
        "depleted": "state of charge at or below depleted_soc (back on line with hysteresis)",
        "brownout": "demand beyond what the pack can deliver (P > V_oc^2 / 4R, or the current "
                    "limit)",
        "over_current": "the BMS held the discharge current at max_discharge_a",
        "under_voltage": "terminal voltage below the empty-cell voltage",
        "under_voltage_cutoff": "terminal voltage under load below cells_series * cutoff_cell_v: "
                                "the BMS switched the pack off (back when it can hold the demand)",
        "over_temperature": "pack above max_c (alarm)",
        "under_temperature": "pack below min_c (alarm)",
    },
    "rail/<name>": {
        "tripped": "current above current_limit_a: off until reset",
        "shed": "shed below shed_below_soc (restored at restore_above_soc)",
    },
    "load/<name>": {
        "over_current": "drawing more than its max_w (normally for a moment: its rail trips)",
    },
    "radio/<name>": {
        "unpowered": "the radio's load has no power (rail off, tripped, failed or shed, or the "
                     "load's circuit open): never in range",
    },
}


# -- the battery fault_code table (SPEC §6: 0 nominal and 5 depleted are fixed) --------------
# Only the pack's own alarms (DERIVED["battery"]) have a code. When several are active the
# battery reports the most severe: the first in this table.

FAULT_CODES: list[tuple[str, int, str]] = [
    # (alarm, code, meaning)
    ("thermal_cutoff", 6, "pack above cutoff_c: disconnected itself"),
    ("no_output", 7, "pack off the bus: it supplies nothing, none of its protections tripped"),
    ("depleted", 5, "state of charge at or below depleted_soc"),
    ("under_voltage_cutoff", 12, "terminal voltage under load below the cut-off: pack switched off"),
    ("brownout", 4, "demand beyond what the pack can deliver (P > Voc^2 / 4R)"),
    ("over_current", 8, "discharge current above max_discharge_a"),
    ("under_voltage", 3, "terminal voltage below the empty-cell voltage"),
    ("over_temperature", 1, "pack above max_c"),
    ("under_temperature", 2, "pack below min_c"),
]
# Codes no longer sent, never to be given another meaning (a recording may hold them).
RETIRED_CODES: list[tuple[int, str]] = [
    (9, "was: an injected capacity loss (now seen as a smaller capacity_j)"),
    (10, "was: an injected resistance increase (now seen as a deeper voltage sag)"),
    (11, "was: injected heating (now seen as a rising temperature, then over_temperature)"),
]


def battery_fault_code(active: Iterable[str]) -> int:
    """The dashboard's single integer for the pack's active alarms (0 when nominal)."""
    names = set(active)
    for name, code, _ in FAULT_CODES:
        if name in names:
            return code
    return 0
