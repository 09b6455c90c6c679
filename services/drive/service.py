"""Drive service: follows ``input/drive/traverse`` and publishes ``drive/state`` every tick.

It serves the rovers that have a ``drive`` section (``lunaris run drive`` leaves the others
out, see :meth:`DriveNode.serves`). A traverse is planned from where the rover is when it arrives
(:func:`common.traverse.plan`) and refused, with the reason, when it is malformed, has no
waypoint, asks for more than the rover's maximum speed or a leg steeper than its
``max_grade_deg``; an accepted one replaces the traverse being driven and is journalled as an
``input`` event. ``delete`` stops the rover where it is. The drive load's power comes from
``drive/state`` (the loads service applies it); its ``load/<name>/power`` (``on``: its rail is
on) and the loads' faults in effect (``faults/active/loads``, the fault book's record) tell this
service whether the motors are supplied (a rail off, an open or shorted load halt the rover).
A traverse is refused while the umbilical is plugged in (``umbilical/state``), unless its cable
follows the rover (SPEC §12e; the solar service unplugs a rover that drives past its cable).

``drive/route`` is the traverse being followed, for a map (:meth:`DriveModel.route`): published
when it changes (a traverse accepted or stopped, a reset, a restore) and at start, cached for
late joiners, never with every tick.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from common import keys
from common.config import Rover
from common.config import Umbilical as UmbilicalConfig
from common.faults import injected, supplies_device
from common.messages import (
    ActiveFault,
    ActiveFaults,
    BadInput,
    Clock,
    DriveRoute,
    DriveState,
    DriveTraverse,
    LoadPower,
    RouteWaypoint,
    SiteXYZ,
    UmbilicalState,
)
from common.node import Node, PerRover, Publishes, Reads
from common.runtime import Sample
from common.traverse import length_and_duration, plan
from services.drive.model import DriveModel, umbilical_holds

__all__ = ["NODE", "Drive", "DriveNode"]


@dataclass
class Drive(PerRover):
    """One rover's drive and what this service follows of the rest of the rover."""

    model: DriveModel
    load: str  # the drive load
    umbilical: UmbilicalConfig
    plugged: bool  # umbilical/state says it is plugged in (the rover file's until then)
    load_on: bool = True  # the drive load's rail is on (load/<load>/power)
    load_faults: list[ActiveFault] = field(default_factory=list)  # the loads' in effect


class DriveNode(Node[Drive]):
    """The drive of each rover served: traverses followed, stepped each tick."""

    name = "drive"
    reads = (
        Reads("input/drive/traverse", DriveTraverse, "on_traverse", kind="input"),
        # each rover's drive load only, not every load's samples
        Reads("load/*/power", LoadPower, "on_load", only="drive_loads"),
        Reads("faults/active/loads", ActiveFaults, "on_load_faults", kind="record",
              only="any_load_faults"),
        Reads("umbilical/state", UmbilicalState, "on_umbilical", only="any_umbilical"),
    )
    publishes = (
        Publishes("drive/state", DriveState),
        Publishes("drive/route", DriveRoute, reliable=True),  # rare: never dropped
    )

    @classmethod
    def serves(cls, rover: Rover) -> bool:
        """The drive service has something to do for this rover."""
        return rover.drive is not None

    def rover_state(self, rover: Rover) -> Drive:
        assert rover.drive is not None  # serves()
        max_w = next(ld.max_w for ld in rover.loads if ld.name == rover.drive.load)
        return Drive(rover.id, DriveModel(rover.drive, max_w), rover.drive.load, rover.umbilical,
                     rover.umbilical.connected)

    def publish_state(self, st: Drive) -> None:
        self.publish(keys.drive_state(st.id), DriveState(self.rt.t_s[st.id], *st.model.reading()))

    def publish_route(self, st: Drive) -> None:
        route = st.model.route()
        self.publish(keys.drive_route(st.id), DriveRoute(
            t_s=self.rt.t_s[st.id], start=None if route.start is None else SiteXYZ(*route.start),
            waypoints=[RouteWaypoint(w.x_m, w.y_m, w.z_m, w.speed_m_per_s)
                       for w in route.waypoints],
            return_to_start=route.return_to_start))

    def on_tick(self, st: Drive, tick: Clock) -> None:
        st.model.step(tick.dt_s)
        self.publish_state(st)

    def on_traverse(self, st: Drive, cmd: DriveTraverse | None, s: Sample) -> None:
        m = st.model
        if cmd is None:
            where = f"({m.x_m:.1f}, {m.y_m:.1f}, {m.z_m:.1f}) m"
            if not m.stop():
                raise BadInput(f"no traverse to stop: the rover is {m.status} at {where}")
            self.publish_state(st)
            self.publish_route(st)
            self.rt.event(st.id, "info", "input", s.key, f"traverse stopped at {where}, "
                          f"odometer {m.odometer_m:.1f} m")
            return
        held = umbilical_holds(st.umbilical, st.plugged)
        if held is not None:
            raise BadInput(held)
        start = (m.x_m, m.y_m, m.z_m)
        legs, problems = plan(cmd, m.cfg, start)
        if problems:
            raise BadInput("; ".join(problems))
        replaced = m.active
        m.start(legs, cmd.return_to_start)
        self.publish_state(st)
        self.publish_route(st)
        length, duration = length_and_duration(start, legs)
        self.rt.event(st.id, "info", "input", s.key,
                      f"{'traverse replaced' if replaced else 'traverse'}: {len(legs)} waypoint(s), "
                      f"{length:.1f} m, {duration / 60:.1f} min at the commanded speed"
                      f"{' (returning to the start)' if cmd.return_to_start else ''}",
                      {"waypoints": len(legs), "length_m": length, "duration_s": duration})

    # -- what moves it or holds it ----------------------------------------------------------

    def power(self, st: Drive) -> None:
        if st.model.set_powered(supplies_device(st.load_on,
                                                injected(st.load_faults, "load", st.load))):
            self.publish_state(st)

    def drive_loads(self) -> list[str]:
        return [keys.load_power(st.id, st.load) for st in self.rovers.values()]

    def on_load(self, st: Drive, power: LoadPower, s: Sample) -> None:
        st.load_on = power.on
        self.power(st)

    def any_load_faults(self) -> list[str]:
        return [keys.faults_active("*", "loads")] if self.rovers else []

    def any_umbilical(self) -> list[str]:
        return [keys.umbilical_state("*")] if self.rovers else []

    def on_load_faults(self, st: Drive, active: ActiveFaults, s: Sample) -> None:
        st.load_faults = active.faults
        self.power(st)

    def on_umbilical(self, st: Drive, umbilical: UmbilicalState, s: Sample) -> None:
        st.plugged = umbilical.connected

    # -- state ------------------------------------------------------------------------------

    def get_state(self, st: Drive) -> dict[str, Any]:
        return st.model.state()

    def set_state(self, st: Drive, state: dict[str, Any]) -> None:
        st.model.set_state(state)

    def reset(self, st: Drive) -> None:
        st.model.reset()
        st.plugged = st.umbilical.connected

    def republish(self, st: Drive) -> None:
        self.publish_state(st)
        self.publish_route(st)

    def start(self) -> None:
        for st in self.rovers.values():
            self.republish(st)


NODE = DriveNode
