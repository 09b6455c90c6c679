"""Solar service: panel power and the umbilical; ``input/sun_angle`` moves the sun (for one
panel ``input/solar/<panel>/sun_angle``, until deleted), ``input/solar/<panel>/dust`` lays dust
on one (the dashboard's, besides the instructor's dust fault; until deleted),
``input/umbilical`` plugs it in. Each accepted input is journalled as an ``input`` event.

The umbilical is a cable (SPEC §12e): for a rover that drives, this service follows
``drive/state``, and a rover that goes farther than ``umbilical.cable_m`` from where it was
plugged in pulls it out, which the twin journals as an ``input`` event of its own."""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import (
    BARE_FIELD,
    BadInput,
    Clock,
    DriveState,
    DustInput,
    SolarPower,
    SunAngle,
    UmbilicalInput,
    UmbilicalState,
    decode,
    decode_input,
)
from common.runtime import Runtime, Sample
from services.solar.model import SolarModel

__all__ = ["serve"]


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    models = {r.id: SolarModel(r) for r in rovers}

    def publish(rover: str) -> None:
        m = models[rover]
        t = rt.t_s[rover]
        for name, power_w, dust in m.panels():
            rt.publish(keys.solar_power(rover, name), SolarPower(
                t_s=t, power_w=power_w, sun_angle_deg=m.angle_of(name), dust=dust))
        rt.publish(keys.umbilical_state(rover), UmbilicalState(
            t_s=t, connected=m.umbilical_connected, power_w=m.umbilical_power_w))

    def on_tick(rover: str, tick: Clock) -> None:
        publish(rover)

    def on_sun(s: Sample) -> None:
        if s.deleted:
            raise BadInput("the rover's sun angle cannot be deleted: put another angle")
        angle = decode_input(s.payload, SunAngle, bare=BARE_FIELD[SunAngle]).angle_deg
        models[s.rover].sun_angle_deg = angle
        publish(s.rover)
        rt.accepted_input(s.rover, s.key, f"sun angle {angle:g} deg", {"angle_deg": angle})

    def panel_input(s: Sample, what: str) -> None:
        """``input/solar/<panel>/sun_angle`` or ``/dust``: set for one panel, or deleted."""
        m, panel = models[s.rover], s.parts[2]
        if panel not in m.panel_names():
            raise BadInput(f"rover {s.rover} has no panel {panel!r} "
                           f"(panels: {', '.join(m.panel_names()) or 'none'})")
        if what == "sun_angle":
            angle = None if s.deleted else decode_input(
                s.payload, SunAngle, bare=BARE_FIELD[SunAngle]).angle_deg
            m.set_panel_angle(panel, angle)
            message = (f"panel {panel} back to the rover's sun angle ({m.sun_angle_deg:g} deg)"
                       if angle is None else f"sun angle {angle:g} deg on panel {panel}")
        else:
            fraction = None if s.deleted else decode_input(
                s.payload, DustInput, bare=BARE_FIELD[DustInput]).fraction
            m.set_input_dust(panel, fraction)
            message = (f"no dust input on panel {panel}" if fraction is None
                       else f"dust {fraction:g} on panel {panel}")
        publish(s.rover)
        rt.accepted_input(s.rover, s.key, message)

    def on_umbilical(s: Sample) -> None:
        if s.deleted:
            raise BadInput('the umbilical input is a put: {"connected": true|false}')
        plugged = decode_input(s.payload, UmbilicalInput, bare=BARE_FIELD[UmbilicalInput]).connected
        models[s.rover].plug(plugged)
        publish(s.rover)
        rt.accepted_input(s.rover, s.key, "umbilical " + ("plugged in" if plugged else "unplugged"),
                          {"connected": plugged})

    def apply_panel_faults(rover: str, panel: str | None, faults: tuple[Fault, ...]) -> None:
        assert panel is not None  # a solar fault names its panel
        models[rover].set_panel_faults(panel, faults)
        publish(rover)

    def apply_umbilical_faults(rover: str, _: str | None, faults: tuple[Fault, ...]) -> None:
        models[rover].set_umbilical_faults(faults)
        publish(rover)

    def on_drive(s: Sample) -> None:
        if s.deleted:
            return
        m = models[s.rover]
        state = decode(s.payload, DriveState)
        distance_m = m.move_rover(state.x_m, state.y_m, state.z_m)
        if distance_m is not None:
            publish(s.rover)
            # TODO(lead): actor="twin" once Event.actor lands (harden-input, D4)
            rt.event(s.rover, "warning", "input", keys.input_umbilical(s.rover),
                     f"umbilical unplugged: the rover drove {distance_m:.1f} m from where it was "
                     f"plugged in, past its {m.cable_m:g} m cable",
                     {"connected": False, "distance_m": distance_m, "cable_m": m.cable_m})

    rt.on_tick(on_tick)
    rt.subscribe(keys.input_sun_angle("*"), on_sun)
    rt.subscribe(keys.input_panel_sun_angle("*", "*"), lambda s: panel_input(s, "sun_angle"))
    rt.subscribe(keys.input_umbilical("*"), on_umbilical)
    rt.subscribe(keys.input_solar_dust("*", "*"), lambda s: panel_input(s, "dust"))
    if any(r.drive is not None for r in rovers):
        rt.subscribe(keys.drive_state("*"), on_drive, telemetry=True)
    rt.faults.own("solar", lambda rover: models[rover].panel_names(), apply_panel_faults)
    rt.faults.own("umbilical", None, apply_umbilical_faults)
    rt.own_state(lambda rover: models[rover].state(), lambda rover, st: models[rover].set_state(st),
                 lambda rover: models[rover].reset(), after=publish)
    rt.faults.restore()
    for rover in models:
        publish(rover)
