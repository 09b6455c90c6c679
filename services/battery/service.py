"""Battery service: steps each pack on the clock, re-solves the bus when demand changes."""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.faults import FaultKey, Params, battery_fault_code
from common.messages import BatteryState, Clock, PowerSummary, decode
from common.runtime import Runtime, Sample
from services.battery.model import BatteryModel

__all__ = ["serve"]

PERSIST_S = 0.2  # wall time between saves: what a killed battery service can lose


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    packs = {r.id: BatteryModel(r.battery) for r in rovers}
    saved = rt.store.load("state") or {}
    for rover, pack in packs.items():
        s = saved.get(rover)
        if s:  # resume after a restart: the store and the heat are not reset
            pack.energy_j = s["energy_j"]
            pack.temperature_c = s["temperature_c"]
            pack.depleted = s.get("depleted", pack.depleted)
            pack.thermal_cutoff = s.get("thermal_cutoff", False)
            rt.t_s[rover] = s.get("t_s", 0.0)

    def publish(rover: str) -> None:
        pack = packs[rover]
        r = pack.reading()
        rt.faults.sync_derived(rover, "battery", pack.derived_faults())
        fields = r._asdict()
        rt.publish(keys.battery_state(rover), BatteryState(
            t_s=rt.t_s[rover], fault_code=battery_fault_code(r.faults), **fields))

    def on_tick(rover: str, tick: Clock) -> None:
        packs[rover].step(tick.dt_s)
        publish(rover)

    def on_summary(s: Sample) -> None:
        summary = decode(s.payload, PowerSummary)
        pack = packs[s.rover]
        if summary.net_battery_power_w != pack.demand_w:
            pack.set_demand(summary.net_battery_power_w)
            publish(s.rover)  # the bus voltage and current move at once, not at the next tick

    def apply_fault(rover: str, fk: FaultKey, params: Params | None) -> None:
        packs[rover].apply_fault(fk, params)
        publish(rover)

    def persist() -> None:
        rt.store.save("state", {
            rover: {"energy_j": p.energy_j, "temperature_c": p.temperature_c,
                    "depleted": p.depleted, "thermal_cutoff": p.thermal_cutoff,
                    "t_s": rt.t_s[rover]}
            for rover, p in packs.items()
        })

    rt.on_tick(on_tick)
    rt.subscribe(keys.power_summary("*"), on_summary)
    rt.faults.own("battery", None, apply_fault)
    rt.faults.restore()
    rt.every(PERSIST_S, persist)
    rt.on_exit(persist)
    for rover in packs:
        publish(rover)
