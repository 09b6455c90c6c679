"""The same models composed in one process: deterministic, faster than real time.

Each tick runs what the services do over Zenoh, in the same order: the battery
integrates the tick at the demand it was holding (zero-order hold), the loads
draw new samples, the drive (of a rover that has one) moves over the tick and
sets its load's power, solar and the PDM resolve rails (trips, shedding,
protection) and the new net demand goes to the battery. Faults are applied
with the same model attributes the services set. No I/O, no clock, no Zenoh.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from common.config import Rover
from services.battery.model import BatteryModel, BatteryReading
from services.drive.model import DriveModel, motors_powered
from services.loads.model import LoadsModel
from services.power.model import PowerModel, Summary
from services.solar.model import SolarModel

__all__ = ["Budget", "ComposedTwin", "run_budget"]

_BLOCK = 4096  # load samples drawn at once: one numpy call instead of one per tick


class ComposedTwin:
    def __init__(self, rover: Rover, seed: int | None = 0):
        self.rover = rover
        self.dt_s = 1.0 / rover.tick_hz
        self.t_s = 0.0
        self.battery = BatteryModel(rover.battery)
        self.loads = LoadsModel(rover, seed)
        self.power = PowerModel(rover)
        self.solar = SolarModel(rover)
        self._samples = np.empty((0, len(self.loads.names)))
        self._row = 0
        self._load_rail = list(zip(self.loads.names, self.loads.rails, strict=True))
        # -- the drive (one self-contained block): it sets its load's power ---------------------
        self.drive: DriveModel | None = None
        if rover.drive is not None:
            load = next(ld for ld in rover.loads if ld.name == rover.drive.load)
            self.drive = DriveModel(rover.drive, load.max_w)
            self._drive_load, self._drive_rail = load.name, load.rail
        self.summary: Summary = self._resolve()

    def _next_samples(self) -> np.ndarray:
        if self._row >= len(self._samples):
            m = self.loads
            self._samples = np.clip(
                m.rng.normal(m.nominal_w, m.std_w, size=(_BLOCK, len(m.names))), 0.0, m.max_w)
            self._row = 0
        row = self._samples[self._row]
        self._row += 1
        return row

    def _resolve(self) -> Summary:
        """Solar, PDM and loads to a fixed point (a tripped rail turns its loads off)."""
        power, loads = self.power, self.loads
        for name, p_w, _, _ in self.solar.panels():
            power.panel_power_w[name] = p_w
        power.umbilical_w = self.solar.umbilical_power_w
        b = self.battery
        point = b.operating_point()
        power.set_battery(b.soc, b.operational, point.voltage_v)
        for _ in range(len(power.switches) + 1):
            for name, p_w, _, _ in loads.powers():
                power.load_power_w[name] = p_w
            readings, summary = power.compute()
            changed = False
            for r in readings:
                if r.name in loads.rail_on:
                    changed |= loads.set_rail(r.name, r.state == "on")
            if not changed:
                break
        b.set_demand(summary.net_battery_power_w)
        return summary

    def step(self) -> None:
        """One tick of ``1 / tick_hz`` simulated seconds."""
        self.battery.step(self.dt_s)
        self.t_s += self.dt_s
        self.loads.sampled_w = self._next_samples()
        if self.drive is not None:
            self._step_drive(self.drive)
        self.summary = self._resolve()

    def _step_drive(self, drive: DriveModel) -> None:
        """As the drive and loads services do: the drive moves over the tick if its load
        supplies it, and sets its load's power for the next tick."""
        loads, name = self.loads, self._drive_load
        drive.set_powered(motors_powered(loads.rail_on.get(self._drive_rail, False),
                                         loads.faults.get(name, ())))
        drive.step(self.dt_s)
        loads.driven_w[name] = drive.power_w

    def reading(self) -> BatteryReading:
        return self.battery.reading()


class Budget(NamedTuple):
    """What a vehicle engineer asks of an accelerated run."""

    simulated_s: float
    ticks: int
    final_soc: float
    min_soc: float
    energy_used_j: float
    mean_load_w: float
    mean_generation_w: float
    depleted_at_s: float | None
    shed_at_s: dict[str, float]
    peak_temperature_c: float


def run_budget(rover: Rover, hours: float, seed: int | None = 0,
               progress=None) -> Budget:
    """Run ``hours`` of simulated time and summarise the power budget."""
    twin = ComposedTwin(rover, seed)
    ticks = int(round(hours * 3600.0 * rover.tick_hz))
    e0 = twin.battery.energy_j
    min_soc = twin.battery.soc
    load_sum = gen_sum = 0.0
    depleted_at: float | None = None
    shed_at: dict[str, float] = {}
    peak_t = twin.battery.temperature_c
    report_every = max(1, ticks // 20)
    for i in range(ticks):
        twin.step()
        b = twin.battery
        soc = b.soc
        min_soc = min(min_soc, soc)
        peak_t = max(peak_t, b.temperature_c)
        load_sum += twin.summary.load_power_w
        gen_sum += twin.summary.generation_w
        if depleted_at is None and b.depleted:
            depleted_at = twin.t_s
        for name, sw in twin.power.switches.items():
            if sw.shed and name not in shed_at:
                shed_at[name] = twin.t_s
        if progress is not None and (i + 1) % report_every == 0:
            progress(i + 1, ticks, twin)
    n = max(ticks, 1)
    return Budget(twin.t_s, ticks, twin.battery.soc, min_soc, e0 - twin.battery.energy_j,
                  load_sum / n, gen_sum / n, depleted_at, shed_at, peak_t)
