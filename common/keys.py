"""Every Zenoh key expression of SPEC §5, built in one place.

All keys live under ``lunaris/<rover>/``. Builders take a rover id (or ``"*"``
for a subscription across the fleet) and return a string. :func:`split`
parses a received key back into its rover and the rest.
"""

from __future__ import annotations

__all__ = [
    "ROOT",
    "battery_state",
    "clock",
    "clock_control",
    "cmd_rail",
    "event",
    "fault",
    "faults",
    "faults_journal",
    "input_radio_position",
    "input_sun_angle",
    "input_umbilical",
    "load_power",
    "power_summary",
    "radio_link",
    "rail_state",
    "rover_prefix",
    "service",
    "solar_power",
    "split",
    "umbilical_state",
]

ROOT = "lunaris"


def rover_prefix(rover: str) -> str:
    return f"{ROOT}/{rover}"


def clock(rover: str) -> str:
    return f"{ROOT}/{rover}/clock"


def clock_control(rover: str) -> str:
    return f"{ROOT}/{rover}/clock/control"


def battery_state(rover: str) -> str:
    return f"{ROOT}/{rover}/battery/state"


def load_power(rover: str, load: str) -> str:
    return f"{ROOT}/{rover}/load/{load}/power"


def rail_state(rover: str, rail: str) -> str:
    return f"{ROOT}/{rover}/rail/{rail}/state"


def power_summary(rover: str) -> str:
    return f"{ROOT}/{rover}/power/summary"


def solar_power(rover: str, panel: str) -> str:
    return f"{ROOT}/{rover}/solar/{panel}/power"


def umbilical_state(rover: str) -> str:
    return f"{ROOT}/{rover}/umbilical/state"


def radio_link(rover: str, radio: str) -> str:
    return f"{ROOT}/{rover}/radio/{radio}/link"


def input_sun_angle(rover: str) -> str:
    return f"{ROOT}/{rover}/input/sun_angle"


def input_radio_position(rover: str, radio: str) -> str:
    return f"{ROOT}/{rover}/input/radio/{radio}/position"


def input_umbilical(rover: str) -> str:
    return f"{ROOT}/{rover}/input/umbilical"


def cmd_rail(rover: str, rail: str) -> str:
    return f"{ROOT}/{rover}/cmd/rail/{rail}"


def fault(rover: str, component: str, kind: str) -> str:
    """``component`` is ``battery``, ``umbilical`` or ``<type>/<name>`` (``load/nav_camera``)."""
    return f"{ROOT}/{rover}/fault/{component}/{kind}"


def faults(rover: str) -> str:
    return f"{ROOT}/{rover}/faults"


def faults_journal(rover: str) -> str:
    return f"{ROOT}/{rover}/faults/journal"


def event(rover: str) -> str:
    return f"{ROOT}/{rover}/event"


def service(rover: str, name: str) -> str:
    return f"{ROOT}/{rover}/service/{name}"


def split(key: str) -> tuple[str, list[str]]:
    """``lunaris/mapp-1/load/imu/power`` -> ``("mapp-1", ["load", "imu", "power"])``."""
    parts = str(key).split("/")
    if len(parts) < 2 or parts[0] != ROOT:
        raise ValueError(f"key {key!r} is not under {ROOT}/<rover>/")
    return parts[1], parts[2:]
