"""The equivalent circuit's functions of plain numbers: its curves, the bus solution and the
thermal step (SPEC §4). The pack (:mod:`services.battery.model`) steps with them; the
vectorised prediction (:mod:`services.battery.prediction`) evaluates the same expressions on
arrays, and a test holds the two to the same numbers.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.config import Battery as BatteryConfig
from common.config import ResistanceCurve
from common.curves import Table, interp, ocv

__all__ = ["Books", "BusPoint", "CircuitTables", "StepRecord", "Table", "circuit_tables", "interp",
           "ocv", "solve_bus", "thermal_step"]


class BusPoint(NamedTuple):
    voltage_v: float
    current_a: float  # positive when discharging
    power_w: float  # delivered at the terminals; negative while charging
    brownout: bool  # the demand could not be met (beyond V_x^2 / 4R0 or the current limit)
    current_limited: bool = False  # the BMS held the current at max_discharge_a



_new = tuple.__new__  # a NamedTuple without its Python-level constructor: this runs every tick


def solve_bus(v_x: float, r_ohm: float, power_w: float) -> BusPoint:
    """Terminal voltage [V] and current [A] for a demanded power [W] behind ``v_x`` and
    ``r_ohm`` (see the module docstring); never NaN, never a division by zero."""
    if not math.isfinite(power_w):
        raise ValueError(f"power_w must be finite, got {power_w}")
    if v_x <= 0.0:
        return _new(BusPoint, (0.0, 0.0, 0.0, power_w > 0.0, False))
    if power_w == 0.0:
        return _new(BusPoint, (v_x, 0.0, 0.0, False, False))
    if r_ohm <= 0.0:
        return _new(BusPoint, (v_x, power_w / v_x, power_w, False, False))
    p_max = v_x * v_x / (4.0 * r_ohm)
    if power_w > p_max:
        return _new(BusPoint, (v_x / 2.0, v_x / (2.0 * r_ohm), p_max, True, False))
    current = 2.0 * power_w / (v_x + math.sqrt(v_x * v_x - 4.0 * r_ohm * power_w))
    voltage = v_x - current * r_ohm
    return _new(BusPoint, (voltage, current, voltage * current, False, False))


def thermal_step(temp_c: float, heat_w: float, conductance_w_per_k: float,
                 heat_capacity_j_per_k: float, env_c: float, dt_s: float) -> float:
    """Exact solution of ``C dT/dt = Q - G (T - T_env)`` over ``dt_s`` with ``Q`` constant."""
    if conductance_w_per_k <= 0.0:
        return temp_c + heat_w * dt_s / heat_capacity_j_per_k
    t_inf = env_c + heat_w / conductance_w_per_k
    return t_inf + (temp_c - t_inf) * math.exp(-conductance_w_per_k * dt_s / heat_capacity_j_per_k)


class StepRecord(NamedTuple):
    """What one step did [J, s]: ``active_s`` of its ``dt_s`` carried the current."""

    dt_s: float
    active_s: float
    drawn_j: float  # out of the store (negative while charging)
    delivered_j: float  # at the terminals
    heat_j: float  # in R0 and the branch resistances

    @property
    def power_w(self) -> float:
        """Mean power at the terminals over the step [W]."""
        return self.delivered_j / self.dt_s if self.dt_s > 0.0 else 0.0


class Books(NamedTuple):
    """Running energy totals since the pack was made [J]. Exactly (to rounding):
    ``drawn = delivered + heat + capacitor_j - capacitor_j at the start``, and the store fell
    by ``drawn + lost`` (to the rounding of the store itself, 1e-16 of its content a step)."""

    drawn_j: float
    delivered_j: float
    heat_j: float
    lost_j: float  # removed by a capacity_loss fault


def _resistance(r: float | ResistanceCurve) -> float | Table:
    return Table.of(r.soc, r.ohm) if isinstance(r, ResistanceCurve) else float(r)


class CircuitTables(NamedTuple):
    """A pack design's circuit as the models read it: the pack's OCV [V], R0 and each
    branch's resistance [ohm] (a number or a table over the state of charge), the branches'
    capacitances [F] and the pack's cut-off voltage [V] (None: no cut-off)."""

    ocv: Table
    r0: float | Table
    rj: list[float | Table]
    cj: list[float]
    cutoff_v: float | None


def circuit_tables(cfg: BatteryConfig) -> CircuitTables:
    """The tables of a pack design, shared by one pack and by many (:mod:`.packs`)."""
    return CircuitTables(
        Table.of(cfg.ocv_curve.soc, cfg.ocv_curve.volts, cfg.cells_series),
        _resistance(cfg.series_resistance),
        [_resistance(p.resistance_curve if p.resistance_curve is not None
                     else p.resistance_ohm or 0.0) for p in cfg.rc_pairs],
        [p.capacitance_f for p in cfg.rc_pairs],
        cfg.cells_series * cfg.cutoff_cell_v if cfg.cutoff_cell_v is not None else None)
