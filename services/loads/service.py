"""Loads service: samples every load on the clock and publishes each one's power.

The drive load of a rover that drives takes its power from ``drive/state`` instead, and is
republished as soon as that changes. The fleet's samples are drawn together
(:class:`~services.loads.model.LoadsFleet`): a rover's tick costs its publications, little more.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import Clock, DriveState, LoadPower, RailState
from common.node import Node, Owns, PerRover, Publishes, Reads
from common.runtime import Sample
from services.loads.model import LoadsFleet, LoadsModel

__all__ = ["NODE", "Loads", "LoadsNode"]


@dataclass
class Loads(PerRover):
    """One rover's loads (its model is a row of the fleet's draws)."""

    model: LoadsModel
    keys: list[str]  # load/<name>/power of each load, in the model's order
    drive_load: str | None  # the load the drive sets, for a rover that drives
    alarmed: set[str] = field(default_factory=set)  # loads with an alarm up


class LoadsNode(Node[Loads]):
    """Every load of the rovers served: sampled each tick, on or off with its rail."""

    name = "loads"
    reads = (
        Reads("rail/*/state", RailState, "on_rail", check="feeds_loads", deletes="reject"),
        Reads("drive/state", DriveState, "on_drive", check="drives"),
    )
    publishes = (Publishes("load/*/power", LoadPower),)
    owns = (Owns("load", "apply_faults", names="load_names"),)
    # No state of its own (rail_on mirrors the PDM, the drive load follows drive/state), but
    # its faults follow resets and snapshots.
    persist_every_s = None

    def __init__(self, rovers: Iterable[Rover], seed: int | None = None):
        rovers = list(rovers)
        self.fleet = LoadsFleet(rovers, seed)
        super().__init__(rovers, seed)

    def rover_state(self, rover: Rover) -> Loads:
        return Loads(rover.id, self.fleet.models[rover.id],
                     [keys.load_power(rover.id, ld.name) for ld in rover.loads],
                     rover.drive.load if rover.drive is not None else None)

    def publish_loads(self, st: Loads, only: set[str] | None = None) -> None:
        m = st.model
        t_s = self.rt.t_s[st.id]
        for key, (name, power_w, rail, on) in zip(st.keys, m.powers(), strict=True):
            if only is None or name in only:
                alarms = m.alarms(name, power_w)
                self.publish(key, LoadPower(t_s=t_s, power_w=power_w, rail=rail, on=on,
                                            faults=alarms))
                if bool(alarms) != (name in st.alarmed):  # raised or resolved: the book's
                    st.alarmed.symmetric_difference_update({name})
                    self.rt.faults.sync_derived(st.id, f"load/{name}", {a: (
                        "critical", f"load {name} draws {power_w:.1f} W, above its max_w "
                        f"{m.max_w_of[name]:g} W") for a in alarms})

    def on_tick(self, st: Loads, tick: Clock) -> None:
        if tick.dt_s > 0.0:  # a paused clock holds every load where it is
            self.fleet.sample(st.id)
        self.publish_loads(st)

    def feeds_loads(self, st: Loads, s: Sample) -> bool:
        return s.parts[1] in st.model.rail_on

    def on_rail(self, st: Loads, state: RailState, s: Sample) -> None:
        rail, m = s.parts[1], st.model
        if m.set_rail(rail, state.state == "on"):
            self.publish_loads(st, {n for n, r in zip(m.names, m.rails, strict=True) if r == rail})

    def drives(self, st: Loads, s: Sample) -> bool:
        return st.drive_load is not None

    def on_drive(self, st: Loads, drive: DriveState, s: Sample) -> None:
        assert st.drive_load is not None  # drives()
        if st.model.set_driven(st.drive_load, drive.power_w):
            self.publish_loads(st, {st.drive_load})

    def load_names(self, st: Loads) -> list[str]:
        return st.model.names

    def apply_faults(self, st: Loads, name: str | None, faults: tuple[Fault, ...]) -> None:
        assert name is not None  # a load fault names its load
        st.model.set_faults(name, faults)
        self.publish_loads(st, {name})

    def reset(self, st: Loads) -> None:
        st.model.reset_driven()

    def republish(self, st: Loads) -> None:
        self.publish_loads(st)


NODE = LoadsNode
