"""Many packs at once: :class:`services.battery.model.BatteryModel`'s equations on numpy arrays.

One element per Monte Carlo sample (:mod:`services.battery.prediction`). Every expression is
the scalar model's, in the same order, so that with the same inputs each element follows
the scalar pack (``tests/services/test_prediction.py`` holds them together); the samples may
differ in capacity and resistance (a factor each). Comments name the scalar method a block
mirrors; read the physics there.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.config import Battery as BatteryConfig
from services.battery.circuit import Table, circuit_tables
from services.battery.model import BatteryModel

__all__ = ["Packs", "Points"]


class Points(NamedTuple):
    """Operating points of every pack: terminal voltage [V] and current [A]."""

    voltage_v: np.ndarray
    current_a: np.ndarray


def _interp(x: np.ndarray, t: Table) -> np.ndarray:
    return np.interp(x, t.x, t.y)


class Packs:
    """``n`` packs of one design, all starting from one pack's state and faults, each with
    its own capacity and resistance factors (1 for the pack as it is)."""

    def __init__(self, pack: BatteryModel, capacity_factor: np.ndarray,
                 resistance_factor: np.ndarray):
        cfg: BatteryConfig = pack.cfg
        n = len(capacity_factor)
        self.cfg = cfg
        self._ocv, self._r0, self._rj, self._cj, self._cutoff_v = circuit_tables(cfg)
        # The sample's pack: the same state of charge of a capacity scaled by its factor.
        self.cap = pack.capacity_j * capacity_factor
        self.energy_j = pack.soc * self.cap if np.any(capacity_factor != 1.0) else np.full(
            n, pack.energy_j)
        self.factor = pack.resistance_factor * resistance_factor
        self.branch_v = [np.full(n, v) for v in pack.branch_v]
        self.temperature_c = np.full(n, pack.temperature_c)
        self.depleted = np.full(n, pack.depleted)
        self.thermal_cutoff = np.full(n, pack.thermal_cutoff)
        self.uv_cutoff = np.full(n, pack.uv_cutoff)
        self.cutoff_demand_w = np.full(n, pack.cutoff_demand_w)
        self.disconnected = pack.disconnected
        self.injected_heat_w = pack.injected_heat_w
        self.demand_w = np.full(n, pack.demand_w)
        th = cfg.thermal
        self._cap_positive = bool(np.all(self.cap > 0.0))
        self._at_e: np.ndarray | None = None
        self._at: tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]
        self._decay: tuple[float, float] = (np.nan, 1.0)
        self._g, self._c, self._env = th.conductance_w_per_k, th.heat_capacity_j_per_k, th.environment_c

    # -- BatteryModel.soc, _params ----------------------------------------------------------

    @property
    def soc(self) -> np.ndarray:
        return self._params()[3]

    @property
    def operational(self) -> np.ndarray:
        off = self.thermal_cutoff | self.depleted | self.uv_cutoff
        return ~off if not self.disconnected else np.zeros_like(off)

    def _params(self) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
        """``(V_oc, R0, [R_j], soc)``, kept while the energy array is the same object."""
        e = self.energy_j
        if e is not self._at_e:
            cap = self.cap
            if self._cap_positive:
                soc = np.minimum(1.0, np.maximum(0.0, e / cap))
            else:
                safe = np.where(cap > 0.0, cap, 1.0)
                soc = np.where(cap > 0.0, np.minimum(1.0, np.maximum(0.0, e / safe)), 0.0)
            f = self.factor
            r0 = self._r0
            rj = [f * (_interp(soc, r) if isinstance(r, Table) else r) for r in self._rj]
            self._at = (_interp(soc, self._ocv), f * (_interp(soc, r0) if isinstance(r0, Table) else r0),
                        rj, soc)
            self._at_e = e
        return self._at

    # -- BatteryModel._solve and circuit.solve_bus --------------------------------------------

    @staticmethod
    def solve_bus(v_x: np.ndarray, r0: np.ndarray, demand: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Voltage, current and brown-out of :func:`~services.battery.circuit.solve_bus`.
        (``where`` evaluates every branch for every element and keeps the one that applies:
        the others' divisions by zero are expected, and silenced.)"""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return Packs._solve_bus(v_x, r0, demand)

    @staticmethod
    def _solve_bus(v_x: np.ndarray, r0: np.ndarray, demand: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        live = v_x > 0.0
        all_live = bool(live.all())
        has_r = r0 > 0.0
        if bool(has_r.all()):
            p_max = v_x * v_x / (4.0 * r0)
            over = demand > p_max
            if bool(over.any()):
                disc = np.maximum(v_x * v_x - 4.0 * r0 * demand, 0.0)
                current = np.where(over, v_x / (2.0 * r0), 2.0 * demand / (v_x + np.sqrt(disc)))
                voltage = np.where(over, v_x / 2.0, v_x - current * r0)
            else:
                current = 2.0 * demand / (v_x + np.sqrt(v_x * v_x - 4.0 * r0 * demand))
                voltage = v_x - current * r0
        elif not bool(has_r.any()):
            over = np.zeros(v_x.shape, dtype=bool)
            current = demand / np.where(live, v_x, 1.0) if not all_live else demand / v_x
            voltage = v_x
        else:
            safe_r = np.where(has_r, r0, 1.0)
            safe_v = np.where(live, v_x, 1.0)
            p_max = v_x * v_x / (4.0 * safe_r)
            over = has_r & (demand > p_max)
            disc = np.maximum(v_x * v_x - 4.0 * safe_r * demand, 0.0)
            normal = 2.0 * demand / (v_x + np.sqrt(disc))
            current = np.where(has_r, np.where(over, v_x / (2.0 * safe_r), normal), demand / safe_v)
            voltage = np.where(has_r, np.where(over, v_x / 2.0, v_x - current * safe_r), v_x)
        if all_live:
            return voltage, current, over
        current = np.where(live & (demand != 0.0), current, 0.0)
        return np.where(live, voltage, 0.0), current, np.where(live, over, demand > 0.0)

    def points(self, demand: np.ndarray | None = None) -> Points:
        """The operating point of each pack for ``demand`` (the held demand when None)."""
        d = self.demand_w if demand is None else demand
        cfg = self.cfg
        charging = d < 0.0
        if bool(charging.any()):
            full = self.energy_j >= self.cap
            d = np.where(charging, np.where(full, 0.0, np.maximum(d, -cfg.max_charge_w)), d)
        v_oc, r0, _, _ = self._params()
        v_x = v_oc - sum(self.branch_v) if self.branch_v else v_oc
        voltage, current, _ = self.solve_bus(v_x, r0, d)
        limited = current > cfg.max_discharge_a
        if bool(limited.any()):
            current = np.where(limited, cfg.max_discharge_a, current)
            voltage = np.where(limited, v_x - cfg.max_discharge_a * r0, voltage)
        if self.disconnected:
            return Points(np.zeros_like(voltage), np.zeros_like(current))
        blocked = self.thermal_cutoff | ((d > 0.0) & (self.depleted | self.uv_cutoff))
        if bool(blocked.any()):
            voltage, current = np.where(blocked, 0.0, voltage), np.where(blocked, 0.0, current)
        return Points(voltage, current)

    # -- BatteryModel.step ------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        i = self.points().current_a
        v_oc, r0, rj, _ = self._params()
        e0 = self.energy_j
        cap = self.cap
        drain = v_oc * i
        floor = self.cfg.depleted_soc * cap
        dis, chg = i > 0.0, i < 0.0
        hit_floor = dis & (drain * dt_s >= e0 - floor)
        hit_full = chg & (-drain * dt_s >= cap - e0)
        moved = e0 - drain * dt_s  # e0 itself where no current flows
        if bool(hit_floor.any() or hit_full.any()):
            safe_drain = np.where(drain != 0.0, drain, 1.0)
            active = np.where(hit_floor, np.maximum(0.0, (e0 - floor) / safe_drain),
                              np.where(hit_full, np.maximum(0.0, (cap - e0) / -safe_drain), dt_s))
            self.energy_j = np.where(hit_floor, np.minimum(e0, floor),
                                     np.where(hit_full, np.maximum(e0, cap), moved))
            self.depleted = self.depleted | hit_floor
            self._branches_partial(i, rj, active, dt_s, r0)
        else:
            self.energy_j = moved
            self._branches(i, rj, dt_s, r0)

    def _branches(self, i: np.ndarray, rj: list[np.ndarray], dt_s: float, r0: np.ndarray) -> None:
        """The branches and the heat over a whole step of current (no store reached its end)."""
        heat = i * i * r0 * dt_s
        if dt_s > 0.0:
            for j, c in enumerate(self._cj):
                r = rj[j]
                tau = r * c
                v = self.branch_v[j]
                x = dt_s / tau
                a = np.exp(-x)
                one_a = -np.expm1(-x)
                v_inf = r * i
                d = v - v_inf
                h = (v_inf * v_inf * dt_s + 2.0 * v_inf * d * tau * one_a
                     + 0.5 * d * d * tau * one_a * (1.0 + a)) / r
                heat = heat + np.maximum(h, 0.0)
                self.branch_v[j] = v_inf + d * a
        self._heat(heat, dt_s)

    def _branches_partial(self, i: np.ndarray, rj: list[np.ndarray], active: np.ndarray,
                          dt_s: float, r0: np.ndarray) -> None:
        """As :meth:`_branches` where some stores stop part-way: the current flows for
        ``active``, the branches relax for the rest."""
        heat = i * i * r0 * active
        rest = dt_s - active
        on = active > 0.0
        relax_any = bool(np.any(rest > 0.0))
        for j, c in enumerate(self._cj):
            r = rj[j]
            tau = r * c
            v = self.branch_v[j]
            x = active / tau
            a = np.exp(-x)
            one_a = -np.expm1(-x)
            v_inf = r * i
            d = v - v_inf
            h = (v_inf * v_inf * active + 2.0 * v_inf * d * tau * one_a
                 + 0.5 * d * d * tau * one_a * (1.0 + a)) / r
            heat = heat + np.where(on & (h > 0.0), h, 0.0)
            v = np.where(on, v_inf + d * a, v)
            if relax_any:
                relax = (rest > 0.0) & (v != 0.0)
                b = np.exp(-rest / tau)
                heat = heat + np.where(relax, 0.5 * c * v * v * (-np.expm1(-rest / tau)) * (1.0 + b), 0.0)
                v = np.where(relax, v * b, v)
            self.branch_v[j] = v
        self._heat(heat, dt_s)

    def _heat(self, heat: np.ndarray, dt_s: float) -> None:
        q = (heat / dt_s if dt_s > 0.0 else 0.0 * heat) + self.injected_heat_w
        g = self._g
        if g > 0.0:
            if self._decay[0] != dt_s:  # math.exp, as the scalar pack computes it
                self._decay = (dt_s, math.exp(-g * dt_s / self._c))
            t_inf = self._env + q / g
            self.temperature_c = t_inf + (self.temperature_c - t_inf) * self._decay[1]
        else:
            self.temperature_c = self.temperature_c + q * dt_s / self._c
        self._update_latches()

    # -- BatteryModel._update_latches and _recovered ----------------------------------------

    def _update_latches(self) -> None:
        cfg = self.cfg
        soc = self.soc
        low, back = cfg.depleted_soc, cfg.depleted_soc + cfg.depleted_hysteresis_soc
        self.depleted = (soc <= low) | (self.depleted & ~(soc >= back))
        th, t = cfg.thermal, self.temperature_c
        self.thermal_cutoff = (t > th.cutoff_c) | (self.thermal_cutoff & ~(t < th.max_c))
        cutoff_v = self._cutoff_v
        if cutoff_v is None:
            return
        point = self.points()
        newly = ~self.uv_cutoff & (point.current_a > 0.0) & (point.voltage_v < cutoff_v)
        was = self.uv_cutoff
        if bool(newly.any()):
            self.cutoff_demand_w = np.where(newly, self.demand_w, self.cutoff_demand_w)
        if bool(was.any()):
            v_oc, r0, rj, _ = self._params()
            noload = v_oc - sum(self.branch_v) if self.branch_v else v_oc
            demand = np.maximum(self.cutoff_demand_w, self.demand_w)
            steady_v, _, brown = self.solve_bus(v_oc, r0 + sum(rj) if rj else r0, demand)
            recovered = (noload >= cutoff_v) & ((demand <= 0.0) | (~brown & (steady_v >= cutoff_v)))
            self.uv_cutoff = newly | (was & ~recovered)
        else:
            self.uv_cutoff = newly
