"""What is valid in a rover file but likely wrong: a rail its loads can trip in normal
operation, a pack whose BMS limit cannot carry the nominal loads without the sun, a pack
nothing can charge, a drive too weak for its top speed. ``lunaris check`` prints them as
warnings after a file has passed :mod:`common.config`.
"""

from __future__ import annotations

from common.config import Rover
from common.curves import ocv

__all__ = ["budget_warnings"]


def budget_warnings(rover: Rover) -> list[str]:
    """What is valid but likely wrong: a rail whose loads, all at ``max_w``, draw more than its
    current limit, so it can trip in normal operation."""
    warnings = []
    for rail in rover.rails:
        peak_w = sum(ld.max_w for ld in rover.loads if ld.rail == rail.name)
        if peak_w / rail.voltage_v > rail.current_limit_a:
            warnings.append(
                f"rails.{rail.name}: its loads can draw {peak_w / rail.voltage_v:.1f} A "
                f"(sum of max_w {peak_w:g} W at {rail.voltage_v:g} V), above current_limit_a "
                f"{rail.current_limit_a:g} A: it may trip in normal operation")
    warnings += _pack_warnings(rover)
    d = rover.drive
    load = next((ld for ld in rover.loads if d is not None and ld.name == d.load), None)
    if d is not None and load is not None:
        force_n = d.mass_kg * d.gravity_m_per_s2 * d.rolling_resistance
        need_w = force_n * d.max_speed_m_per_s / d.drivetrain_efficiency + d.idle_w
        if need_w > load.max_w:
            warnings.append(
                f"drive: on the flat at max_speed_m_per_s the drive needs {need_w:.1f} W, above "
                f"the max_w {load.max_w:g} W of load {load.name}: the rover never reaches full speed")
    return warnings


def _pack_warnings(rover: Rover) -> list[str]:
    """A pack that cannot carry the rover's nominal loads without the sun (its BMS limit at
    half charge), and one that nothing can charge. Found by a vehicle engineer: both passed
    ``check`` and ``sim`` without a word (sim averaged the unmet demand away)."""
    b, d = rover.battery, rover.drive
    rails = {r.name: r for r in rover.rails}
    bus_w = sum((d.idle_w if d is not None and ld.name == d.load else ld.nominal_w)
                / rails[ld.rail].efficiency for ld in rover.loads if ld.rail in rails)
    volts = ocv(0.5, b.ocv_curve.soc, b.ocv_curve.volts, b.cells_series)
    out = []
    if volts > 0.0 and bus_w / volts > b.max_discharge_a:
        out.append(f"battery.max_discharge_a: the loads at their nominal power need {bus_w:.1f} W on "
                   f"the bus (through the rails' efficiencies), {bus_w / volts:.2f} A from the pack at "
                   f"half charge ({volts:.1f} V), above max_discharge_a {b.max_discharge_a:g} A: without "
                   "the sun part of the demand is never met")
    if b.max_charge_w == 0.0 and (rover.solar.panels or rover.umbilical.power_w > 0.0):
        out.append("battery.max_charge_w: 0, so neither the panels nor the umbilical ever charge the pack")
    return out
