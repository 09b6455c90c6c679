"""Power distribution (the PDM): rails as converters from the battery bus.

A rail with load power ``P_r`` [W] at ``voltage_v`` carries ``I_r = P_r / V_r``
[A] and draws ``P_r / efficiency`` from the bus. A rail whose current exceeds
``current_limit_a`` trips and stays off until reset. Protection: every rail
goes off while the battery is non-operational; a rail with ``shed_below_soc``
is shed below it and restored at ``restore_above_soc`` (hysteresis). Solar
generation reaches the bus through the solar rail's efficiency; net battery
power is rail draw minus generation. A rail whose loads return power (a drive regenerating
on a descent) feeds the bus through the same converter: ``P_r * efficiency``.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from common.config import Rail, Rover, SolarRail
from common.faults import Fail, FaultParams, kind_of
from common.messages import COMMANDED_OFF, RailStateName, Severity

__all__ = ["COMMANDED_OFF", "PowerModel", "RailReading", "RailSwitch", "Summary"]

_ON: tuple[RailStateName, str] = ("on", "")


class RailReading(NamedTuple):
    name: str
    voltage_v: float
    current_a: float
    power_w: float
    current_limit_a: float | None
    state: RailStateName
    reason: str


class Summary(NamedTuple):
    load_power_w: float
    bus_power_w: float
    generation_w: float
    net_battery_power_w: float
    bus_voltage_v: float


class RailSwitch:
    """The switching state of one rail; ``state`` resolves it by precedence."""

    def __init__(self, cfg: Rail):
        self.cfg = cfg
        self.commanded_on = cfg.initially_on
        self.tripped = False
        self.failed = False
        self.shed = False
        self.trip_current_a = 0.0

    @property
    def restore_soc(self) -> float | None:
        c = self.cfg
        if c.shed_below_soc is None:
            return None
        return c.restore_above_soc if c.restore_above_soc is not None else c.shed_below_soc + 0.05

    def state(self, battery_ok: bool) -> tuple[RailStateName, str]:
        if self.failed:
            return "failed", "converter failed"
        if self.tripped:
            return "tripped", f"over-current {self.trip_current_a:.2f} A > {self.cfg.current_limit_a} A"
        if not battery_ok:
            return "off", "battery non-operational"
        if self.shed:
            return "shed", f"state of charge below {self.cfg.shed_below_soc}"
        if not self.commanded_on:
            return "off", COMMANDED_OFF
        return _ON


class PowerModel:
    """The PDM of one rover. Inputs are set as they arrive; :meth:`compute` resolves them."""

    def __init__(self, rover: Rover):
        self.rover = rover
        self.switches = {r.name: RailSwitch(r) for r in rover.rails}
        self._switch_list = list(self.switches.values())
        self._sheddable = [(sw, sw.cfg.shed_below_soc, sw.restore_soc) for sw in self._switch_list
                           if sw.cfg.shed_below_soc is not None and sw.restore_soc is not None]
        self.load_power_w = {ld.name: 0.0 for ld in rover.loads}  # its keys never change
        rail_index = {name: i for i, name in enumerate(self.switches)}
        self._load_rail_index = [rail_index[ld.rail] for ld in rover.loads]
        self.panel_power_w = {p.name: 0.0 for p in rover.solar.panels}
        self.umbilical_w = 0.0
        self.solar_failed = False
        self.battery_ok = True
        self.battery_soc = 1.0
        self.bus_voltage_v = 0.0

    @property
    def solar_rail(self) -> SolarRail:
        return self.rover.solar.rail

    def rail_names(self) -> list[str]:
        return list(self.switches) + [self.solar_rail.name]

    # -- inputs -----------------------------------------------------------------------------

    def set_battery(self, soc: float, operational: bool, voltage_v: float) -> None:
        """Battery state in; applies shedding with hysteresis."""
        self.battery_soc = soc
        self.battery_ok = operational
        self.bus_voltage_v = voltage_v
        for sw, shed_below, restore in self._sheddable:
            if not sw.shed and soc < shed_below:
                sw.shed = True
            elif sw.shed and soc >= restore:
                sw.shed = False

    def state(self) -> dict[str, dict[str, float | bool]]:
        """The switches of every rail (a converter failure is re-applied by its owner)."""
        return {name: {"commanded_on": sw.commanded_on, "tripped": sw.tripped,
                       "trip_current_a": sw.trip_current_a, "shed": sw.shed}
                for name, sw in self.switches.items()}

    def set_state(self, state: dict) -> None:
        for name, sw in self.switches.items():
            saved = state.get(name, {})
            sw.commanded_on = bool(saved.get("commanded_on", sw.cfg.initially_on))
            sw.tripped = bool(saved.get("tripped", False))
            sw.trip_current_a = float(saved.get("trip_current_a", 0.0))
            sw.shed = bool(saved.get("shed", False))

    def reset(self) -> None:
        """Every rail as the rover file says: its initial switch, not tripped, not shed."""
        self.set_state({})

    def set_faults(self, rail: str, faults: Iterable[FaultParams]) -> None:
        """Apply the injected faults in effect on one rail (the solar rail's too), all of
        them: ``fail`` kills its converter. A kind that is not a rail's raises ValueError."""
        failed = False
        for fault in faults:
            match fault:
                case Fail():
                    failed = True
                case _:
                    raise ValueError(f"a rail has no fault kind {kind_of(fault)!r}")
        if rail == self.solar_rail.name:
            self.solar_failed = failed
        elif rail in self.switches:
            self.switches[rail].failed = failed
        else:
            raise ValueError(f"no rail {rail!r}")

    def command(self, rail: str, on: bool | None = None, reset: bool = False) -> None:
        sw = self.switches[rail]
        if reset:
            sw.tripped = False
            sw.trip_current_a = 0.0
        if on is not None:
            sw.commanded_on = on

    # -- resolution -------------------------------------------------------------------------

    def compute(self) -> tuple[list[RailReading], Summary]:
        """Rail readings and bus totals; trips any rail over its limit (latched)."""
        per_rail = [0.0] * len(self._switch_list)
        for i, power_w in zip(self._load_rail_index, self.load_power_w.values(), strict=True):
            per_rail[i] += power_w  # in load order, from 0.0 (the composed twin's sums too)
        states, summary = self.resolve(per_rail)
        readings: list[RailReading] = []
        for (name, sw), power_w, (state, reason) in zip(self.switches.items(), per_rail,
                                                        states, strict=True):
            cfg = sw.cfg
            if state == "on":
                readings.append(RailReading(name, cfg.voltage_v, power_w / cfg.voltage_v,
                                            power_w, cfg.current_limit_a, state, reason))
            else:
                readings.append(RailReading(name, 0.0, 0.0, 0.0, cfg.current_limit_a, state, reason))
        sr = self.solar_rail
        panels_w = 0.0 if self.solar_failed else sum(self.panel_power_w.values())
        readings.append(RailReading(
            sr.name, sr.voltage_v if panels_w > 0.0 else 0.0, panels_w / sr.voltage_v, panels_w,
            sr.current_limit_a, "failed" if self.solar_failed else "on",
            "converter failed" if self.solar_failed else "",
        ))
        return readings, summary

    def resolve(self, rail_w: list[float]) -> tuple[list[tuple[RailStateName, str]], Summary]:
        """Each rail's ``(state, reason)`` and the bus totals, given the power its loads
        draw when it is on [W, in rail order]; trips any rail over its limit (latched).
        :meth:`compute` is this with the loads summed per rail; the composed twin, which
        sums them for many ticks at once, calls it directly."""
        ok = self.battery_ok
        states: list[tuple[RailStateName, str]] = []
        load_total = bus_total = 0.0
        for sw, power_w in zip(self._switch_list, rail_w, strict=True):
            # RailSwitch.state's precedence, without the call for a rail that is simply on
            on = ok and sw.commanded_on and not (sw.failed or sw.tripped or sw.shed)
            state = _ON if on else sw.state(ok)
            if on:
                cfg = sw.cfg
                current = power_w / cfg.voltage_v
                if current > cfg.current_limit_a:
                    sw.tripped = True
                    sw.trip_current_a = current
                    state = sw.state(ok)
                else:
                    load_total += power_w
                    # a rail whose loads return power (regeneration) feeds the bus through it
                    bus_total += power_w / cfg.efficiency if power_w >= 0.0 else power_w * cfg.efficiency
            states.append(state)
        panels_w = 0.0 if self.solar_failed else sum(self.panel_power_w.values())
        generation = panels_w * self.solar_rail.efficiency + self.umbilical_w
        summary = tuple.__new__(Summary, (load_total, bus_total, generation, bus_total - generation,
                                          self.bus_voltage_v))  # the constructor, without its cost
        return states, summary

    def derived_faults(self, rail: str) -> dict[str, tuple[Severity, str]]:
        """Faults a rail raises itself: name -> (severity, message)."""
        sw = self.switches.get(rail)
        if sw is None:
            return {}
        out: dict[str, tuple[Severity, str]] = {}
        if sw.tripped:
            out["tripped"] = ("critical", f"rail {rail} tripped: {sw.trip_current_a:.2f} A over "
                              f"its {sw.cfg.current_limit_a} A limit")
        if sw.shed and self.battery_ok:
            out["shed"] = ("warning", f"rail {rail} shed: state of charge "
                           f"{self.battery_soc:.3f} below {sw.cfg.shed_below_soc}")
        return out
