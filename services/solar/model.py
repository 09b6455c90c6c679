"""Solar panels and the umbilical.

Panel power [W] = ``irradiance * area * efficiency * max(0, cos(angle)) *
(1 - dust) * (1 - degradation)``; a disconnected panel gives nothing. The sun angle is the
rover's (``input/sun_angle``) unless a panel has its own (``input/solar/<panel>/sun_angle``,
until it is deleted). Dust is the instructor's dust fault and the dashboard's
``input/solar/<panel>/dust``, two layers: ``1 - (1 - fault) * (1 - input)``, computed as
``fault + input - fault * input`` (exact with one layer). The umbilical, when connected, can
supply up to its ``power_w``.
"""

from __future__ import annotations

import math
from typing import Any

from common.config import Rover
from common.faults import FaultKey, FractionParams, Params

__all__ = ["SolarModel", "panel_power"]


def panel_power(irradiance_w_per_m2: float, area_m2: float, efficiency: float,
                sun_angle_deg: float, dust: float = 0.0, degradation: float = 0.0) -> float:
    """Electrical output of one panel [W]; zero when the sun is behind it (|angle| >= 90 deg)."""
    cos = max(0.0, math.cos(math.radians(sun_angle_deg)))
    return irradiance_w_per_m2 * area_m2 * efficiency * cos * (1.0 - dust) * (1.0 - degradation)


class SolarModel:
    def __init__(self, rover: Rover):
        self.cfg = rover.solar
        self.umbilical_cfg = rover.umbilical
        self.sun_angle_deg = rover.solar.sun_angle_deg
        self.panel_angle_deg: dict[str, float] = {}  # panels with their own sun angle
        self.dust = {p.name: 0.0 for p in rover.solar.panels}  # the dust fault's fraction
        self.input_dust: dict[str, float] = {}  # dust set as an input (the dashboard's)
        self.disconnected: set[str] = set()
        self.umbilical_plugged = rover.umbilical.connected
        self.umbilical_fault = False

    def state(self) -> dict[str, Any]:
        """The inputs that evolve (the panels' faults are re-applied by their owner)."""
        return {"sun_angle_deg": self.sun_angle_deg, "umbilical_plugged": self.umbilical_plugged,
                "panel_angle_deg": dict(self.panel_angle_deg), "input_dust": dict(self.input_dust)}

    def set_state(self, state: dict) -> None:
        self.sun_angle_deg = float(state.get("sun_angle_deg", self.cfg.sun_angle_deg))
        names = set(self.dust)
        self.panel_angle_deg = {n: float(a) for n, a in (state.get("panel_angle_deg") or {}).items()
                                if n in names}
        self.umbilical_plugged = bool(state.get("umbilical_plugged", self.umbilical_cfg.connected))
        self.input_dust = {k: float(v) for k, v in state.get("input_dust", {}).items() if k in names}

    def set_input_dust(self, panel: str, fraction: float | None) -> None:
        """Dust on a panel as an input (``input/solar/<panel>/dust``, what the dashboard
        sends); it combines with a dust fault as two layers: ``1 - (1 - a)(1 - b)``. None
        clears it."""
        if panel not in self.dust:
            raise ValueError(f"no panel {panel!r} (panels: {', '.join(self.dust) or 'none'})")
        if fraction is None:
            self.input_dust.pop(panel, None)
        else:
            self.input_dust[panel] = fraction

    def reset(self) -> None:
        """The rover file's sun angle and umbilical."""
        self.set_state({})

    def apply_fault(self, fault: FaultKey, params: Params | None) -> None:
        """Inject (``params``) or clear (None) a fault of a panel or of the umbilical."""
        if fault.component == "umbilical":
            self.umbilical_fault = params is not None
        elif fault.name not in self.dust:
            raise ValueError(f"no panel {fault.name!r}")
        elif fault.kind == "dust":
            self.dust[fault.name] = params.fraction if isinstance(params, FractionParams) else 0.0
        elif params is not None:
            self.disconnected.add(fault.name)
        else:
            self.disconnected.discard(fault.name)

    def panel_names(self) -> list[str]:
        return [p.name for p in self.cfg.panels]

    def set_panel_angle(self, panel: str, angle_deg: float | None) -> None:
        """Give one panel its own sun angle; None returns it to the rover's."""
        if panel not in self.dust:
            raise ValueError(f"no panel {panel!r}")
        if angle_deg is None:
            self.panel_angle_deg.pop(panel, None)
        else:
            self.panel_angle_deg[panel] = angle_deg

    def angle_of(self, panel: str) -> float:
        """The sun angle a panel sees [deg]."""
        return self.panel_angle_deg.get(panel, self.sun_angle_deg)

    def panels(self) -> list[tuple[str, float, float, list[str]]]:
        """``(panel, power_w, dust, faults)`` for every panel (its angle: :meth:`angle_of`)."""
        out = []
        for p in self.cfg.panels:
            fault_dust = self.dust[p.name]
            input_dust = self.input_dust.get(p.name, 0.0)
            dust = fault_dust + input_dust - fault_dust * input_dust  # exact with one layer
            faults = (["dust"] if fault_dust > 0.0 else []) + (
                ["disconnect"] if p.name in self.disconnected else [])
            power = 0.0 if p.name in self.disconnected else panel_power(
                self.cfg.irradiance_w_per_m2, p.area_m2, p.efficiency, self.angle_of(p.name),
                dust, p.degradation)
            out.append((p.name, power, dust, faults))
        return out

    @property
    def umbilical_connected(self) -> bool:
        return self.umbilical_plugged and not self.umbilical_fault

    @property
    def umbilical_power_w(self) -> float:
        return self.umbilical_cfg.power_w if self.umbilical_connected else 0.0
