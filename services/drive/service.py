"""Drive service: follows ``input/drive/traverse`` and publishes ``drive/state`` every tick.

It serves the rovers that have a ``drive`` section (``lunaris run drive`` leaves the others
out, see :func:`serves`). A traverse is planned from where the rover is when it arrives
(:func:`common.traverse.plan`) and refused, with the reason, when it is malformed, has no
waypoint, asks for more than the rover's maximum speed or a leg steeper than its
``max_grade_deg``; an accepted one replaces the traverse being driven and is journalled as an
``input`` event. ``delete`` stops the rover where it is. The drive load's power comes from
``drive/state`` (the loads service applies it); its ``load/<name>/power`` (``on``: its rail is
on) and the loads' faults in effect (``faults/active/loads``, the fault book's record) tell this
service whether the motors are supplied (a rail off, an open or shorted load halt the rover).
A traverse is refused while the umbilical is plugged in (``umbilical/state``), unless its cable
follows the rover (SPEC §12e; the solar service unplugs a rover that drives past its cable).
"""

from __future__ import annotations

from typing import Any

from common import keys
from common.config import Rover
from common.faults import injected, supplies_device
from common.messages import (
    ActiveFault,
    ActiveFaults,
    BadInput,
    Clock,
    DriveState,
    DriveTraverse,
    LoadPower,
    UmbilicalState,
    decode,
    decode_input,
)
from common.runtime import Runtime, Sample
from common.traverse import length_and_duration, plan
from services.drive.model import DriveModel, umbilical_holds

__all__ = ["serve", "serves"]


def serves(rover: Rover) -> bool:
    """The drive service has something to do for this rover."""
    return rover.drive is not None


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    configs = {r.id: r for r in rovers if serves(r)}
    models: dict[str, DriveModel] = {}
    for rover_id, r in configs.items():
        assert r.drive is not None  # serves()
        max_w = next(ld.max_w for ld in r.loads if ld.name == r.drive.load)
        models[rover_id] = DriveModel(r.drive, max_w)
    load_on = dict.fromkeys(models, True)  # the drive load's rail is on (load/<load>/power)
    load_faults: dict[str, list[ActiveFault]] = {}  # the loads' faults in effect, per rover
    plugged = {r: configs[r].umbilical.connected for r in models}  # umbilical/state

    def publish(rover: str) -> None:
        if rover in models:
            rt.publish(keys.drive_state(rover), DriveState(rt.t_s[rover], *models[rover].reading()))

    def on_tick(rover: str, tick: Clock) -> None:
        if rover in models:
            models[rover].step(tick.dt_s)
            publish(rover)

    def on_traverse(s: Sample) -> None:
        m = models[s.rover]
        if s.deleted:
            where = f"({m.x_m:.1f}, {m.y_m:.1f}, {m.z_m:.1f}) m"
            if not m.stop():
                raise BadInput(f"no traverse to stop: the rover is {m.status} at {where}")
            publish(s.rover)
            rt.event(s.rover, "info", "input", s.key, f"traverse stopped at {where}, "
                     f"odometer {m.odometer_m:.1f} m")
            return
        cmd = decode_input(s.payload, DriveTraverse)
        held = umbilical_holds(configs[s.rover].umbilical, plugged[s.rover])
        if held is not None:
            raise BadInput(held)
        start = (m.x_m, m.y_m, m.z_m)
        legs, problems = plan(cmd, m.cfg, start)
        if problems:
            raise BadInput("; ".join(problems))
        replaced = m.active
        m.start(legs)
        publish(s.rover)
        length, duration = length_and_duration(start, legs)
        rt.event(s.rover, "info", "input", s.key,
                 f"{'traverse replaced' if replaced else 'traverse'}: {len(legs)} waypoint(s), "
                 f"{length:.1f} m, {duration / 60:.1f} min at the commanded speed"
                 f"{' (returning to the start)' if cmd.return_to_start else ''}",
                 {"waypoints": len(legs), "length_m": length, "duration_s": duration})

    def power(rover: str) -> None:
        load = configs[rover].drive.load  # type: ignore[union-attr]  # serves(): has a drive
        if models[rover].set_powered(supplies_device(
                load_on[rover], injected(load_faults.get(rover, []), "load", load))):
            publish(rover)

    def on_load(s: Sample) -> None:
        if not s.deleted:
            load_on[s.rover] = decode(s.payload, LoadPower).on
            power(s.rover)

    def on_load_faults(s: Sample) -> None:
        if not s.deleted and s.rover in models:
            load_faults[s.rover] = decode(s.payload, ActiveFaults).faults
            power(s.rover)

    def on_umbilical(s: Sample) -> None:
        if not s.deleted and s.rover in models:
            plugged[s.rover] = decode(s.payload, UmbilicalState).connected

    def get_state(rover: str) -> dict[str, Any]:
        return models[rover].state() if rover in models else {}

    def set_state(rover: str, state: dict[str, Any]) -> None:
        if rover in models:
            models[rover].set_state(state)

    def reset(rover: str) -> None:
        if rover in models:
            models[rover].reset()
            plugged[rover] = configs[rover].umbilical.connected

    rt.on_tick(on_tick)
    rt.subscribe(keys.input_drive_traverse("*"), on_traverse)
    for rover_id, r in configs.items():  # each rover's drive load only, not every load's samples
        assert r.drive is not None
        rt.subscribe(keys.load_power(rover_id, r.drive.load), on_load, telemetry=True)
    if models:
        rt.subscribe(keys.faults_active("*", "loads"), on_load_faults, history=True)
        rt.subscribe(keys.umbilical_state("*"), on_umbilical, telemetry=True)
    rt.own_state(get_state, set_state, reset, after=publish)
    for rover in models:
        publish(rover)
