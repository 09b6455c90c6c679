"""Loads: each draws a noisy power around its nominal value, or what a fault dictates.

Every tick a load draws ``clip(N(nominal_w, std_w), 0, max_w)`` [W]. It draws
nothing while its rail is off. Faults (SPEC §6) override the sample: ``short``
draws ``V_rail^2 / R``, ``open`` nothing, ``stuck`` a constant power. The model is given the
faults in effect on a load (:meth:`LoadsModel.set_faults`) and keeps what they do, never a
record of them; a load's own alarm is ``over_current`` (drawing above its ``max_w``).

The drive load of a rover with a ``drive`` section draws what the drive sets
(:meth:`LoadsModel.set_driven`, from ``drive/state``; ``idle_w`` until it says otherwise)
instead of samples; its faults still win.

A service serving a fleet holds its rovers' models in a :class:`LoadsFleet`, which draws the
samples of every load of every rover together, ``BLOCK_TICKS`` ticks at a time.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from common.config import Rover
from common.faults import FaultParams, held_power_w, supplies_device

__all__ = ["BLOCK_TICKS", "LoadsFleet", "LoadsModel", "sample_power"]

BLOCK_TICKS = 16  # the ticks of a fleet's loads drawn at once


def sample_power(rng: np.random.Generator, nominal_w: np.ndarray, std_w: np.ndarray,
                 max_w: np.ndarray, ticks: int | None = None) -> np.ndarray:
    """One draw per load [W]: normal around ``nominal_w`` with ``std_w``, clipped to [0, max_w];
    with ``ticks``, that many rows of them (one per tick)."""
    size = None if ticks is None else (ticks, len(nominal_w))
    return np.clip(rng.normal(nominal_w, std_w, size=size), 0.0, max_w)


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
        self.max_w_of = {ld.name: ld.max_w for ld in rover.loads}
        self.sampled_w = self.nominal_w.copy()
        self.rail_on = {r.name: r.initially_on for r in rover.rails}
        # The drive load: what the drive sets, instead of a sample.
        self.idle_w = {rover.drive.load: rover.drive.idle_w} if rover.drive is not None else {}
        self.driven_w: dict[str, float] = dict(self.idle_w)
        # what the injected faults do: the power a fault holds a load at while its rail is on
        # [W], and the loads whose device gets no supply (see common.faults.supplies_device)
        self.held_w: dict[str, float] = {}
        self.unsupplied: set[str] = set()
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
        return self.held_w.get(name)

    def set_faults(self, name: str, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on one load, all of them (none: it draws its
        samples again). Several on one load: a short dominates, then an open circuit, then
        stuck. A kind that is not a load's raises ValueError, and nothing changes."""
        if name not in self.index:
            raise ValueError(f"no load {name!r}")
        faults = list(faults)
        held = held_power_w(faults, self.rail_voltage_v[self.rails[self.index[name]]])
        if held is None:
            self.held_w.pop(name, None)
        else:
            self.held_w[name] = held
        if supplies_device(True, faults):
            self.unsupplied.discard(name)
        else:
            self.unsupplied.add(name)

    def supplied(self, name: str) -> bool:
        """Whether the device behind a load has power (its rail on, no fault cutting it off)."""
        return self.rail_on.get(self.rails[self.index[name]], False) and name not in self.unsupplied

    def alarms(self, name: str, power_w: float) -> list[str]:
        """A load's own alarms at the power it draws: ``over_current`` above its ``max_w``."""
        return ["over_current"] if power_w > self.max_w_of[name] else []

    def powers(self) -> list[tuple[str, float, str, bool]]:
        """``(load, power_w, rail, on)`` for every load: :meth:`power` of each, in one pass."""
        out = []
        rail_on, held_w, driven_w = self.rail_on, self.held_w, self.driven_w
        for name, rail, sampled_w in zip(self.names, self.rails, self.sampled_w.tolist(),
                                         strict=True):
            if not rail_on.get(rail, False):
                out.append((name, 0.0, rail, False))
                continue
            held = held_w.get(name)
            if held is None:
                held = driven_w.get(name, sampled_w)
            out.append((name, held, rail, True))
        return out


class LoadsFleet:
    """The loads of many rovers in one process: a :class:`LoadsModel` per rover (``models``),
    their samples drawn together.

    A draw of one rover's dozen loads costs what numpy's calls cost, not what the numbers
    do; so the fleet draws every load of every rover for ``block_ticks`` ticks at once, and
    a rover's tick (:meth:`sample`) only moves it to its next row of that block (its model's
    ``sampled_w`` is a view of it). A rover that runs out of rows has a new block drawn for
    all; the rows the others had left are dropped (independent draws: none is the worse for
    it). With a seed, the samples repeat for the same order of ticks across the fleet.
    """

    def __init__(self, rovers: list[Rover], seed: int | None = None,
                 block_ticks: int = BLOCK_TICKS):
        self.models = {r.id: LoadsModel(r) for r in rovers}
        self._slices: dict[str, slice] = {}
        start = 0
        for rover, m in self.models.items():
            self._slices[rover] = slice(start, start + len(m.names))
            start += len(m.names)
        ms = list(self.models.values())
        self.nominal_w = np.concatenate([m.nominal_w for m in ms] + [np.zeros(0)])
        self.std_w = np.concatenate([m.std_w for m in ms] + [np.zeros(0)])
        self.max_w = np.concatenate([m.max_w for m in ms] + [np.zeros(0)])
        self.rng = np.random.default_rng(seed)
        self.block_ticks = block_ticks
        self.draws = 0  # how many blocks have been drawn
        self._block = np.empty((0, start))
        self._row = dict.fromkeys(self.models, 0)  # each rover's next row of the block

    def sample(self, rover: str) -> None:
        """One tick of one rover: a new noisy sample for each of its loads."""
        row = self._row[rover]
        if row >= len(self._block):
            self._block = sample_power(self.rng, self.nominal_w, self.std_w, self.max_w,
                                       ticks=self.block_ticks)
            self.draws += 1
            self._row = dict.fromkeys(self._row, 0)
            row = 0
        self._row[rover] = row + 1
        self.models[rover].sampled_w = self._block[row, self._slices[rover]]
