"""Solar panels and the umbilical.

Panel power [W] = ``irradiance * area * efficiency * max(0, cos(angle)) *
(1 - dust) * (1 - degradation)``; a disconnected panel gives nothing. The sun angle is the
rover's (``input/sun_angle``) unless a panel has its own (``input/solar/<panel>/sun_angle``,
until it is deleted). Dust is the environment's, ``input/solar/<panel>/dust`` (what
``solar/<panel>/power.dust`` reports), and an instructor's dust fault on top, two layers:
``1 - (1 - fault) * (1 - input)``, computed as ``fault + input - fault * input`` (exact with
one layer). The model is given the faults in effect on each panel and on the umbilical
(:meth:`SolarModel.set_panel_faults`, :meth:`SolarModel.set_umbilical_faults`) and keeps
what they do, never a record of them: the panels have no alarms of their own.

The umbilical, when plugged in, can supply up to its ``power_w``. It is a cable of
``umbilical.cable_m`` (none: no slack at all): a rover that drives farther than that from
where it was plugged in pulls it out (:meth:`SolarModel.move_rover`). Distances are straight
lines in the site frame, from the rover's position when it was plugged in.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from common.config import Rover
from common.faults import Disconnect, Dust, FaultParams, kind_of

__all__ = ["SolarModel", "panel_power"]

Point = tuple[float, float, float]


def panel_power(irradiance_w_per_m2: float, area_m2: float, efficiency: float,
                sun_angle_deg: float, dust: float = 0.0, degradation: float = 0.0) -> float:
    """Electrical output of one panel [W]; zero when the sun is behind it (|angle| >= 90 deg)."""
    cos = max(0.0, math.cos(math.radians(sun_angle_deg)))
    return irradiance_w_per_m2 * area_m2 * efficiency * cos * (1.0 - dust) * (1.0 - degradation)


class SolarModel:
    def __init__(self, rover: Rover):
        self.cfg = rover.solar
        self.umbilical_cfg = rover.umbilical
        d = rover.drive
        self.start_m: Point = (d.start.x_m, d.start.y_m, d.start.z_m) if d is not None else (
            0.0, 0.0, 0.0)
        self.rover_m: Point = self.start_m  # where the rover is (drive/state)
        self.sun_angle_deg = rover.solar.sun_angle_deg
        self.panel_angle_deg: dict[str, float] = {}  # panels with their own sun angle
        self.input_dust: dict[str, float] = {}  # dust set as an input (the environment's)
        # what the injected faults do
        self.fault_dust = {p.name: 0.0 for p in rover.solar.panels}
        self.dark: set[str] = set()  # panels disconnected
        self.umbilical_cut = False  # no supply through the umbilical
        self.umbilical_plugged = rover.umbilical.connected
        self.plugged_at_m: Point | None = self.start_m if self.umbilical_plugged else None

    def state(self) -> dict[str, Any]:
        """The inputs that evolve (the panels' faults are re-applied by their owner)."""
        return {"sun_angle_deg": self.sun_angle_deg, "umbilical_plugged": self.umbilical_plugged,
                "plugged_at_m": None if self.plugged_at_m is None else list(self.plugged_at_m),
                "panel_angle_deg": dict(self.panel_angle_deg), "input_dust": dict(self.input_dust)}

    def set_state(self, state: dict) -> None:
        self.sun_angle_deg = float(state.get("sun_angle_deg", self.cfg.sun_angle_deg))
        names = set(self.fault_dust)
        self.panel_angle_deg = {n: float(a) for n, a in (state.get("panel_angle_deg") or {}).items()
                                if n in names}
        self.rover_m = self.start_m  # until the drive says where the rover is
        plugged = bool(state.get("umbilical_plugged", self.umbilical_cfg.connected))
        at = state.get("plugged_at_m")
        self.umbilical_plugged = plugged
        self.plugged_at_m = (tuple(float(v) for v in at) if isinstance(at, list) and len(at) == 3
                             else self.start_m) if plugged else None  # type: ignore[assignment]
        self.input_dust = {k: float(v) for k, v in state.get("input_dust", {}).items() if k in names}

    def set_input_dust(self, panel: str, fraction: float | None) -> None:
        """Dust on a panel as an input (``input/solar/<panel>/dust``, what the dashboard
        sends); it combines with a dust fault as two layers: ``1 - (1 - a)(1 - b)``. None
        clears it."""
        if panel not in self.fault_dust:
            raise ValueError(f"no panel {panel!r} (panels: {', '.join(self.fault_dust) or 'none'})")
        if fraction is None:
            self.input_dust.pop(panel, None)
        else:
            self.input_dust[panel] = fraction

    def reset(self) -> None:
        """The rover file's sun angle and umbilical."""
        self.set_state({})

    def set_panel_faults(self, panel: str, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on one panel, all of them. A kind that is not
        a panel's raises ValueError, and nothing changes."""
        if panel not in self.fault_dust:
            raise ValueError(f"no panel {panel!r}")
        dust, dark = 0.0, False
        for fault in faults:
            match fault:
                case Dust(fraction=fraction):
                    dust = fraction
                case Disconnect():
                    dark = True
                case _:
                    raise ValueError(f"a panel has no fault kind {kind_of(fault)!r}")
        self.fault_dust[panel] = dust
        if dark:
            self.dark.add(panel)
        else:
            self.dark.discard(panel)

    def set_umbilical_faults(self, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on the umbilical: ``disconnect`` cuts its supply."""
        cut = False
        for fault in faults:
            match fault:
                case Disconnect():
                    cut = True
                case _:
                    raise ValueError(f"the umbilical has no fault kind {kind_of(fault)!r}")
        self.umbilical_cut = cut

    # -- the umbilical's cable ----------------------------------------------------------------

    def plug(self, plugged: bool) -> None:
        """Plug the umbilical in where the rover is now, or pull it out."""
        self.umbilical_plugged = plugged
        self.plugged_at_m = self.rover_m if plugged else None

    @property
    def cable_m(self) -> float:
        """How far the rover may go from where it was plugged in [m] (no cable_m: 0)."""
        return self.umbilical_cfg.cable_m or 0.0

    def move_rover(self, x_m: float, y_m: float, z_m: float) -> float | None:
        """The rover is at (x, y, z) in the site frame: when that is farther than the cable
        from where the umbilical was plugged in, it is pulled out, and the distance [m] is
        returned (None otherwise)."""
        self.rover_m = (x_m, y_m, z_m)
        at = self.plugged_at_m
        if at is None or not self.umbilical_plugged:
            return None
        distance_m = math.dist(at, self.rover_m)
        if distance_m <= self.cable_m:
            return None
        self.plug(False)
        return distance_m

    # -- what it reads --------------------------------------------------------------------------

    def panel_names(self) -> list[str]:
        return [p.name for p in self.cfg.panels]

    def set_panel_angle(self, panel: str, angle_deg: float | None) -> None:
        """Give one panel its own sun angle; None returns it to the rover's."""
        if panel not in self.fault_dust:
            raise ValueError(f"no panel {panel!r}")
        if angle_deg is None:
            self.panel_angle_deg.pop(panel, None)
        else:
            self.panel_angle_deg[panel] = angle_deg

    def angle_of(self, panel: str) -> float:
        """The sun angle a panel sees [deg]."""
        return self.panel_angle_deg.get(panel, self.sun_angle_deg)

    def panels(self) -> list[tuple[str, float, float]]:
        """``(panel, power_w, dust)`` for every panel, ``dust`` the environment's (the input,
        what the panel's telemetry reports; a dust fault shows only as less power). Its angle:
        :meth:`angle_of`."""
        out = []
        for p in self.cfg.panels:
            fault_dust = self.fault_dust[p.name]
            input_dust = self.input_dust.get(p.name, 0.0)
            dust = fault_dust + input_dust - fault_dust * input_dust  # exact with one layer
            power = 0.0 if p.name in self.dark else panel_power(
                self.cfg.irradiance_w_per_m2, p.area_m2, p.efficiency, self.angle_of(p.name),
                dust, p.degradation)
            out.append((p.name, power, input_dust))
        return out

    @property
    def umbilical_connected(self) -> bool:
        return self.umbilical_plugged and not self.umbilical_cut

    @property
    def umbilical_power_w(self) -> float:
        return self.umbilical_cfg.power_w if self.umbilical_connected else 0.0
