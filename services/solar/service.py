"""Solar service: panel power and the umbilical; ``input/sun_angle`` moves the sun for every
panel, ``input/solar/<panel>/sun_angle`` for one (until deleted), ``input/solar/<panel>/dust``
lays dust on one (the dashboard's dust, besides the instructor's dust fault)."""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.faults import FaultKey, Params
from common.messages import (
    BadInput,
    Clock,
    DustInput,
    SolarPower,
    SunAngle,
    UmbilicalInput,
    UmbilicalState,
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
        for name, power_w, dust, faults in m.panels():
            rt.publish(keys.solar_power(rover, name), SolarPower(
                t_s=t, power_w=power_w, sun_angle_deg=m.sun_deg(name), dust=dust, faults=faults))
        rt.publish(keys.umbilical_state(rover), UmbilicalState(
            t_s=t, connected=m.umbilical_connected, power_w=m.umbilical_power_w))

    def on_tick(rover: str, tick: Clock) -> None:
        publish(rover)

    def on_sun(s: Sample) -> None:
        models[s.rover].sun_angle_deg = decode_input(s.payload, SunAngle, bare="angle_deg").angle_deg
        publish(s.rover)

    def on_panel_input(s: Sample) -> None:
        panel, what = s.parts[2], s.parts[3]
        m = models[s.rover]
        try:
            if what == "sun_angle":
                m.set_panel_sun(panel, None if s.deleted else decode_input(
                    s.payload, SunAngle, bare="angle_deg").angle_deg)
            else:
                m.set_input_dust(panel, None if s.deleted else decode_input(
                    s.payload, DustInput, bare="fraction").fraction)
        except ValueError as exc:
            raise BadInput(str(exc)) from None
        publish(s.rover)

    def on_umbilical(s: Sample) -> None:
        models[s.rover].umbilical_plugged = decode_input(
            s.payload, UmbilicalInput, bare="connected").connected
        publish(s.rover)

    def apply_fault(rover: str, fk: FaultKey, params: Params | None) -> None:
        models[rover].apply_fault(fk, params)
        publish(rover)

    rt.on_tick(on_tick)
    rt.subscribe(keys.input_sun_angle("*"), on_sun)
    rt.subscribe(keys.input_umbilical("*"), on_umbilical)
    rt.subscribe(keys.input_solar_sun_angle("*", "*"), on_panel_input)
    rt.subscribe(keys.input_solar_dust("*", "*"), on_panel_input)
    rt.faults.own("solar", lambda rover: models[rover].panel_names(), apply_fault)
    rt.faults.own("umbilical", None, apply_fault)
    rt.own_state(lambda rover: models[rover].state(), lambda rover, st: models[rover].set_state(st),
                 lambda rover: models[rover].reset(), after=publish)
    rt.faults.restore()
    for rover in models:
        publish(rover)
