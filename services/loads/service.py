"""Loads service: samples every load on the clock and publishes each one's power.

The drive load of a rover that drives takes its power from ``drive/state`` instead, and is
republished as soon as that changes. The fleet's samples are drawn together
(:class:`~services.loads.model.LoadsFleet`): a rover's tick costs its publications, little more.
"""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import Clock, DriveState, LoadPower, RailState, decode
from common.runtime import Runtime, Sample
from services.loads.model import LoadsFleet

__all__ = ["serve"]


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    fleet = LoadsFleet(rovers, seed)
    models = fleet.models
    load_keys = {r.id: [keys.load_power(r.id, ld.name) for ld in r.loads] for r in rovers}
    alarmed: dict[str, set[str]] = {r.id: set() for r in rovers}  # loads with an alarm up

    def publish(rover: str, only: set[str] | None = None) -> None:
        m = models[rover]
        t_s = rt.t_s[rover]
        for key, (name, power_w, rail, on) in zip(load_keys[rover], m.powers(), strict=True):
            if only is None or name in only:
                alarms = m.alarms(name, power_w)
                rt.publish(key, LoadPower(t_s=t_s, power_w=power_w, rail=rail, on=on,
                                          faults=alarms))
                if bool(alarms) != (name in alarmed[rover]):  # raised or resolved: the book's
                    alarmed[rover].symmetric_difference_update({name})
                    rt.faults.sync_derived(rover, f"load/{name}", {a: (
                        "critical", f"load {name} draws {power_w:.1f} W, above its max_w "
                        f"{m.max_w_of[name]:g} W") for a in alarms})

    def on_tick(rover: str, tick: Clock) -> None:
        if tick.dt_s > 0.0:  # a paused clock holds every load where it is
            fleet.sample(rover)
        publish(rover)

    def on_rail(s: Sample) -> None:
        rail = s.parts[1]
        m = models[s.rover]
        if rail in m.rail_on and m.set_rail(rail, decode(s.payload, RailState).state == "on"):
            publish(s.rover, {n for n, r in zip(m.names, m.rails, strict=True) if r == rail})

    drive_load = {r.id: r.drive.load for r in rovers if r.drive is not None}

    def on_drive(s: Sample) -> None:
        load = drive_load.get(s.rover)
        if load is not None and not s.deleted and models[s.rover].set_driven(
                load, decode(s.payload, DriveState).power_w):
            publish(s.rover, {load})

    def reset(rover: str) -> None:
        models[rover].reset_driven()

    def apply_faults(rover: str, name: str | None, faults: tuple[Fault, ...]) -> None:
        assert name is not None  # a load fault names its load
        models[rover].set_faults(name, faults)
        publish(rover, {name})

    rt.on_tick(on_tick)
    rt.subscribe(keys.rail_state("*", "*"), on_rail, telemetry=True)
    rt.subscribe(keys.drive_state("*"), on_drive, telemetry=True)
    rt.faults.own("load", lambda rover: models[rover].names, apply_faults)
    # No state of its own (rail_on mirrors the PDM, the drive load follows drive/state), but
    # its faults follow resets and snapshots.
    rt.own_state(lambda rover: {}, lambda rover, st: None, reset, after=publish,
                 persist_every_s=None)
    rt.faults.restore()
