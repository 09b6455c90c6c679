"""The same models composed in one process: deterministic, faster than real time.

Each tick runs what the services do over Zenoh, in the same order: the battery
integrates the tick at the demand it was holding (zero-order hold), the loads
draw new samples, the drive (of a rover that has one) moves over the tick and
sets its load's power, solar and the PDM resolve rails (trips, shedding,
protection) and the new net demand goes to the battery. Faults are given to the
models as the services give them, typed (:data:`common.faults.Fault`), with
:meth:`ComposedTwin.set_faults`: the faults in effect on one component at a time. The
umbilical's cable follows the drive as the solar service makes it. No I/O, no clock, no Zenoh.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from common.config import Rover
from common.faults import CATALOGUE, FaultParams
from common.messages import RailStateName
from services.battery.model import BatteryModel, BatteryReading
from services.drive.model import DriveModel
from services.loads.model import LoadsModel, sample_power
from services.power.model import PowerModel, Summary
from services.radio.model import in_range
from services.solar.model import SolarModel

__all__ = ["Budget", "ComposedTwin", "run_budget"]

_BLOCK = 4096  # load samples drawn at once: one numpy call instead of one per tick


class ComposedTwin:
    """One rover's models stepped together on a deterministic clock.

    Where the time of a tick goes, and what keeps it short (the results are the same numbers
    the general path computes, to the bit): the loads are drawn :data:`_BLOCK` ticks at a
    time and summed per rail in the same order :meth:`PowerModel.compute` adds them, so while
    no load has a fault the PDM resolves the rails from those sums directly (one pass, not
    the fixed point of loads and rails; ``loads.sampled_w`` is brought up to date when the
    general path runs); the panels are recomputed only when the sun angle, the dust, a
    disconnection or the umbilical changed.
    """

    def __init__(self, rover: Rover, seed: int | None = 0, fast: bool = True):
        self.rover = rover
        self.sited = [r for r in rover.radios if r.site is not None]  # the radios the drive moves against
        self.fast = fast  # False: every tick takes the general path (the tests compare them)
        self.dt_s = 1.0 / rover.tick_hz
        self.t_s = 0.0
        self.battery = BatteryModel(rover.battery)
        self.loads = LoadsModel(rover, seed)
        self.power = PowerModel(rover)
        self.solar = SolarModel(rover)
        self._samples = np.empty((0, len(self.loads.names)))
        self._rail_w: list[list[float]] = []
        self._row = 0
        self._rail_names = list(self.power.switches)
        self._rail_loads = [[k for k, r in enumerate(self.loads.rails) if r == name]
                            for name in self._rail_names]
        self._solar_seen: tuple | None = None  # what the panels were last computed for
        self._states: list[tuple[RailStateName, str]] = []
        self._fast = False  # the present tick's loads are a row of the block's rail sums
        # -- the drive (one self-contained block): it sets its load's power ---------------------
        # Its load is left out of the block's sums; its power is added to its rail each tick.
        self.drive: DriveModel | None = None
        self._drive_col = -1
        if rover.drive is not None:
            load = next(ld for ld in rover.loads if ld.name == rover.drive.load)
            self.drive = DriveModel(rover.drive, load.max_w)
            self._drive_load, self._drive_rail = load.name, load.rail
            k = self.loads.index[load.name]
            self._drive_col = self._rail_names.index(load.rail)
            self._rail_loads = [[i for i in members if i != k] for members in self._rail_loads]
        self.summary: Summary = self._resolve()

    def _draw_block(self) -> None:
        m = self.loads
        self._samples = sample_power(m.rng, m.nominal_w, m.std_w, m.max_w, ticks=_BLOCK)
        # per rail, the loads added in load order from 0.0, as PowerModel.compute adds them
        sums = np.zeros((_BLOCK, len(self._rail_names)))
        for j, members in enumerate(self._rail_loads):
            for k in members:
                sums[:, j] = sums[:, j] + self._samples[:, k]
        self._rail_w = sums.tolist()
        self._row = 0

    def out_of_range(self) -> list[str]:
        """The radios standing at a site whose footprint the rover is outside now (the
        geometry only: whether the rover's end has power is the radio service's)."""
        d = self.drive
        if d is None:
            return []
        return [r.name for r in self.sited if r.site is not None and not in_range(
            d.x_m - r.site.x_m, d.y_m - r.site.y_m, r.a_m, r.b_m, r.offset_x_m, r.offset_y_m)]

    def set_faults(self, component: str, name: str | None, faults: Iterable[FaultParams]) -> None:
        """Give the model of one component every injected fault in effect on it, as the
        fault book gives them to the services: ``set_faults("load", "nav_camera",
        [Short(0.05)])``; ``[]`` clears them. ``component`` as in a fault key (SPEC §6)."""
        if component not in CATALOGUE:
            raise ValueError(f"no fault component {component!r} (known: {', '.join(CATALOGUE)})")
        faults = list(faults)
        if component == "battery":
            self.battery.set_faults(faults)
        elif component == "umbilical":
            self.solar.set_umbilical_faults(faults)
        elif name is None:
            raise ValueError(f"a {component} fault names its {component}")
        elif component == "load":
            self.loads.set_faults(name, faults)
        elif component == "rail":
            self.power.set_faults(name, faults)
        elif component == "solar":
            self.solar.set_panel_faults(name, faults)
        else:
            raise ValueError(f"the composed twin has no {component} (it has no radio)")
        self.summary = self._resolve()

    def _update_solar(self) -> None:
        sol, seen = self.solar, self._solar_seen
        if seen is not None and (sol.sun_angle_deg == seen[0] and sol.fault_dust == seen[1]
                                 and sol.dark == seen[2] and sol.umbilical_connected == seen[3]
                                 and sol.input_dust == seen[4] and sol.panel_angle_deg == seen[5]):
            return
        self._solar_seen = (sol.sun_angle_deg, dict(sol.fault_dust), set(sol.dark),
                            sol.umbilical_connected, dict(sol.input_dust), dict(sol.panel_angle_deg))
        power = self.power
        for name, p_w, _ in sol.panels():
            power.panel_power_w[name] = p_w
        power.umbilical_w = sol.umbilical_power_w

    def _resolve(self) -> Summary:
        """Solar, PDM and loads to a fixed point (a tripped rail turns its loads off)."""
        power, loads = self.power, self.loads
        self._update_solar()
        b = self.battery
        point = b.operating_point()
        power.set_battery(b.soc, b.operational, point.voltage_v)
        if self._fast and self.fast and not loads.held_w:
            rail_w = self._rail_w[self._row - 1]
            if self.drive is not None:
                rail_w = list(rail_w)
                rail_w[self._drive_col] += loads.driven_w[self._drive_load]
            states, summary = power.resolve(rail_w)
            if states != self._states:  # the loads follow their rails, as over Zenoh
                self._states = states
                rail_on = loads.rail_on
                for name, (state, _) in zip(self._rail_names, states, strict=True):
                    rail_on[name] = state == "on"
        else:
            if self._fast:  # the loads model draws this tick's row of the block
                loads.sampled_w = self._samples[self._row - 1]
            summary = self._fixed_point()
        b.set_demand(summary.net_battery_power_w)
        return summary

    def _fixed_point(self) -> Summary:
        power, loads = self.power, self.loads
        self._states = []  # the loads' rails are set here: the fast path syncs them afresh
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
        return summary

    def step(self) -> None:
        """One tick of ``1 / tick_hz`` simulated seconds."""
        self.battery.step(self.dt_s)
        self.t_s += self.dt_s
        if self._row >= len(self._rail_w):
            self._draw_block()
        self._row += 1
        self._fast = True
        if self.drive is not None:
            self._step_drive(self.drive)
        self.summary = self._resolve()

    def _step_drive(self, drive: DriveModel) -> None:
        """As the drive, loads and solar services do: the drive moves over the tick if its
        load supplies it, and sets its load's power for the next tick; a rover that drives
        past its umbilical's cable pulls it out."""
        loads, name = self.loads, self._drive_load
        # loads.supplied(name), without the call: this runs every tick
        drive.set_powered(loads.rail_on.get(self._drive_rail, False) and name not in loads.unsupplied)
        drive.step(self.dt_s)
        loads.driven_w[name] = drive.power_w
        if self.solar.umbilical_plugged:
            self.solar.move_rover(drive.x_m, drive.y_m, drive.z_m)

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
    cutoff_at_s: float | None = None  # the first under-voltage cut-off
    short_s: float = 0.0  # time the pack could not give the demand (its discharge limit, a brownout)
    unmet_j: float = 0.0  # the energy of the demand it could not give


def run_budget(rover: Rover, hours: float, seed: int | None = 0,
               progress=None, sample=None, sample_every_s: float = 60.0) -> Budget:
    """Run ``hours`` of simulated time and summarise the power budget. ``sample(twin)`` is
    called every ``sample_every_s`` of simulated time and at the end (a series: ``lunaris sim
    --csv``)."""
    twin = ComposedTwin(rover, seed)
    ticks = int(round(hours * 3600.0 * rover.tick_hz))
    e0 = twin.battery.energy_j
    min_soc = twin.battery.soc
    load_sum = gen_sum = 0.0
    depleted_at: float | None = None
    cutoff_at: float | None = None
    shed_at: dict[str, float] = {}
    peak_t = twin.battery.temperature_c
    report_every = max(1, ticks // 20)
    b, step = twin.battery, twin.step
    pending = [(name, sw) for name, sw in twin.power.switches.items()  # rails that can shed
               if sw.cfg.shed_below_soc is not None]
    shed_soc = max((sw.cfg.shed_below_soc or 0.0 for _, sw in pending), default=0.0)
    next_report = report_every if progress is not None else ticks + 1
    dt = 1.0 / rover.tick_hz
    short_s = unmet_j = 0.0
    sample_every = max(1, int(round(sample_every_s * rover.tick_hz)))
    next_sample = sample_every if sample is not None else ticks + 1
    for i in range(1, ticks + 1):
        demand = b.demand_w
        point = b.operating_point()  # what the step below gives the bus (solved once: cached)
        step()
        if point.current_limited or point.brownout:
            short_s += dt
            unmet_j += max(0.0, demand - point.power_w) * dt
        soc = b.soc
        if soc < min_soc:
            min_soc = soc
        if b.temperature_c > peak_t:
            peak_t = b.temperature_c
        summary = twin.summary
        load_sum += summary[0]  # load_power_w
        gen_sum += summary[2]  # generation_w
        if depleted_at is None and b.depleted:
            depleted_at = twin.t_s
        if cutoff_at is None and b.uv_cutoff:
            cutoff_at = twin.t_s
        if pending and soc < shed_soc:  # a rail sheds below its threshold only
            for name, sw in [p for p in pending if p[1].shed]:
                shed_at[name] = twin.t_s
                pending.remove((name, sw))
        if i == next_report:
            next_report += report_every
            progress(i, ticks, twin)
        if i == next_sample:
            next_sample += sample_every
            sample(twin)
    if sample is not None and ticks % sample_every:
        sample(twin)  # the run's end
    n = max(ticks, 1)
    return Budget(twin.t_s, ticks, twin.battery.soc, min_soc, e0 - twin.battery.energy_j,
                  load_sum / n, gen_sum / n, depleted_at, shed_at, peak_t, cutoff_at, short_s, unmet_j)
