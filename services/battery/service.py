"""Battery service: steps each pack on the clock, re-solves the bus when demand changes,
and answers ``prediction`` queries (:mod:`services.battery.query` says why here).

A pack integrates the simulated time since it last stepped (not only the tick's ``dt_s``),
so time that passed while no tick could reach it (a restart of this service, a router
outage) is integrated at the demand it was holding: the stored energy always equals the
integral of the demand, and no stretch of time is integrated twice.

One ``battery/state`` per tick: while the PDM runs, a tick's state is published when the
PDM's summary of that tick arrives (the demand its loads set), or after ``HOLD_S``; before,
each tick gave two samples, the first with the previous tick's demand.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import zenoh

from common import keys
from common.config import Battery as BatteryConfig
from common.config import Rover
from common.faults import Fault, battery_fault_code
from common.messages import BatteryState, Clock, PowerSummary, Prediction
from common.node import Answers, Every, Node, Owns, PerRover, Publishes, Reads
from common.runtime import Runtime, Sample
from services.battery.circuit import circuit_tables
from services.battery.model import BatteryModel
from services.battery.query import PredictionQueries

__all__ = ["NODE", "BatteryNode", "Limits", "Pack", "limits"]

PERSIST_S = 0.2  # wall time between saves: what a killed battery service can lose
HOLD_S = 0.04  # the longest a tick's state waits for the PDM's summary [s of wall time]
PDM_HEARD_S = 1.0  # a summary within this long: the PDM is running [s of wall time]


class Limits(NamedTuple):
    """Where a pack stops: ``depleted_soc``, the charge at which it is empty (0..1), and
    ``cutoff_v``, the BMS cut-off ``cells_series * cutoff_cell_v`` [V] (None without one)."""

    depleted_soc: float
    cutoff_v: float | None


def limits(cfg: BatteryConfig) -> Limits:
    """The :class:`Limits` of a pack design, as ``battery/state`` publishes them."""
    return Limits(cfg.depleted_soc, circuit_tables(cfg).cutoff_v)


@dataclass
class Pack(PerRover):
    """One rover's pack and what the service remembers beside it."""

    cfg: BatteryConfig
    model: BatteryModel
    limits: Limits
    stepped_t: float = 0.0  # the sim time the pack has reached [s]
    generation_w: float | None = None  # the last generation the PDM reported (None: not yet)
    held_until: float | None = None  # monotonic time this tick's state goes out anyway
    heard_at: float = -math.inf  # monotonic time of the PDM's last summary
    summary_t: float | None = None  # sim time of the PDM's last summary


class BatteryNode(Node[Pack]):
    """The packs of the rovers served: stepped with the clock, their demand from the PDM."""

    name = "battery"
    reads = (Reads("power/summary", PowerSummary, "on_summary", deletes="reject"),)
    publishes = (Publishes("battery/state", BatteryState),)
    owns = (Owns("battery", "apply_faults"),)
    answers = (Answers("prediction", Prediction, "on_prediction"),)
    timers = (Every(HOLD_S / 4, "release_held"),)
    persist_every_s = PERSIST_S

    def rover_state(self, rover: Rover) -> Pack:
        return Pack(rover.id, rover.battery, BatteryModel(rover.battery), limits(rover.battery))

    def attach(self, rt: Runtime) -> None:
        self.queries = PredictionQueries(rt.zenoh_session, self.configs, self.snapshot)
        rt.on_exit(self.queries.close)
        super().attach(rt)

    def publish_state(self, pack: Pack, t_s: float | None = None) -> None:
        r = pack.model.reading()
        self.rt.faults.sync_derived(pack.id, "battery", pack.model.derived_faults())
        self.publish(keys.battery_state(pack.id), BatteryState(
            t_s=self.rt.t_s[pack.id] if t_s is None else t_s,
            fault_code=battery_fault_code(r.faults), depleted_soc=pack.limits.depleted_soc,
            cutoff_v=pack.limits.cutoff_v, **r._asdict()))

    # One sample per tick: while the PDM is heard from, a tick's state waits for the PDM's
    # summary of that tick (the demand its loads just set), up to HOLD_S; a summary that
    # changes the demand between ticks (a fault) is published at once.

    def on_tick(self, pack: Pack, tick: Clock) -> None:
        if pack.held_until is not None:  # the last tick's summary never came: its state goes
            pack.held_until = None        # out now, with its own time
            self.publish_state(pack, pack.stepped_t)
        dt = tick.t_s - pack.stepped_t
        if dt > 0.0:
            pack.model.step(dt)
            pack.stepped_t = tick.t_s
        now = time.monotonic()
        if now - pack.heard_at < PDM_HEARD_S:
            pack.held_until = now + HOLD_S
        else:
            self.publish_state(pack)

    def release_held(self) -> None:
        now = time.monotonic()
        for pack in self.rovers.values():
            if pack.held_until is not None and now >= pack.held_until:
                pack.held_until = None
                self.publish_state(pack)

    def on_summary(self, pack: Pack, summary: PowerSummary, s: Sample) -> None:
        pack.generation_w = summary.generation_w
        pack.heard_at = time.monotonic()
        changed = summary.net_battery_power_w != pack.model.demand_w
        if changed:
            pack.model.set_demand(summary.net_battery_power_w)
        # The tick's state waits for this (held); a later summary of the same tick is news
        # between ticks (a fault, a command): the bus voltage and current move at once. The
        # first summary of a tick arriving after its state went out anyway (a PDM lagging
        # under load) sets the demand for the next tick: never two states for one tick.
        again = pack.summary_t == summary.t_s
        pack.summary_t = summary.t_s
        if pack.held_until is not None or (changed and again):
            pack.held_until = None
            self.publish_state(pack)

    def apply_faults(self, pack: Pack, _: str | None, faults: tuple[Fault, ...]) -> None:
        pack.model.set_faults(faults)
        self.publish_state(pack)

    # -- state ------------------------------------------------------------------------------

    def get_state(self, pack: Pack) -> dict[str, Any]:
        return {**pack.model.state(), "t_s": pack.stepped_t}

    def set_state(self, pack: Pack, state: dict[str, Any]) -> None:
        pack.model.set_state(state)
        pack.stepped_t = float(state.get("t_s", 0.0))

    def check_state(self, pack: Pack, state: dict[str, Any]) -> None:
        capacity = pack.cfg.capacity_j
        if not 0.0 <= state.get("energy_j", 0.0) <= capacity:
            raise ValueError(f"energy_j {state['energy_j']} J is outside 0 .. {capacity} J")
        if not state.get("temperature_c", 0.0) > -273.15:
            raise ValueError(f"temperature_c {state['temperature_c']} C is below absolute zero")
        if not state.get("t_s", 0.0) >= 0.0:
            raise ValueError(f"t_s {state['t_s']} s is negative")

    def reset(self, pack: Pack) -> None:
        pack.model = BatteryModel(pack.cfg)
        pack.stepped_t = 0.0

    def republish(self, pack: Pack) -> None:
        self.publish_state(pack)

    def start(self) -> None:
        for rover in self.rt.keeper.damaged:  # reset to the rover file from now: no past to
            self.rovers[rover].stepped_t = self.rt.t_s[rover]  # integrate
        for pack in self.rovers.values():
            if pack.stepped_t == 0.0:  # a fresh start; after a restart the first tick
                self.publish_state(pack)  # publishes, with its own time, never the saved one

    # -- prediction -------------------------------------------------------------------------

    def snapshot(self, rover: str) -> tuple[BatteryModel, float, float | None]:
        """A copy of a rover's pack, the sim time it has reached and the last generation."""
        pack = self.rovers[rover]
        return pack.model.clone(), pack.stepped_t, pack.generation_w

    def on_prediction(self, q: zenoh.Query) -> None:
        self.queries.on_query(q)


NODE = BatteryNode
