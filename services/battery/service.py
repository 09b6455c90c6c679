"""Battery service: steps each pack on the clock, re-solves the bus when demand changes."""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.faults import FaultKey, battery_fault_code
from common.messages import BatteryState, Clock, PowerSummary, decode
from common.runtime import Runtime, Sample
from services.battery.model import BatteryModel

__all__ = ["serve"]

PERSIST_S = 0.2  # wall time between saves: what a killed battery service can lose


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    packs = {r.id: BatteryModel(r.battery) for r in rovers}
    saved = rt.load_state("state") or {}
    for rover, pack in packs.items():
        s = saved.get(rover)
        if s:  # resume after a restart: the store and the heat are not reset
            pack.energy_j = s["energy_j"]
            pack.temperature_c = s["temperature_c"]
            pack.depleted = s.get("depleted", pack.depleted)
            pack.thermal_cutoff = s.get("thermal_cutoff", False)
            rt.now[rover] = s.get("t_s", 0.0)

    def publish(rover: str) -> None:
        pack = packs[rover]
        r = pack.reading()
        rt.sync_derived(rover, "battery", pack.derived_faults())
        rt.publish(keys.battery_state(rover), BatteryState(
            t_s=rt.now[rover], energy_j=r.energy_j, capacity_j=r.capacity_j, soc=r.soc,
            ocv_v=r.ocv_v, voltage_v=r.voltage_v, current_a=r.current_a, power_w=r.power_w,
            temperature_c=r.temperature_c, operational=r.operational,
            fault_code=battery_fault_code(r.faults), faults=r.faults,
            time_to_empty_s=r.time_to_empty_s, heat_w=r.heat_w,
        ))

    def on_clock(s: Sample) -> None:
        tick = decode(s.payload, Clock)
        packs[s.rover].step(tick.dt_s)
        publish(s.rover)

    def on_summary(s: Sample) -> None:
        summary = decode(s.payload, PowerSummary)
        pack = packs[s.rover]
        if summary.net_battery_power_w != pack.demand_w:
            pack.set_demand(summary.net_battery_power_w)
            publish(s.rover)  # the bus voltage and current move at once, not at the next tick

    def apply_fault(rover: str, fk: FaultKey, params: dict | None) -> None:
        pack = packs[rover]
        if fk.kind == "capacity_loss":
            pack.apply_capacity_loss(params["fraction"] if params else 0.0)
        elif fk.kind == "resistance":
            pack.resistance_factor = params["factor"] if params else 1.0
        elif fk.kind == "heating":
            pack.injected_heat_w = params["heat_w"] if params else 0.0
        elif fk.kind == "disconnect":
            pack.disconnected = params is not None
        publish(rover)

    def persist() -> None:
        rt.save_state("state", {
            rover: {"energy_j": p.energy_j, "temperature_c": p.temperature_c,
                    "depleted": p.depleted, "thermal_cutoff": p.thermal_cutoff,
                    "t_s": rt.now[rover]}
            for rover, p in packs.items()
        })

    rt.subscribe(keys.clock("*"), on_clock)
    rt.subscribe(keys.power_summary("*"), on_summary)
    rt.handle_faults("battery", None, apply_fault)
    rt.restore_faults()
    rt.every(PERSIST_S, persist)
    rt.on_exit(persist)
    for rover in packs:
        publish(rover)
