"""Solar service: panel power and the umbilical; ``input/sun_angle`` moves the sun (for one
panel ``input/solar/<panel>/sun_angle``, until deleted), ``input/solar/<panel>/dust`` lays dust
on one (the dashboard's, besides the instructor's dust fault; until deleted),
``input/umbilical`` plugs it in. Each accepted input is journalled as an ``input`` event.

The umbilical is a cable (SPEC §12e): for a rover that drives, this service follows
``drive/state``, and a rover that goes farther than ``umbilical.cable_m`` from where it was
plugged in pulls it out, which the twin journals as an ``input`` event of its own.
``umbilical/state`` says, for a map, where it was plugged in (while connected) and its
``cable_m``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import (
    BadInput,
    Clock,
    DriveState,
    DustInput,
    SiteXYZ,
    SolarPower,
    SunAngle,
    UmbilicalInput,
    UmbilicalState,
)
from common.node import Node, Owns, PerRover, Publishes, Reads
from common.runtime import Sample
from services.solar.model import SolarModel

__all__ = ["NODE", "Solar", "SolarNode"]


@dataclass
class Solar(PerRover):
    """One rover's panels and umbilical (the model keeps all there is of them)."""

    model: SolarModel


class SolarNode(Node[Solar]):
    """The panels and the umbilical of the rovers served: published each tick and on a change."""

    name = "solar"
    reads = (
        Reads("input/sun_angle", SunAngle, "on_sun", kind="input"),
        Reads("input/solar/*/sun_angle", SunAngle, "on_panel_angle", kind="input",
              check="known_panel"),
        Reads("input/umbilical", UmbilicalInput, "on_umbilical", kind="input"),
        Reads("input/solar/*/dust", DustInput, "on_dust", kind="input", check="known_panel"),
        Reads("drive/state", DriveState, "on_drive", only="if_driving"),
    )
    publishes = (Publishes("solar/*/power", SolarPower), Publishes("umbilical/state", UmbilicalState))
    owns = (Owns("solar", "apply_panel_faults", names="panel_names"),
            Owns("umbilical", "apply_umbilical_faults"))

    def rover_state(self, rover: Rover) -> Solar:
        return Solar(rover.id, SolarModel(rover))

    def publish_power(self, st: Solar) -> None:
        m = st.model
        t = self.rt.t_s[st.id]
        for name, power_w, dust in m.panels():
            self.publish(keys.solar_power(st.id, name), SolarPower(
                t_s=t, power_w=power_w, sun_angle_deg=m.angle_of(name), dust=dust))
        at = m.umbilical_plugged_at
        self.publish(keys.umbilical_state(st.id), UmbilicalState(
            t_s=t, connected=m.umbilical_connected, power_w=m.umbilical_power_w,
            plugged_at=None if at is None else SiteXYZ(*at), cable_m=m.umbilical_cfg.cable_m))

    def on_tick(self, st: Solar, tick: Clock) -> None:
        self.publish_power(st)

    # -- inputs -----------------------------------------------------------------------------

    def on_sun(self, st: Solar, sun: SunAngle | None, s: Sample) -> None:
        if sun is None:
            raise BadInput("the rover's sun angle cannot be deleted: put another angle")
        st.model.sun_angle_deg = sun.angle_deg
        self.publish_power(st)
        self.rt.accepted_input(st.id, s.key, f"sun angle {sun.angle_deg:g} deg",
                               {"angle_deg": sun.angle_deg})

    def known_panel(self, st: Solar, s: Sample) -> bool:
        """``input/solar/<panel>/...`` names a panel of the rover (whatever the payload)."""
        names = st.model.panel_names()
        if s.parts[2] not in names:
            raise BadInput(f"rover {st.id} has no panel {s.parts[2]!r} "
                           f"(panels: {', '.join(names) or 'none'})")
        return True

    def on_panel_angle(self, st: Solar, sun: SunAngle | None, s: Sample) -> None:
        """Set for one panel, or deleted: back to the rover's sun angle."""
        m, panel = st.model, s.parts[2]
        angle = None if sun is None else sun.angle_deg
        m.set_panel_angle(panel, angle)
        self.publish_power(st)
        self.rt.accepted_input(st.id, s.key, (
            f"panel {panel} back to the rover's sun angle ({m.sun_angle_deg:g} deg)"
            if angle is None else f"sun angle {angle:g} deg on panel {panel}"))

    def on_dust(self, st: Solar, dust: DustInput | None, s: Sample) -> None:
        """Laid on one panel, or deleted: no dust input there."""
        panel = s.parts[2]
        fraction = None if dust is None else dust.fraction
        st.model.set_input_dust(panel, fraction)
        self.publish_power(st)
        self.rt.accepted_input(st.id, s.key, f"no dust input on panel {panel}" if fraction is None
                               else f"dust {fraction:g} on panel {panel}")

    def on_umbilical(self, st: Solar, umbilical: UmbilicalInput | None, s: Sample) -> None:
        if umbilical is None:
            raise BadInput('the umbilical input is a put: {"connected": true|false}')
        plugged = umbilical.connected
        st.model.plug(plugged)
        self.publish_power(st)
        self.rt.accepted_input(st.id, s.key,
                               "umbilical " + ("plugged in" if plugged else "unplugged"),
                               {"connected": plugged})

    # -- the drive pulls the cable ----------------------------------------------------------

    def if_driving(self) -> list[str]:
        return [keys.drive_state("*")] if any(
            c.drive is not None for c in self.configs.values()) else []

    def on_drive(self, st: Solar, state: DriveState, s: Sample) -> None:
        m = st.model
        distance_m = m.move_rover(state.x_m, state.y_m, state.z_m)
        if distance_m is not None:
            self.publish_power(st)
            self.rt.event(st.id, "warning", "input", keys.input_umbilical(st.id),
                          f"umbilical unplugged: the rover drove {distance_m:.1f} m from where "
                          f"it was plugged in, past its {m.cable_m:g} m cable",
                          {"connected": False, "distance_m": distance_m, "cable_m": m.cable_m},
                          actor="twin")

    # -- faults and state -------------------------------------------------------------------

    def panel_names(self, st: Solar) -> list[str]:
        return st.model.panel_names()

    def apply_panel_faults(self, st: Solar, panel: str | None, faults: tuple[Fault, ...]) -> None:
        assert panel is not None  # a solar fault names its panel
        st.model.set_panel_faults(panel, faults)
        self.publish_power(st)

    def apply_umbilical_faults(self, st: Solar, _: str | None, faults: tuple[Fault, ...]) -> None:
        st.model.set_umbilical_faults(faults)
        self.publish_power(st)

    def get_state(self, st: Solar) -> dict[str, Any]:
        return st.model.state()

    def set_state(self, st: Solar, state: dict[str, Any]) -> None:
        st.model.set_state(state)

    def reset(self, st: Solar) -> None:
        st.model.reset()

    def republish(self, st: Solar) -> None:
        self.publish_power(st)

    def start(self) -> None:
        for st in self.rovers.values():
            self.publish_power(st)


NODE = SolarNode
