"""Loads: each draws a noisy power around its nominal value, or what a fault dictates.

Every tick a load draws ``clip(N(nominal_w, std_w), 0, max_w)`` [W]. It draws
nothing while its rail is off. Faults (SPEC §6) override the sample: ``short``
draws ``V_rail^2 / R``, ``open`` nothing, ``stuck`` a constant power.

The drive load of a rover with a ``drive`` section draws what the drive sets
(:meth:`LoadsModel.set_driven`, from ``drive/state``; ``idle_w`` until it says otherwise)
instead of samples; its faults still win.
"""

from __future__ import annotations

import numpy as np

from common.config import Rover
from common.faults import FaultKey, Params, ShortParams, StuckParams

__all__ = ["LoadsModel", "sample_power"]


def sample_power(rng: np.random.Generator, nominal_w: np.ndarray, std_w: np.ndarray,
                 max_w: np.ndarray) -> np.ndarray:
    """One draw per load [W]: normal around ``nominal_w`` with ``std_w``, clipped to [0, max_w]."""
    return np.clip(rng.normal(nominal_w, std_w), 0.0, max_w)


class LoadsModel:
    """The loads of one rover, vectorised."""

    def __init__(self, rover: Rover, seed: int | None = None):
        self.names = [ld.name for ld in rover.loads]
        self.index = {n: i for i, n in enumerate(self.names)}
        self.rails = [ld.rail for ld in rover.loads]
        self.rail_voltage_v = {r.name: r.voltage_v for r in rover.rails}
        self.nominal_w = np.array([ld.nominal_w for ld in rover.loads], dtype=float)
        self.std_w = np.array([ld.std_w for ld in rover.loads], dtype=float)
        self.max_w = np.array([ld.max_w for ld in rover.loads], dtype=float)
        self.sampled_w = self.nominal_w.copy()
        self.rail_on = {r.name: r.initially_on for r in rover.rails}
        # The drive load: what the drive sets, instead of a sample.
        self.idle_w = {rover.drive.load: rover.drive.idle_w} if rover.drive is not None else {}
        self.driven_w: dict[str, float] = dict(self.idle_w)
        self.faults: dict[str, dict[str, Params]] = {}  # load -> {kind: params}
        self.rng = np.random.default_rng(seed)

    def sample(self) -> None:
        """Draw a new noisy sample for every load (one tick)."""
        if len(self.names):
            self.sampled_w = sample_power(self.rng, self.nominal_w, self.std_w, self.max_w)

    def set_driven(self, name: str, power_w: float) -> bool:
        """The power the drive sets for its load [W]; True when it changed. Ignored for a load
        the drive does not own."""
        if name not in self.driven_w or self.driven_w[name] == power_w:
            return False
        self.driven_w[name] = power_w
        return True

    def reset_driven(self) -> None:
        """Back to the drive's idle power (a session reset)."""
        self.driven_w = dict(self.idle_w)

    def set_rail(self, rail: str, on: bool) -> bool:
        """Record a rail's state; True when it changed."""
        changed = self.rail_on.get(rail) != on
        self.rail_on[rail] = on
        return changed

    def power(self, name: str) -> tuple[float, bool]:
        """Power drawn by one load [W] and whether its rail is on."""
        i = self.index[name]
        rail = self.rails[i]
        on = self.rail_on.get(rail, False)
        if not on:
            return 0.0, False
        held = self.fault_power(name)
        if held is not None:
            return held, True
        driven = self.driven_w.get(name)  # the drive sets its load's power while it exists
        return (float(self.sampled_w[i]) if driven is None else driven), True

    def fault_power(self, name: str) -> float | None:
        """The power a fault holds a load at while its rail is on [W]; None without a fault."""
        faults = self.faults.get(name)
        if not faults:
            return None
        # Several faults on one load: a short dominates, then an open circuit, then stuck.
        short = faults.get("short")
        if isinstance(short, ShortParams):
            return self.rail_voltage_v[self.rails[self.index[name]]] ** 2 / short.resistance_ohm
        if "open" in faults:
            return 0.0
        stuck = faults["stuck"]
        assert isinstance(stuck, StuckParams)
        return stuck.power_w

    def apply_fault(self, fault: FaultKey, params: Params | None) -> None:
        """Inject (``params``) or clear (None) one fault of one load."""
        if fault.name not in self.index:
            raise ValueError(f"no load {fault.name!r}")
        faults = self.faults.setdefault(fault.name, {})
        if params is None:
            faults.pop(fault.kind, None)
        else:
            faults[fault.kind] = params

    def fault_names(self, name: str) -> list[str]:
        return sorted(self.faults.get(name, {}))

    def powers(self) -> list[tuple[str, float, str, bool]]:
        """``(load, power_w, rail, on)`` for every load."""
        out = []
        for name, rail in zip(self.names, self.rails, strict=True):
            power_w, on = self.power(name)
            out.append((name, power_w, rail, on))
        return out
