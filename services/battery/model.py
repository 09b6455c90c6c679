"""Battery pack: the equivalent circuit, its energy books and its protections (SPEC §4).

The circuit: an open-circuit voltage ``V_oc(soc)`` (the per-cell curve times
``cells_series``, linear between points), a series resistance ``R0(soc)`` and ``n``
polarisation branches, each a resistance ``R_j(soc)`` in parallel with a capacitance
``C_j`` (none: the first release's model). With branch voltages ``v_j``::

    V = V_x - R0 I,   V_x = V_oc - sum_j v_j,   dv_j/dt = I / C_j - v_j / (R_j C_j)

For a demanded terminal power ``P`` [W], ``P = V I`` gives
``I = 2 P / (V_x + sqrt(V_x^2 - 4 R0 P))`` (the root of ``R0 I^2 - V_x I + P = 0`` that
meets ``P / V_x`` at ``R0 = 0``, written without cancellation). The pack delivers at most
``V_x^2 / 4 R0`` (a brown-out beyond); the BMS holds the discharge current at
``max_discharge_a``; negative ``P`` charges, up to ``max_charge_w``.

A step of ``dt`` holds ``I`` and integrates every branch exactly (``a = exp(-dt / R_j C_j)``,
``v_j <- a v_j + (1 - a) R_j I``). Its energy books are exact, not approximate: the store
gives ``V_oc I dt``; the terminals take ``integral V I dt``; ``I^2 R0 dt`` and
``integral v_j^2 / R_j dt`` become heat; the rest changes the capacitors' energy
``sum_j C_j v_j^2 / 2``. :attr:`BatteryModel.books` keeps the running totals, and the heat
warms the pack: ``C dT/dt = Q - G (T - T_env)``, integrated exactly over the step.

The store never goes below ``depleted_soc`` (exactly ``0 J`` by default) nor above full: a
step that reaches either runs the current only for the part of the step that had charge
(or room), the branches relax for the rest, and :attr:`BatteryModel.last_step` says what the
step delivered. ``cutoff_cell_v`` latches the pack off when the terminal voltage under load
falls below ``cells_series * cutoff_cell_v``; it comes back when the voltage at no load,
``V_x``, has recovered above that and the demand (the larger of the one it was cut at and
the present one) would hold the terminals above it at steady state (branches charged), so a
pack cut off at the knee of its curve needs charge before it supplies again.

Plain Python floats: one pack steps in a few microseconds. The circuit's functions (the
curves, the bus solution, the thermal step) are :mod:`services.battery.circuit`. The vectorised copy of these
equations, for the Monte Carlo, is :mod:`services.battery.prediction`; a test holds the two
to the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

from common.config import Battery as BatteryConfig
from common.faults import CapacityLoss, Disconnect, FaultParams, Heating, Resistance, kind_of
from common.messages import Severity
from services.battery.circuit import (
    Books,
    BusPoint,
    StepRecord,
    Table,
    circuit_tables,
    interp,
    ocv,
    solve_bus,
    thermal_step,
)

__all__ = ["BatteryModel", "BatteryReading", "Books", "BusPoint", "StepRecord", "Table", "interp",
           "ocv", "solve_bus", "thermal_step"]


_OFF = BusPoint(0.0, 0.0, 0.0, False)
_new = tuple.__new__  # a NamedTuple without its Python-level constructor: this runs every tick
_INF = math.inf


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
    faults: list[str]  # the pack's own alarms (its derived faults), by name
    polarisation_v: list[float]  # the branch voltages v_j


class BatteryModel:
    """One pack. ``demand_w`` (net, positive = discharge) is held until the next change;
    :meth:`step` integrates it over ``dt``. :meth:`set_faults` applies the injected faults in
    effect (SPEC §6; ``resistance`` multiplies R0 and every branch resistance), keeping their
    effect, never a record; it reports only its own alarms (:meth:`derived_faults`)."""

    def __init__(self, cfg: BatteryConfig):
        self.cfg = cfg
        self._ocv, self._r0, self._rj, self._cj, self._cutoff_v = circuit_tables(cfg)
        # hot-path caches: the circuit at a charge, the operating point of a state and demand
        self._at_e = math.nan
        self._at: tuple[float, float, list[float]] = (0.0, 0.0, [])
        self._rev = 0  # moves whenever the branches, the latches or the faults change
        self._point_e = self._point_demand = math.nan
        self._point_rev = -1
        self._point = _OFF
        self._th_dt, self._th_decay = math.nan, 1.0
        self._cap = cfg.capacity_j
        self._depleted_soc = cfg.depleted_soc
        self._capacity_loss = 0.0
        self.energy_j = cfg.initial_soc * cfg.capacity_j
        self.temperature_c = cfg.thermal.initial_c
        self.demand_w = 0.0
        self.branch_v = [0.0] * len(self._cj)
        # what the injected faults do (and the capacity loss, a property)
        self.resistance_factor, self.injected_heat_w = 1.0, 0.0
        self.disconnected = False  # off the bus: its connection open
        # latched protections
        self.depleted = self.soc <= cfg.depleted_soc
        self.thermal_cutoff = False
        self.uv_cutoff = False
        self.cutoff_demand_w = 0.0  # the demand the pack was cut off at
        # the books
        self.last_step = StepRecord(0.0, 0.0, 0.0, 0.0, 0.0)
        self._drawn = self._delivered = self._heat = self._lost = 0.0
        self._changed()

    # -- state ------------------------------------------------------------------------------

    def state(self) -> dict[str, float | bool | list[float]]:
        """Everything that evolves (not the injected faults: their owner re-applies them)."""
        return {"energy_j": self.energy_j, "temperature_c": self.temperature_c,
                "demand_w": self.demand_w, "depleted": self.depleted,
                "thermal_cutoff": self.thermal_cutoff, "polarisation_v": list(self.branch_v),
                "uv_cutoff": self.uv_cutoff, "cutoff_demand_w": self.cutoff_demand_w}

    def set_state(self, state: dict) -> None:
        """Back to a saved :meth:`state`; a state saved before the circuit had its branches
        (or with another number of them) starts them relaxed."""
        self.energy_j = float(state["energy_j"])
        self.temperature_c = float(state["temperature_c"])
        self.demand_w = float(state.get("demand_w", 0.0))
        self.depleted = bool(state.get("depleted", self.depleted))
        self.thermal_cutoff = bool(state.get("thermal_cutoff", False))
        self.uv_cutoff = bool(state.get("uv_cutoff", False))
        self.cutoff_demand_w = float(state.get("cutoff_demand_w", 0.0))
        saved = state.get("polarisation_v")
        if isinstance(saved, list) and len(saved) == len(self._cj):
            self.branch_v = [float(v) for v in saved]
        else:
            self.branch_v = [0.0] * len(self._cj)
        self._changed()

    def clone(self) -> BatteryModel:
        """A pack in the same state with the same injected faults (a prediction's start)."""
        twin = BatteryModel(self.cfg)
        twin.set_state(self.state())
        twin._set_capacity_loss(self.capacity_loss)
        twin.energy_j = self.energy_j
        twin.resistance_factor = self.resistance_factor
        twin.injected_heat_w = self.injected_heat_w
        twin.disconnected = self.disconnected
        twin._changed()
        return twin

    def _changed(self) -> None:
        """Forget the cached circuit and operating point (a fault, a restored state)."""
        self._at_e = math.nan
        self._rev += 1
        f = self.resistance_factor  # the constant resistances times the fault's factor, once
        self._rj_fixed = [0.0 if isinstance(r, Table) else f * r for r in self._rj]
        self._rj_curves = [(k, r) for k, r in enumerate(self._rj) if isinstance(r, Table)]

    # -- derived quantities -----------------------------------------------------------------

    @property
    def capacity_loss(self) -> float:
        """The capacity lost to an injected fault, 0..1 (:meth:`set_faults`)."""
        return self._capacity_loss

    @property
    def capacity_j(self) -> float:
        return self._cap

    @property
    def soc(self) -> float:
        cap = self._cap
        return min(1.0, max(0.0, self.energy_j / cap)) if cap > 0.0 else 0.0

    def _params(self) -> tuple[float, float, list[float]]:
        """``(V_oc, R0, [R_j])`` at the present charge, with the resistance fault applied."""
        e = self.energy_j
        if e != self._at_e:  # asked several times a tick at the same charge
            cap = self._cap
            soc = min(1.0, max(0.0, e / cap)) if cap > 0.0 else 0.0
            f = self.resistance_factor
            r0 = self._r0
            rj = self._rj_fixed.copy()
            for k, t in self._rj_curves:
                rj[k] = f * interp(soc, t)
            self._at = (interp(soc, self._ocv), f * (interp(soc, r0) if isinstance(r0, Table) else r0),
                        rj)
            self._at_e = e
        return self._at

    @property
    def ocv_v(self) -> float:
        return self._params()[0]

    @property
    def resistance_ohm(self) -> float:
        """R0 at the present charge [ohm]."""
        return self._params()[1]

    @property
    def capacitor_j(self) -> float:
        """Energy held in the branch capacitances [J]."""
        return sum(0.5 * c * v * v for c, v in zip(self._cj, self.branch_v, strict=True))

    @property
    def books(self) -> Books:
        return Books(self._drawn, self._delivered, self._heat, self._lost)

    @property
    def operational(self) -> bool:
        """Able to supply the bus: not disconnected, not cut off, not depleted."""
        return not (self.disconnected or self.thermal_cutoff or self.depleted or self.uv_cutoff)

    def operating_point(self) -> BusPoint:
        """Where the pack sits on the bus for the present demand."""
        e, demand, rev = self.energy_j, self.demand_w, self._rev
        if e == self._point_e and demand == self._point_demand and rev == self._point_rev:
            return self._point  # the step and the PDM ask about the same state
        point = self._solve()
        self._point_e, self._point_demand, self._point_rev, self._point = e, demand, rev, point
        return point

    def _solve(self) -> BusPoint:
        demand = self.demand_w
        if self.disconnected or self.thermal_cutoff:
            return _OFF
        if demand > 0.0 and (self.depleted or self.uv_cutoff):
            return _OFF
        if demand < 0.0:
            demand = 0.0 if self.energy_j >= self._cap else max(demand, -self.cfg.max_charge_w)
        v_oc, r0, _ = self._params()
        v_x = v_oc - sum(self.branch_v) if self.branch_v else v_oc
        point = solve_bus(v_x, r0, demand)
        i_max = self.cfg.max_discharge_a
        if point.current_a > i_max:
            voltage = v_x - i_max * r0
            return BusPoint(voltage, i_max, voltage * i_max, True, True)
        return point

    # -- evolution --------------------------------------------------------------------------

    def set_demand(self, power_w: float) -> None:
        if not math.isfinite(power_w):
            raise ValueError(f"power_w must be finite, got {power_w}")
        self.demand_w = power_w

    def set_faults(self, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on the pack, all of them (an empty list: none);
        a kind that is not the battery's raises ValueError, and nothing changes."""
        loss, factor, heat_w, off = 0.0, 1.0, 0.0, False
        for fault in faults:
            match fault:
                case CapacityLoss(fraction=fraction):
                    loss = fraction
                case Resistance(factor=f):
                    factor = f
                case Heating(heat_w=w):
                    heat_w = w
                case Disconnect():
                    off = True
                case _:
                    raise ValueError(f"the battery has no fault kind {kind_of(fault)!r}")
        self.resistance_factor, self.injected_heat_w, self.disconnected = factor, heat_w, off
        self._set_capacity_loss(loss)

    def _set_capacity_loss(self, fraction: float) -> None:
        """Shrink usable capacity; energy above the new capacity is lost for good."""
        self._capacity_loss = fraction
        self._cap = self.cfg.capacity_j * (1.0 - fraction)
        excess = self.energy_j - self._cap
        if excess > 0.0:
            self._lost += excess
            self.energy_j = self._cap
        self._changed()

    def step(self, dt_s: float) -> StepRecord:
        """Integrate the circuit, the store and the temperature over ``dt_s`` [s] at the
        present operating point (see the module docstring); returns what the step did."""
        if not 0.0 <= dt_s < _INF:
            raise ValueError(f"dt_s must be finite and >= 0, got {dt_s}")
        i = self.operating_point().current_a
        v_oc, r0, rj = self._params()
        self._rev += 1  # the branches and latches move below
        e0 = self.energy_j
        drain = v_oc * i  # out of the store [W]
        active = dt_s
        if i > 0.0:
            floor = self._depleted_soc * self._cap
            if drain * dt_s >= e0 - floor:  # reaches the floor within the step: stop there
                active = max(0.0, (e0 - floor) / drain)
                self.energy_j = min(e0, floor)
                self.depleted = True
            else:
                self.energy_j = e0 - drain * dt_s
        elif i < 0.0:
            cap = self._cap
            if -drain * dt_s >= cap - e0:  # full within the step: stop there
                active = max(0.0, (cap - e0) / -drain)
                self.energy_j = max(e0, cap)
            else:
                self.energy_j = e0 - drain * dt_s
        heat = i * i * r0 * active
        v_integral = 0.0  # integral over the active part of sum_j v_j
        bv = self.branch_v
        rest = dt_s - active
        exp, expm1 = math.exp, math.expm1
        for j, c in enumerate(self._cj):
            r = rj[j]
            tau = r * c
            v = bv[j]
            if active > 0.0:
                x = active / tau
                a = exp(-x)
                one_a = -expm1(-x)
                v_inf = r * i
                d = v - v_inf
                v_integral += v_inf * active + d * tau * one_a
                # integral of v^2 / R: >= 0, though its terms nearly cancel when dt << tau
                h = (v_inf * v_inf * active + 2.0 * v_inf * d * tau * one_a
                     + 0.5 * d * d * tau * one_a * (1.0 + a)) / r
                if h > 0.0:
                    heat += h
                v = v_inf + d * a
            if rest > 0.0 and v != 0.0:  # no current for the rest of the step: it relaxes
                b = exp(-rest / tau)
                heat += 0.5 * c * v * v * (-expm1(-rest / tau)) * (1.0 + b)
                v *= b
            bv[j] = v
        delivered = (v_oc - r0 * i) * i * active - i * v_integral
        drawn = drain * active  # the store moved by this, to its own rounding
        self._drawn += drawn
        self._delivered += delivered
        self._heat += heat
        th = self.cfg.thermal
        q = (heat / dt_s if dt_s > 0.0 else 0.0) + self.injected_heat_w
        g = th.conductance_w_per_k
        if g > 0.0:  # thermal_step, with its decay kept while dt does not change
            if dt_s != self._th_dt:
                self._th_dt, self._th_decay = dt_s, math.exp(-g * dt_s / th.heat_capacity_j_per_k)
            t_inf = th.environment_c + q / g
            self.temperature_c = t_inf + (self.temperature_c - t_inf) * self._th_decay
        else:
            self.temperature_c = thermal_step(self.temperature_c, q, g, th.heat_capacity_j_per_k,
                                              th.environment_c, dt_s)
        self._update_latches()
        record = self.last_step = _new(StepRecord, (dt_s, active, drawn, delivered, heat))
        return record

    def _update_latches(self) -> None:
        self._rev += 1
        cfg = self.cfg
        cap = self._cap
        soc = min(1.0, max(0.0, self.energy_j / cap)) if cap > 0.0 else 0.0
        if soc <= cfg.depleted_soc:
            self.depleted = True
        elif self.depleted and soc >= cfg.depleted_soc + cfg.depleted_hysteresis_soc:
            self.depleted = False
        th, t = cfg.thermal, self.temperature_c
        if t > th.cutoff_c:
            self.thermal_cutoff = True
        elif self.thermal_cutoff and t < th.max_c:
            self.thermal_cutoff = False
        cutoff_v = self._cutoff_v
        if cutoff_v is None:
            return
        if not self.uv_cutoff:
            point = self.operating_point()
            if point.current_a > 0.0 and point.voltage_v < cutoff_v:
                self.uv_cutoff = True
                self.cutoff_demand_w = self.demand_w
                self._rev += 1
        elif self._recovered(cutoff_v):
            self.uv_cutoff = False
            self._rev += 1

    def _recovered(self, cutoff_v: float) -> bool:
        v_oc, r0, rj = self._params()
        if v_oc - sum(self.branch_v) < cutoff_v:
            return False
        demand = max(self.cutoff_demand_w, self.demand_w)
        if demand <= 0.0:
            return True
        steady = solve_bus(v_oc, r0 + sum(rj), demand)
        return not steady.brownout and steady.voltage_v >= cutoff_v

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
        elif self.disconnected:  # what its BMS sees: an open output, no protection of its own
            out["no_output"] = ("critical", "the pack supplies nothing: its connection to the "
                                "bus is open (bus at 0 V)")
        if self.depleted:
            out["depleted"] = ("critical", f"battery depleted (soc {self.soc:.3f} <= "
                               f"{cfg.depleted_soc})")
        if self.uv_cutoff:
            out["under_voltage_cutoff"] = (
                "critical", f"terminal voltage fell below the cut-off {self._cutoff_v:.2f} V "
                f"under {self.cutoff_demand_w:.1f} W: pack off until it can hold that demand")
        if point.brownout:
            out["brownout"] = ("critical", f"demand {self.demand_w:.1f} W beyond what the pack "
                               f"can deliver ({point.power_w:.1f} W): bus browned out")
        if point.current_limited:
            out["over_current"] = ("critical", f"demand {self.demand_w:.1f} W needs more than "
                                   f"the {cfg.max_discharge_a} A discharge limit")
        v_min = self._ocv.y[0]
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
        v_oc, r0, rj = self._params()
        faults = list(self.derived_faults(point))
        drain_w = v_oc * point.current_a
        usable_j = self.energy_j - self.cfg.depleted_soc * self.capacity_j
        tte: float | None = None  # idle or charging: never empties
        if drain_w > 0.0:
            tte = usable_j / drain_w if usable_j > 0.0 else 0.0
            if not math.isfinite(tte):
                tte = None  # a vanishing draw: as good as idle
        # the pack's own losses (I^2 R): an injected heating shows only as temperature (SPEC 12b)
        heat_w = point.current_a**2 * r0 + sum(
            v * v / r for v, r in zip(self.branch_v, rj, strict=True) if r > 0.0)
        return BatteryReading(
            energy_j=self.energy_j, capacity_j=self.capacity_j, soc=self.soc, ocv_v=v_oc,
            voltage_v=point.voltage_v, current_a=point.current_a, power_w=point.power_w,
            temperature_c=self.temperature_c, heat_w=heat_w, operational=self.operational,
            time_to_empty_s=tte, faults=faults, polarisation_v=list(self.branch_v),
        )
