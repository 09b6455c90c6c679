"""Every Zenoh key expression of SPEC §5, built in one place, and the table of key families.

Longer than 450 lines on purpose: every key of the twin is built in this one module.

All keys live under ``lunaris/<rover>/``. Builders take a rover id (or ``"*"`` for a
subscription across the fleet) and return a string; :func:`split` parses a received key
back into its rover and the rest.

A *family* is a key shape after ``lunaris/<rover>/`` whose name chunks are placeholders
(``load/{load}/power``), with the msgspec Struct its payload follows, whether the twin
publishes it (telemetry, ``out``), reads it (an input or command, ``in``) or answers a
``get`` on it (``query``), and the service that owns it. :data:`FAMILIES` is the one table
every tool reads: the bridge's mapping validation, the recorder's schemas, the scenario
conditions, the gatekeeper that refuses keys nobody owns.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import msgspec

from common import messages as m
from common.scenario_progress import ScenarioProgress

__all__ = [
    # the families, each a key builder of its own: BATTERY_STATE.key(rover)
    "ARMED_FAULT", "BATTERY_STATE", "BRIDGE_DELIVERY", "CLOCK", "CLOCK_CONTROL", "CMD_RAIL",
    "DRIVE_ROUTE", "DRIVE_STATE", "EVENT", "FAULTS_ACTIVE", "INPUT_DRIVE_TRAVERSE",
    "INPUT_PANEL_SUN_ANGLE", "INPUT_RADIO_POSITION", "INPUT_SOLAR_DUST", "INPUT_SUN_ANGLE",
    "INPUT_UMBILICAL", "LOAD_POWER", "POWER_SUMMARY", "PREDICTION", "RADIO_LINK", "RAIL_STATE",
    "SCENARIO_PROGRESS", "SOLAR_POWER", "UMBILICAL_STATE", "DELETABLE",
    "FAMILIES",
    "PLACEHOLDERS",
    "ROOT",
    "SNAPSHOT_NAME",
    "Family",
    "battery_state",
    "clock",
    "clock_control",
    "cmd_rail",
    "control_mark",
    "control_reset",
    "control_restore",
    "control_scenario",
    "control_session",
    "control_snapshot",
    "drive_route",
    "drive_state",
    "event",
    "event_of",
    "families",
    "family_of",
    "family_of_template",
    "fault",
    "fault_prefix",
    "has_wildcard",
    "is_write",
    "faults",
    "faults_active",
    "faults_armed",
    "faults_armed_of",
    "faults_journal",
    "input_drive_traverse",
    "input_panel_sun_angle",
    "input_radio_position",
    "input_solar_dust",
    "input_sun_angle",
    "input_umbilical",
    "load_power",
    "power_summary",
    "prediction",
    "radio_link",
    "rail_state",
    "rover_prefix",
    "service",
    "service_claim",
    "service_claims",
    "service_owner",
    "sessions",
    "snapshots",
    "snapshots_of",
    "solar_power",
    "split",
    "telemetry_family",
    "umbilical_state",
    "under",
]

ROOT = "lunaris"
SNAPSHOT_NAME = m.SNAPSHOT_NAME  # a snapshot's name: one key chunk
PLACEHOLDERS = ("load", "rail", "radio", "panel")  # the component kinds a key can name


def rover_prefix(rover: str) -> str:
    return f"{ROOT}/{rover}"


def under(rover: str, tail: str = "**") -> str:
    """A key expression under a rover: ``under("*", "fault/**")`` -> ``lunaris/*/fault/**``."""
    return f"{ROOT}/{rover}/{tail}"


def clock(rover: str) -> str:
    return CLOCK.key(rover)


def clock_control(rover: str) -> str:
    return CLOCK_CONTROL.key(rover)


def battery_state(rover: str) -> str:
    return BATTERY_STATE.key(rover)


def load_power(rover: str, load: str) -> str:
    return LOAD_POWER.key(rover, load)


def rail_state(rover: str, rail: str) -> str:
    return RAIL_STATE.key(rover, rail)


def power_summary(rover: str) -> str:
    return POWER_SUMMARY.key(rover)


def solar_power(rover: str, panel: str) -> str:
    return SOLAR_POWER.key(rover, panel)


def umbilical_state(rover: str) -> str:
    return UMBILICAL_STATE.key(rover)


def radio_link(rover: str, radio: str) -> str:
    return RADIO_LINK.key(rover, radio)


def drive_state(rover: str) -> str:
    return DRIVE_STATE.key(rover)


def drive_route(rover: str) -> str:
    """The traverse the rover follows (published on change, for a map)."""
    return DRIVE_ROUTE.key(rover)


def input_drive_traverse(rover: str) -> str:
    return INPUT_DRIVE_TRAVERSE.key(rover)


def input_sun_angle(rover: str) -> str:
    return INPUT_SUN_ANGLE.key(rover)


def input_panel_sun_angle(rover: str, panel: str) -> str:
    """One panel's sun angle: overrides ``input/sun_angle`` for that panel until deleted."""
    return INPUT_PANEL_SUN_ANGLE.key(rover, panel)


def input_solar_dust(rover: str, panel: str) -> str:
    """The dashboard's dust on one panel, besides the instructor's dust fault."""
    return INPUT_SOLAR_DUST.key(rover, panel)


def input_radio_position(rover: str, radio: str) -> str:
    return INPUT_RADIO_POSITION.key(rover, radio)


def input_umbilical(rover: str) -> str:
    return INPUT_UMBILICAL.key(rover)


def cmd_rail(rover: str, rail: str) -> str:
    return CMD_RAIL.key(rover, rail)


def fault(rover: str, component: str, kind: str) -> str:
    """``component`` is ``battery``, ``umbilical`` or ``<type>/<name>`` (``load/nav_camera``)."""
    return f"{ROOT}/{rover}/fault/{component}/{kind}"


def fault_prefix(rover: str, component: str) -> str:
    """Every fault key of one component type: ``lunaris/<rover>/fault/<component>/**``."""
    return f"{ROOT}/{rover}/fault/{component}/**"


def derived_fault(rover: str, component: str, name: str) -> str:
    """The key a derived fault is known by: ``lunaris/<rover>/rail/12V/tripped``."""
    return f"{ROOT}/{rover}/{component}/{name}"


def faults(rover: str) -> str:
    return f"{ROOT}/{rover}/faults"


def faults_active(rover: str, service: str) -> str:
    """The faults in effect on the components one service owns (published and queryable)."""
    return FAULTS_ACTIVE.key(rover, service)


def faults_armed(rover: str) -> str:
    """``get`` lists the rover's armed faults (the faults service's, SPEC 13b)."""
    return f"{ROOT}/{rover}/faults/armed"


def faults_armed_of(rover: str, component: str, kind: str) -> str:
    """The key a fault is armed on (put) and disarmed (delete): ``component`` as for
    :func:`fault` (``load/nav_camera``)."""
    return f"{ROOT}/{rover}/faults/armed/{component}/{kind}"


def faults_journal(rover: str) -> str:
    return f"{ROOT}/{rover}/faults/journal"


def control_reset(rover: str) -> str:
    return f"{ROOT}/{rover}/control/reset"


def control_snapshot(rover: str, name: str) -> str:
    return f"{ROOT}/{rover}/control/snapshot/{name}"


def control_restore(rover: str, name: str) -> str:
    return f"{ROOT}/{rover}/control/restore/{name}"


def control_session(rover: str) -> str:
    """``{"trainee", "from_snapshot"?}``: end the running session, begin a trainee's (the clock
    answers)."""
    return f"{ROOT}/{rover}/control/session"


def control_mark(rover: str) -> str:
    """``{"text"}``: an instructor's mark on the timeline (a ``mark`` event of the faults service)."""
    return f"{ROOT}/{rover}/control/mark"


def sessions(rover: str) -> str:
    """``get`` lists the rover's trainee sessions (from the journal, by the faults service)."""
    return f"{ROOT}/{rover}/sessions"


def control_scenario(rover: str) -> str:
    """A scenario's progress, journalled by the faults service as ``scenario`` events."""
    return f"{ROOT}/{rover}/control/scenario"


def snapshots(rover: str) -> str:
    """``get`` lists the rover's snapshots (gathered by the faults service)."""
    return f"{ROOT}/{rover}/snapshots"


def snapshots_of(rover: str, service: str) -> str:
    """The snapshots one service holds of a rover (queryable)."""
    return f"{ROOT}/{rover}/snapshots/{service}"


def prediction(rover: str) -> str:
    """``get`` with ``?hours=8;samples=1000`` returns the Monte Carlo from the live state."""
    return PREDICTION.key(rover)


def event(rover: str) -> str:
    return EVENT.key(rover)


def event_of(rover: str, service: str) -> str:
    """The key a service publishes its events of a rover on (``lunaris/<rover>/event/<service>``):
    the access control lets only that service put there, and the faults service journals what
    arrives there and relays it on :func:`event` (SPEC §5's key)."""
    return f"{ROOT}/{rover}/event/{service}"


def service(rover: str, name: str) -> str:
    return f"{ROOT}/{rover}/service/{name}"


def service_claim(rover: str, name: str, zid: str) -> str:
    """Liveliness: an instance of a service claiming a rover as it starts (see
    :meth:`common.runtime.Runtime.claim`); below ``service/<name>``, out of ``service/*``."""
    return f"{ROOT}/{rover}/service/{name}/claim/{zid}"


def service_owner(rover: str, name: str, zid: str) -> str:
    """Liveliness: the instance of a service that won its claim on a rover, for its life."""
    return f"{ROOT}/{rover}/service/{name}/owner/{zid}"


def service_claims(rover: str, name: str) -> str:
    """Every claim and ownership of a service on a rover (liveliness key expression)."""
    return f"{ROOT}/{rover}/service/{name}/*/*"


def is_write(parts: list[str] | tuple[str, ...]) -> bool:
    """Whether a key's chunks after ``lunaris/<rover>/`` are a write to the twin: a fault, an
    input, a command, a clock or session control (what instructors, scenarios and dashboards
    put), or a fault armed (``faults/armed/...``)."""
    return bool(parts) and (parts[0] in ("fault", "input", "cmd", "control")
                            or (parts[0] == "clock" and len(parts) > 1 and parts[1] == "control")
                            or (parts[0] == "faults" and len(parts) > 2 and parts[1] == "armed"))


def has_wildcard(key: str) -> bool:
    """Whether a key expression names more than one key: a chunk ``*`` or ``**``, or ``$*``
    inside a chunk (``sun$*``). A write on such a key is never input (it would reach every
    owner whose keys it matches)."""
    return any(chunk in ("*", "**") or "$*" in chunk for chunk in str(key).split("/"))


def split(key: str) -> tuple[str, list[str]]:
    """``lunaris/mapp-1/load/imu/power`` -> ``("mapp-1", ["load", "imu", "power"])``."""
    parts = str(key).split("/")
    if len(parts) < 2 or parts[0] != ROOT:
        raise ValueError(f"key {key!r} is not under {ROOT}/<rover>/")
    return parts[1], parts[2:]


# -- families ----------------------------------------------------------------------------------

Direction = Literal["out", "in", "query"]  # published, read, or answered to a get


class Family(NamedTuple):
    """A family of keys: chunks after ``lunaris/<rover>/`` (``{load}`` stands for a name; a
    last chunk ``**`` for one chunk or more: ``faults/armed/**``, whose component takes one
    or two), its payload Struct, its direction and the service that owns it."""

    chunks: tuple[str, ...]
    payload: type[msgspec.Struct]
    direction: Direction
    owner: str

    @property
    def name(self) -> str:
        """``load/*/power``: the family as it is written in tables and recordings."""
        return "/".join("*" if c.startswith("{") else c for c in self.chunks)

    @property
    def placeholder(self) -> str | None:
        return next((c[1:-1] for c in self.chunks if c.startswith("{")), None)

    def pattern(self, rover: str = "*") -> str:
        """Zenoh key expression for every component of the family (of every rover)."""
        return "/".join([ROOT, rover, *("*" if c.startswith("{") else c for c in self.chunks)])

    def key(self, rover: str, name: str | None = None) -> str:
        """The key of one component (``LOAD_POWER.key("mapp-1", "imu")`` ->
        ``lunaris/mapp-1/load/imu/power``); ``name`` only for a family with a placeholder."""
        if (name is None) != (self.placeholder is None):
            wants = f"a {self.placeholder}" if self.placeholder else "no"
            raise TypeError(f"the key of {self.name} takes {wants} name")
        named = name or ""  # "" gives a prefix: faults_active(rover, "") -> .../faults/active/
        return "/".join([ROOT, rover, *(named if c.startswith("{") else c for c in self.chunks)])

    def matches(self, parts: list[str] | tuple[str, ...]) -> bool:
        if self.chunks[-1] == "**":
            head = self.chunks[:-1]
            return len(parts) > len(head) and tuple(parts[:len(head)]) == head
        return len(parts) == len(self.chunks) and all(
            c.startswith("{") or c == p for c, p in zip(self.chunks, parts, strict=True))


def _f(shape: str, payload: type[msgspec.Struct], owner: str, direction: Direction | None = None
       ) -> Family:
    return Family(tuple(shape.split("/")), payload,
                  direction or ("out" if m.is_telemetry(payload) else "in"), owner)


CLOCK = _f("clock", m.Clock, "clock")
BATTERY_STATE = _f("battery/state", m.BatteryState, "battery")
LOAD_POWER = _f("load/{load}/power", m.LoadPower, "loads")
RAIL_STATE = _f("rail/{rail}/state", m.RailState, "power")
POWER_SUMMARY = _f("power/summary", m.PowerSummary, "power")
SOLAR_POWER = _f("solar/{panel}/power", m.SolarPower, "solar")
UMBILICAL_STATE = _f("umbilical/state", m.UmbilicalState, "solar")
RADIO_LINK = _f("radio/{radio}/link", m.RadioLink, "radio")
DRIVE_STATE = _f("drive/state", m.DriveState, "drive")
DRIVE_ROUTE = _f("drive/route", m.DriveRoute, "drive")
EVENT = _f("event", m.Event, "*")
FAULTS_ACTIVE = _f("faults/active/{service}", m.ActiveFaults, "*")
INPUT_SUN_ANGLE = _f("input/sun_angle", m.SunAngle, "solar")
INPUT_PANEL_SUN_ANGLE = _f("input/solar/{panel}/sun_angle", m.SunAngle, "solar")
INPUT_RADIO_POSITION = _f("input/radio/{radio}/position", m.RadioPosition, "radio")
INPUT_SOLAR_DUST = _f("input/solar/{panel}/dust", m.DustInput, "solar")
INPUT_UMBILICAL = _f("input/umbilical", m.UmbilicalInput, "solar")
INPUT_DRIVE_TRAVERSE = _f("input/drive/traverse", m.DriveTraverse, "drive")
CMD_RAIL = _f("cmd/rail/{rail}", m.RailCommand, "power")
CLOCK_CONTROL = _f("clock/control", m.ClockControl, "clock")
PREDICTION = _f("prediction", m.Prediction, "battery", "query")
# an instructor arms a fault (SPEC 13b): faults/armed/<component>/<kind>, a delete disarms it
ARMED_FAULT = _f("faults/armed/**", m.ArmFault, "faults", "in")
BRIDGE_DELIVERY = _f("bridge/delivery", m.BridgeDelivery, "bridge")
# put by the scenario runner (a tool)
SCENARIO_PROGRESS = _f("scenario/progress", ScenarioProgress, "*", "out")

FAMILIES: tuple[Family, ...] = (
    CLOCK,
    BATTERY_STATE,
    LOAD_POWER,
    RAIL_STATE,
    POWER_SUMMARY,
    SOLAR_POWER,
    UMBILICAL_STATE,
    RADIO_LINK,
    DRIVE_STATE,
    DRIVE_ROUTE,
    EVENT,
    FAULTS_ACTIVE,
    INPUT_SUN_ANGLE,
    INPUT_PANEL_SUN_ANGLE,
    INPUT_RADIO_POSITION,
    INPUT_SOLAR_DUST,
    INPUT_UMBILICAL,
    INPUT_DRIVE_TRAVERSE,
    CMD_RAIL,
    CLOCK_CONTROL,
    PREDICTION,
    SCENARIO_PROGRESS,
    ARMED_FAULT,
    BRIDGE_DELIVERY,
)


# The inputs that take a delete: a panel back to the rover's sun angle, a panel's dust input
# gone, the rover stopped (by family name).
DELETABLE = ("input/solar/*/sun_angle", "input/solar/*/dust", "input/drive/traverse")


def families(direction: Direction | None = None) -> tuple[Family, ...]:
    return tuple(f for f in FAMILIES if direction is None or f.direction == direction)


def family_of(parts: list[str] | tuple[str, ...]) -> Family | None:
    """The family of a key's chunks after ``lunaris/<rover>/``, or None if it has none.

    >>> family_of(["load", "imu", "power"]).name
    'load/*/power'
    """
    return next((f for f in FAMILIES if f.matches(parts)), None)


def telemetry_family(parts: list[str] | tuple[str, ...]) -> Family | None:
    """The family of a key the twin publishes (telemetry, events, faults in effect); None
    for inputs, commands and keys outside every family."""
    fam = family_of(parts)
    return fam if fam is not None and fam.direction == "out" else None


def family_of_template(template: str) -> tuple[Family, str | None] | None:
    """The family of a key template ``lunaris/{rover}/...`` and the component it names (a
    literal name, a ``{placeholder}``, or None for keys without one); None when no family
    fits. ``lunaris/{rover}/rail/{rail}/state`` -> (rail family, ``"{rail}"``)."""
    parts = template.split("/")
    if len(parts) < 3 or parts[0] != ROOT or parts[1] != "{rover}":
        return None
    rest = parts[2:]
    for fam in FAMILIES:
        # a family of many shapes (faults/armed/**) is no template's: the crew's bridge never
        # arms a fault
        if len(fam.chunks) != len(rest) or fam.chunks[-1] == "**":
            continue
        item: str | None = None
        for want, got in zip(fam.chunks, rest, strict=True):
            if want.startswith("{"):
                if got.startswith("{") and got != want:
                    break
                item = got
            elif want != got:
                break
        else:
            return fam, item
    return None
