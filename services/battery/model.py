"""Battery pack: open-circuit voltage curve, bus solution, energy and heat.

Equivalent circuit (SPEC §4): an ideal source ``V_oc`` behind an internal
resistance ``R``. For a demanded terminal power ``P`` [W]::

    V = V_oc - I R,   P = V I   =>   I = (V_oc - sqrt(V_oc^2 - 4 R P)) / (2 R)

computed as ``I = 2 P / (V_oc + sqrt(V_oc^2 - 4 R P))`` which is the same
root, free of cancellation, and reduces to ``P / V_oc`` at ``R = 0``. The pack
can deliver at most ``V_oc^2 / 4R`` (at ``V = V_oc / 2``); beyond it the bus
browns out. The BMS also limits the discharge current to ``max_discharge_a``: a
demand that needs more is met only in part (over-current, and a brown-out).
Negative ``P`` charges the pack, limited to ``max_charge_w``.

Stored energy falls by ``V_oc I dt`` so the ``I^2 R`` loss is paid from the
store and becomes heat. Temperature follows a lumped model
``C dT/dt = I^2 R + Q_inj - G (T - T_env)``, integrated exactly over each step
(stable for any ``dt``).
"""

from __future__ import annotations

import bisect
import math
from typing import NamedTuple

from common.config import Battery as BatteryConfig
from common.faults import FactorParams, FaultKey, FractionParams, HeatParams, Params
from common.messages import Severity

__all__ = ["BatteryModel", "BatteryReading", "BusPoint", "ocv", "solve_bus", "thermal_step"]


class BusPoint(NamedTuple):
    voltage_v: float
    current_a: float  # positive when discharging
    power_w: float  # delivered at the terminals; negative while charging
    brownout: bool  # the demand could not be met (beyond V_oc^2 / 4R or the current limit)
    current_limited: bool = False  # the BMS held the current at max_discharge_a


def ocv(soc: float, curve_soc: list[float], curve_volts: list[float], cells_series: int) -> float:
    """Pack open-circuit voltage [V]: ``cells_series`` times the per-cell curve, linearly
    interpolated, held flat outside [0, 1]. (Plain Python: for one value it is several
    times faster than ``numpy.interp``, and it runs every tick.)"""
    if soc <= curve_soc[0]:
        return cells_series * curve_volts[0]
    if soc >= curve_soc[-1]:
        return cells_series * curve_volts[-1]
    i = bisect.bisect_right(curve_soc, soc)
    s0, s1 = curve_soc[i - 1], curve_soc[i]
    v0, v1 = curve_volts[i - 1], curve_volts[i]
    return cells_series * (v0 + (v1 - v0) * (soc - s0) / (s1 - s0))


def solve_bus(v_oc: float, r_ohm: float, power_w: float) -> BusPoint:
    """Terminal voltage [V] and current [A] for a demanded power [W] (see module docstring)."""
    if not math.isfinite(power_w):
        raise ValueError(f"power_w must be finite, got {power_w}")
    if v_oc <= 0.0:
        return BusPoint(0.0, 0.0, 0.0, power_w > 0.0)
    if power_w == 0.0:
        return BusPoint(v_oc, 0.0, 0.0, False)
    if r_ohm <= 0.0:
        return BusPoint(v_oc, power_w / v_oc, power_w, False)
    p_max = v_oc * v_oc / (4.0 * r_ohm)
    if power_w > p_max:
        current = v_oc / (2.0 * r_ohm)
        return BusPoint(v_oc / 2.0, current, p_max, True)
    current = 2.0 * power_w / (v_oc + math.sqrt(v_oc * v_oc - 4.0 * r_ohm * power_w))
    voltage = v_oc - current * r_ohm
    return BusPoint(voltage, current, voltage * current, False)


def thermal_step(temp_c: float, heat_w: float, conductance_w_per_k: float,
                 heat_capacity_j_per_k: float, env_c: float, dt_s: float) -> float:
    """Exact solution of ``C dT/dt = Q - G (T - T_env)`` over ``dt_s`` with ``Q`` constant."""
    if conductance_w_per_k <= 0.0:
        return temp_c + heat_w * dt_s / heat_capacity_j_per_k
    t_inf = env_c + heat_w / conductance_w_per_k
    return t_inf + (temp_c - t_inf) * math.exp(-conductance_w_per_k * dt_s / heat_capacity_j_per_k)


class BatteryReading(NamedTuple):
    energy_j: float
    capacity_j: float
    soc: float
    ocv_v: float
    voltage_v: float
    current_a: float
    power_w: float
    temperature_c: float
    heat_w: float
    operational: bool
    time_to_empty_s: float | None
    faults: list[str]  # active derived and injected battery faults, by name


class BatteryModel:
    """One pack. ``demand_w`` (net, positive = discharge) is held until the next change;
    :meth:`step` integrates it over ``dt``. The pack's injected faults (SPEC §6) are applied
    by :meth:`apply_fault`."""

    def __init__(self, cfg: BatteryConfig):
        self.cfg = cfg
        self.energy_j = cfg.initial_soc * cfg.capacity_j
        self.temperature_c = cfg.thermal.initial_c
        self.demand_w = 0.0
        self._ocv_soc, self._ocv = -1.0, 0.0
        # injected faults
        self.capacity_loss = 0.0
        self.resistance_factor = 1.0
        self.injected_heat_w = 0.0
        self.disconnected = False
        # latched protections
        self.depleted = self.soc <= cfg.depleted_soc
        self.thermal_cutoff = False

    # -- state ------------------------------------------------------------------------------

    def state(self) -> dict[str, float | bool]:
        """Everything that evolves (not the injected faults: their owner re-applies them)."""
        return {"energy_j": self.energy_j, "temperature_c": self.temperature_c,
                "demand_w": self.demand_w, "depleted": self.depleted,
                "thermal_cutoff": self.thermal_cutoff}

    def set_state(self, state: dict) -> None:
        self.energy_j = float(state["energy_j"])
        self.temperature_c = float(state["temperature_c"])
        self.demand_w = float(state.get("demand_w", 0.0))
        self.depleted = bool(state.get("depleted", self.depleted))
        self.thermal_cutoff = bool(state.get("thermal_cutoff", False))

    # -- derived quantities -----------------------------------------------------------------

    @property
    def capacity_j(self) -> float:
        return self.cfg.capacity_j * (1.0 - self.capacity_loss)

    @property
    def soc(self) -> float:
        cap = self.capacity_j
        return min(1.0, max(0.0, self.energy_j / cap)) if cap > 0.0 else 0.0

    @property
    def resistance_ohm(self) -> float:
        return self.cfg.internal_resistance_ohm * self.resistance_factor

    @property
    def ocv_v(self) -> float:
        soc = self.soc
        if soc != self._ocv_soc:  # evaluated several times a tick at the same charge
            c = self.cfg.ocv_curve
            self._ocv_soc, self._ocv = soc, ocv(soc, c.soc, c.volts, self.cfg.cells_series)
        return self._ocv

    @property
    def operational(self) -> bool:
        """Able to supply the bus: not disconnected, not cut off for heat, not depleted."""
        return not (self.disconnected or self.thermal_cutoff or self.depleted)

    def operating_point(self) -> BusPoint:
        """Where the pack sits on the bus for the present demand."""
        demand = self.demand_w
        if demand > 0.0 and not self.operational:
            return BusPoint(0.0, 0.0, 0.0, False)
        if demand < 0.0:
            if self.disconnected or self.thermal_cutoff or self.energy_j >= self.capacity_j:
                demand = 0.0
            else:
                demand = -min(-demand, self.cfg.max_charge_w)
        if self.disconnected or self.thermal_cutoff:
            return BusPoint(0.0, 0.0, 0.0, False)
        point = solve_bus(self.ocv_v, self.resistance_ohm, demand)
        i_max = self.cfg.max_discharge_a
        if point.current_a > i_max:
            voltage = self.ocv_v - i_max * self.resistance_ohm
            return BusPoint(voltage, i_max, voltage * i_max, True, True)
        return point

    # -- evolution --------------------------------------------------------------------------

    def set_demand(self, power_w: float) -> None:
        if not math.isfinite(power_w):
            raise ValueError(f"power_w must be finite, got {power_w}")
        self.demand_w = power_w

    def apply_fault(self, fault: FaultKey, params: Params | None) -> None:
        """Inject (``params``) or clear (None) one of the pack's faults."""
        if fault.kind == "capacity_loss":
            self.apply_capacity_loss(params.fraction if isinstance(params, FractionParams) else 0.0)
        elif fault.kind == "resistance":
            self.resistance_factor = params.factor if isinstance(params, FactorParams) else 1.0
        elif fault.kind == "heating":
            self.injected_heat_w = params.heat_w if isinstance(params, HeatParams) else 0.0
        elif fault.kind == "disconnect":
            self.disconnected = params is not None
        else:
            raise ValueError(f"the battery has no fault kind {fault.kind!r}")

    def apply_capacity_loss(self, fraction: float) -> None:
        """Shrink usable capacity; energy above the new capacity is lost for good."""
        self.capacity_loss = fraction
        self.energy_j = min(self.energy_j, self.capacity_j)

    def step(self, dt_s: float) -> None:
        """Integrate energy and temperature over ``dt_s`` [s] at the present operating point."""
        if dt_s < 0.0 or not math.isfinite(dt_s):
            raise ValueError(f"dt_s must be finite and >= 0, got {dt_s}")
        point = self.operating_point()
        v_oc = self.ocv_v
        drain_w = v_oc * point.current_a  # chemical power out of the store
        active_s = dt_s
        if drain_w > 0.0 and drain_w * dt_s > self.energy_j:
            active_s = self.energy_j / drain_w  # the store empties part-way through the step
        self.energy_j = min(self.capacity_j, max(0.0, self.energy_j - drain_w * active_s))
        joule_w = point.current_a**2 * self.resistance_ohm * (active_s / dt_s if dt_s else 0.0)
        th = self.cfg.thermal
        self.temperature_c = thermal_step(
            self.temperature_c, joule_w + self.injected_heat_w, th.conductance_w_per_k,
            th.heat_capacity_j_per_k, th.environment_c, dt_s,
        )
        self._update_latches()

    def _update_latches(self) -> None:
        cfg = self.cfg
        if self.soc <= cfg.depleted_soc:
            self.depleted = True
        elif self.depleted and self.soc >= cfg.depleted_soc + cfg.depleted_hysteresis_soc:
            self.depleted = False
        if self.temperature_c > cfg.thermal.cutoff_c:
            self.thermal_cutoff = True
        elif self.thermal_cutoff and self.temperature_c < cfg.thermal.max_c:
            self.thermal_cutoff = False

    # -- reporting --------------------------------------------------------------------------

    def derived_faults(self, point: BusPoint | None = None) -> dict[str, tuple[Severity, str]]:
        """Faults the pack raises itself: name -> (severity, message)."""
        point = point or self.operating_point()
        cfg, th = self.cfg, self.cfg.thermal
        t = self.temperature_c
        out: dict[str, tuple[Severity, str]] = {}
        if self.thermal_cutoff:
            out["thermal_cutoff"] = ("critical", f"pack at {t:.1f} C above cutoff "
                                     f"{th.cutoff_c} C: disconnected itself")
        if self.depleted:
            out["depleted"] = ("critical", f"battery depleted (soc {self.soc:.3f} <= "
                               f"{cfg.depleted_soc})")
        if point.brownout:
            out["brownout"] = ("critical", f"demand {self.demand_w:.1f} W beyond what the pack "
                               f"can deliver ({point.power_w:.1f} W): bus browned out")
        if point.current_limited:
            out["over_current"] = ("critical", f"demand {self.demand_w:.1f} W needs more than "
                                   f"the {cfg.max_discharge_a} A discharge limit")
        v_min = cfg.cells_series * cfg.ocv_curve.volts[0]
        if point.current_a > 0.0 and point.voltage_v < v_min:
            out["under_voltage"] = ("warning", f"bus at {point.voltage_v:.2f} V below "
                                    f"{v_min:.2f} V")
        if t > th.max_c and not self.thermal_cutoff:
            out["over_temperature"] = ("warning", f"pack at {t:.1f} C above {th.max_c} C")
        if t < th.min_c:
            out["under_temperature"] = ("warning", f"pack at {t:.1f} C below {th.min_c} C")
        return out

    def reading(self) -> BatteryReading:
        point = self.operating_point()
        v_oc = self.ocv_v
        faults = list(self.derived_faults(point))
        faults += [name for name, on in (
            ("disconnected", self.disconnected), ("heating", self.injected_heat_w > 0.0),
            ("resistance", self.resistance_factor > 1.0), ("capacity_loss", self.capacity_loss > 0.0),
        ) if on]
        drain_w = v_oc * point.current_a
        usable_j = self.energy_j - self.cfg.depleted_soc * self.capacity_j
        tte: float | None = None  # idle or charging: never empties
        if drain_w > 0.0:
            tte = usable_j / drain_w if usable_j > 0.0 else 0.0
            if not math.isfinite(tte):
                tte = None  # a vanishing draw: as good as idle
        return BatteryReading(
            energy_j=self.energy_j, capacity_j=self.capacity_j, soc=self.soc,
            ocv_v=v_oc,
            voltage_v=point.voltage_v, current_a=point.current_a, power_w=point.power_w,
            temperature_c=self.temperature_c,
            heat_w=point.current_a**2 * self.resistance_ohm + self.injected_heat_w,
            operational=self.operational, time_to_empty_s=tte, faults=faults,
        )
