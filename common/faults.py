"""The fault catalogue of SPEC §6 and the battery ``fault_code`` table.

A fault key is ``lunaris/<rover>/fault/<component>/<kind>`` where ``<component>``
is ``battery``, ``umbilical`` or ``<type>/<name>`` for ``load``, ``rail``,
``solar`` and ``radio``. Each kind has a parameter Struct; one-parameter kinds
also accept a bare JSON number; parameterless kinds accept only an empty payload
(or ``{}``).
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import msgspec

from common.messages import BadInput, decode_input
from common.reasons import shown

__all__ = [
    "CATALOGUE",
    "DERIVED",
    "FAULT_CODES",
    "NAMED_COMPONENTS",
    "FactorParams",
    "FaultKey",
    "FractionParams",
    "HeatParams",
    "KindSpec",
    "NoParams",
    "Params",
    "RangeScaleParams",
    "ShortParams",
    "StuckParams",
    "battery_fault_code",
    "check_component",
    "fault_of",
    "params_from_dict",
    "parse_fault_key",
    "parse_params",
]


class Params(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """The parameters of one fault kind; the model that owns the component reads them."""


_Params = Params


class NoParams(_Params, frozen=True):
    pass


class FractionParams(_Params, frozen=True):
    fraction: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]


class FactorParams(_Params, frozen=True):
    factor: Annotated[float, msgspec.Meta(ge=1.0, le=1e6)]


class HeatParams(_Params, frozen=True):
    heat_w: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]


class ShortParams(_Params, frozen=True):
    resistance_ohm: Annotated[float, msgspec.Meta(gt=0.0, le=1e9)] = 0.05


class StuckParams(_Params, frozen=True):
    power_w: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]


class RangeScaleParams(_Params, frozen=True):
    range_scale: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]


class KindSpec(NamedTuple):
    params: type[_Params]
    bare: str | None  # the field a bare JSON number stands for
    description: str


_NONE = NoParams

CATALOGUE: dict[str, dict[str, KindSpec]] = {
    "battery": {
        "capacity_loss": KindSpec(FractionParams, "fraction", "usable capacity shrinks"),
        "resistance": KindSpec(FactorParams, "factor", "internal resistance multiplied"),
        "heating": KindSpec(HeatParams, "heat_w", "extra internal heat"),
        "disconnect": KindSpec(_NONE, None, "pack off the bus"),
    },
    "load": {
        "short": KindSpec(ShortParams, "resistance_ohm", "draws V_rail^2 / R"),
        "open": KindSpec(_NONE, None, "draws nothing"),
        "stuck": KindSpec(StuckParams, "power_w", "draws a constant power"),
    },
    "rail": {"fail": KindSpec(_NONE, None, "converter dead")},
    "solar": {
        "dust": KindSpec(FractionParams, "fraction", "output scaled by 1 - fraction"),
        "disconnect": KindSpec(_NONE, None, "no output"),
    },
    "umbilical": {"disconnect": KindSpec(_NONE, None, "no supply")},
    "radio": {
        "failure": KindSpec(_NONE, None, "never in range"),
        "degraded": KindSpec(RangeScaleParams, "range_scale", "ellipse axes scaled"),
    },
}

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


def fault_of(path: str, params: dict | None = None) -> tuple[FaultKey, Params | None]:
    """A fault and its typed parameters from its path (``load/nav_camera/short``) and JSON
    parameters; ``params`` None stands for a clearing. For callers that hold a model directly
    (the composed twin, tests)."""
    fk = parse_fault_key(path.split("/"))
    return fk, None if params is None else params_from_dict(fk, params)


def parse_params(key: FaultKey, payload: bytes) -> Params:
    """Decode and validate the parameters of an injection into the kind's Struct."""
    spec = CATALOGUE[key.component][key.kind]
    if spec.params is NoParams:
        text = bytes(payload).strip()
        if text not in (b"", b"{}"):
            raise BadInput(f"{key.component} {key.kind} takes no parameters (got {shown(text[:60])})")
        return NoParams()
    return decode_input(payload, spec.params, bare=spec.bare)


def params_from_dict(key: FaultKey, params: dict) -> Params:
    """The typed parameters of a fault from their JSON object (a persisted fault)."""
    try:
        return msgspec.convert(params, CATALOGUE[key.component][key.kind].params)
    except msgspec.ValidationError as exc:
        raise BadInput(f"{key.path}: {exc}") from None


# -- derived faults: raised by the models themselves ----------------------------------------

DERIVED: dict[str, dict[str, str]] = {
    "battery": {
        "thermal_cutoff": "pack above cutoff_c: it disconnected itself (back on below max_c)",
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
}


# -- the battery fault_code table (SPEC §6: 0 nominal and 5 depleted are fixed) --------------
# When several faults are active the battery reports the most severe: the first in this table.

FAULT_CODES: list[tuple[str, int, str]] = [
    # (fault name, code, meaning)
    ("thermal_cutoff", 6, "pack above cutoff_c: disconnected itself"),
    ("disconnected", 7, "pack off the bus (injected disconnect)"),
    ("depleted", 5, "state of charge at or below depleted_soc"),
    ("under_voltage_cutoff", 12, "terminal voltage under load below the cut-off: pack switched off"),
    ("brownout", 4, "demand beyond what the pack can deliver (P > Voc^2 / 4R)"),
    ("over_current", 8, "discharge current above max_discharge_a"),
    ("under_voltage", 3, "terminal voltage below the empty-cell voltage"),
    ("over_temperature", 1, "pack above max_c"),
    ("under_temperature", 2, "pack below min_c"),
    ("heating", 11, "injected extra heat (failed thermal control)"),
    ("resistance", 10, "injected internal resistance increase"),
    ("capacity_loss", 9, "injected capacity loss"),
]
_CODE = {name: code for name, code, _ in FAULT_CODES}


def battery_fault_code(active: list[str] | set[str]) -> int:
    """The dashboard's single integer for a set of active battery faults (0 when nominal)."""
    for name, code, _ in FAULT_CODES:
        if name in active:
            return code
    return 0
