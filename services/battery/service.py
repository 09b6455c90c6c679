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
from typing import Any

from common import keys
from common.config import Rover
from common.faults import Fault, battery_fault_code
from common.messages import BatteryState, Clock, PowerSummary, decode
from common.runtime import Runtime, Sample
from services.battery.model import BatteryModel
from services.battery.query import PredictionQueries

__all__ = ["serve"]

PERSIST_S = 0.2  # wall time between saves: what a killed battery service can lose
HOLD_S = 0.04  # the longest a tick's state waits for the PDM's summary [s of wall time]
PDM_HEARD_S = 1.0  # a summary within this long: the PDM is running [s of wall time]


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    config = {r.id: r.battery for r in rovers}
    packs = {r.id: BatteryModel(r.battery) for r in rovers}
    stepped_t: dict[str, float] = dict.fromkeys(packs, 0.0)  # sim time each pack has reached
    generation: dict[str, float] = {}  # the last generation each rover's PDM reported

    def publish(rover: str, t_s: float | None = None) -> None:
        pack = packs[rover]
        r = pack.reading()
        rt.faults.sync_derived(rover, "battery", pack.derived_faults())
        rt.publish(keys.battery_state(rover), BatteryState(
            t_s=rt.t_s[rover] if t_s is None else t_s, fault_code=battery_fault_code(r.faults),
            **r._asdict()))

    # One sample per tick: while the PDM is heard from, a tick's state waits for the PDM's
    # summary of that tick (the demand its loads just set), up to HOLD_S; a summary that
    # changes the demand between ticks (a fault) is published at once.
    held: dict[str, float] = {}  # rover -> monotonic time its tick's state goes out anyway
    heard: dict[str, float] = {}  # rover -> monotonic time of its last summary

    def on_tick(rover: str, tick: Clock) -> None:
        if held.pop(rover, None) is not None:  # the last tick's summary never came: its state
            publish(rover, stepped_t[rover])   # goes out now, with its own time
        dt = tick.t_s - stepped_t[rover]
        if dt > 0.0:
            packs[rover].step(dt)
            stepped_t[rover] = tick.t_s
        now = time.monotonic()
        if now - heard.get(rover, -math.inf) < PDM_HEARD_S:
            held[rover] = now + HOLD_S
        else:
            publish(rover)

    def release_held() -> None:
        now = time.monotonic()
        for rover in [r for r, due in held.items() if now >= due]:
            del held[rover]
            publish(rover)

    summary_t: dict[str, float] = {}  # rover -> sim time of its last summary

    def on_summary(s: Sample) -> None:
        summary = decode(s.payload, PowerSummary)
        pack = packs[s.rover]
        generation[s.rover] = summary.generation_w
        heard[s.rover] = time.monotonic()
        changed = summary.net_battery_power_w != pack.demand_w
        if changed:
            pack.set_demand(summary.net_battery_power_w)
        # The tick's state waits for this (held); a later summary of the same tick is news
        # between ticks (a fault, a command): the bus voltage and current move at once. The
        # first summary of a tick arriving after its state went out anyway (a PDM lagging
        # under load) sets the demand for the next tick: never two states for one tick.
        again = summary_t.get(s.rover) == summary.t_s
        summary_t[s.rover] = summary.t_s
        if s.rover in held or (changed and again):
            held.pop(s.rover, None)
            publish(s.rover)

    def apply_faults(rover: str, _: str | None, faults: tuple[Fault, ...]) -> None:
        packs[rover].set_faults(faults)
        publish(rover)

    def get_state(rover: str) -> dict[str, Any]:
        return {**packs[rover].state(), "t_s": stepped_t[rover]}

    def set_state(rover: str, state: dict[str, Any]) -> None:
        packs[rover].set_state(state)
        stepped_t[rover] = float(state.get("t_s", 0.0))

    def reset(rover: str) -> None:
        packs[rover] = BatteryModel(config[rover])
        stepped_t[rover] = 0.0

    def snapshot(rover: str) -> tuple[BatteryModel, float, float | None]:
        return packs[rover].clone(), stepped_t[rover], generation.get(rover)

    queries = PredictionQueries(rt.zenoh_session, {r.id: r for r in rovers}, snapshot)
    rt.queryable(keys.prediction("*"), queries.on_query)
    rt.on_exit(queries.close)
    rt.on_tick(on_tick)
    rt.every(HOLD_S / 4, release_held)
    rt.subscribe(keys.power_summary("*"), on_summary, telemetry=True)
    rt.faults.own("battery", None, apply_faults)
    rt.own_state(get_state, set_state, reset, after=publish, persist_every_s=PERSIST_S)
    rt.faults.restore()
    for rover in packs:
        if stepped_t[rover] == 0.0:  # a fresh start; after a restart the first tick publishes,
            publish(rover)           # with its own time, never the older saved one
