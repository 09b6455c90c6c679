"""Radio service: link in range or not, published on change and at least once a second.

A link sample is sent reliably (it waits rather than being dropped under congestion): it is
rare, a lost change of ``in_range`` would stand for a second, and a dashboard marks a radio
whose samples stop as stale.

The rover's position relative to a radio comes from ``input/radio/<radio>/position``, except
for a radio with a ``site`` on a rover with a ``drive`` section: that radio follows the
rover, with the distance and bearing from its site to the position ``drive/state`` reports
(the rover file's ``drive.start`` until the drive says otherwise). Its position input is
refused then, with the reason: two sources of one position would contradict each other.

Each link sample also carries what a map draws: the radio's ``site`` (null without one), its
nominal footprint (never scaled by an injected degradation) and ``follows_drive``.

A radio with a ``load`` needs it powered (SPEC §12e): this service follows that load's
``load/<load>/power`` (``on``: its rail is on) and the loads' faults in effect
(``faults/active/loads``, the fault book's record: an open or shorted load powers nothing);
without power the radio is out of range, with the alarm ``unpowered``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from common import keys
from common.config import Radio, Rover
from common.faults import Fault, injected, supplies_device
from common.messages import (
    ActiveFault,
    ActiveFaults,
    BadInput,
    DriveState,
    LoadPower,
    RadioLink,
    RadioPosition,
    SiteXY,
)
from common.node import Every, Node, Owns, PerRover, Publishes, Reads
from common.runtime import Sample
from services.radio.model import RadioModel, relative_to_site

__all__ = ["NODE", "RadioNode", "Radios"]

HEARTBEAT_S = 1.0


@dataclass
class Radios(PerRover):
    """One rover's radios and what the service remembers beside them."""

    models: dict[str, RadioModel]  # by radio
    following: list[Radio]  # the radios that follow the rover's drive (a site, a drive)
    start: tuple[float, float] | None  # where the rover starts (None: it does not drive)
    placed: dict[str, tuple[SiteXY | None, bool]]  # radio -> where a map draws it, follows
    powering: dict[str, list[str]]  # load -> the radios it powers
    load_on: dict[str, bool]  # load -> its rail is on (as the file starts it until told)
    load_faults: list[ActiveFault] = field(default_factory=list)  # the loads' in effect
    # radio -> (in_range, wall time published); radio -> its alarms up
    last: dict[str, tuple[bool, float]] = field(default_factory=dict)
    alarmed: dict[str, list[str]] = field(default_factory=dict)


class RadioNode(Node[Radios]):
    """The radios of the rovers served: in range or not, with their power and position."""

    name = "radio"
    reads = (
        Reads("input/radio/*/position", RadioPosition, "on_position", kind="input",
              check="positionable"),
        Reads("drive/state", DriveState, "on_drive", check="drives"),
        # each radio's load only, not every load's samples
        Reads("load/*/power", LoadPower, "on_load", check="powers_radios", only="radio_loads"),
        Reads("faults/active/loads", ActiveFaults, "on_load_faults", kind="record",
              check="has_powered", only="if_powered"),
    )
    publishes = (Publishes("radio/*/link", RadioLink, reliable=True),)
    owns = (Owns("radio", "apply_faults", names="radio_names"),)
    timers = (Every(0.2, "heartbeat"),)

    def rover_state(self, rover: Rover) -> Radios:
        rail_of = {ld.name: ld.rail for ld in rover.loads}
        initially_on = {rl.name: rl.initially_on for rl in rover.rails}
        following = [c for c in rover.radios if c.site is not None] if rover.drive else []
        powering: dict[str, list[str]] = {}
        load_on: dict[str, bool] = {}
        for c in rover.radios:
            if c.load is not None:
                powering.setdefault(c.load, []).append(c.name)
                load_on[c.load] = initially_on.get(rail_of[c.load], False)
        st = Radios(
            rover.id, {c.name: RadioModel(c) for c in rover.radios}, following,
            None if rover.drive is None else (rover.drive.start.x_m, rover.drive.start.y_m),
            {c.name: (None if c.site is None else SiteXY(c.site.x_m, c.site.y_m),
                      any(f.name == c.name for f in following)) for c in rover.radios},
            powering, load_on)
        if st.start is not None:
            self.follow(st, *st.start)
        return st

    def power_radios(self, st: Radios, load: str) -> None:
        powered = supplies_device(st.load_on[load], injected(st.load_faults, "load", load))
        for name in st.powering[load]:
            if st.models[name].set_powered(powered):
                self.publish_link(st, name, force=True)

    def follow(self, st: Radios, x_m: float, y_m: float) -> list[str]:
        """Move the radios that follow the drive to the rover at (x, y); their names."""
        names = []
        for c in st.following:
            assert c.site is not None  # following holds radios with a site
            st.models[c.name].set_position(*relative_to_site(c.site.x_m, c.site.y_m, x_m, y_m))
            names.append(c.name)
        return names

    def publish_link(self, st: Radios, name: str, force: bool = False) -> None:
        m = st.models[name]
        link = m.link()
        prev = st.last.get(name)
        now = time.monotonic()
        if force or prev is None or prev[0] != link.in_range or now - prev[1] >= HEARTBEAT_S:
            st.last[name] = (link.in_range, now)
            alarms = m.alarms()
            site, follows = st.placed[name]
            self.publish(keys.radio_link(st.id, name), RadioLink(
                t_s=self.rt.t_s[st.id], faults=alarms, **link._asdict(), site=site,
                follows_drive=follows, **m.footprint._asdict()))
            if st.alarmed.get(name, []) != alarms:
                st.alarmed[name] = alarms
                self.rt.faults.sync_derived(st.id, f"radio/{name}", {a: (
                    "warning", f"radio {name}: its load {m.cfg.load} has no power") for a in alarms})

    def heartbeat(self) -> None:
        for st in self.rovers.values():
            for name in st.models:
                self.publish_link(st, name)

    # -- inputs and streams -----------------------------------------------------------------

    def positionable(self, st: Radios, s: Sample) -> bool:
        name = s.parts[2]
        if name not in st.models:
            known = ", ".join(st.models) or "none"
            raise BadInput(f"rover {st.id} has no radio {name!r} (radios: {known})")
        if any(c.name == name for c in st.following):
            raise BadInput(f"radio {name} of {st.id} follows the rover's drive (its site and "
                           "drive/state give the position); move the rover with a traverse on "
                           "input/drive/traverse")
        return True

    def on_position(self, st: Radios, pos: RadioPosition | None, s: Sample) -> None:
        if pos is None:
            raise BadInput("a radio position is a put: {\"distance_m\": D, \"angle_deg\": A}")
        name = s.parts[2]
        st.models[name].set_position(pos.distance_m, pos.angle_deg)
        self.publish_link(st, name, force=True)
        link = st.models[name].link()
        self.rt.accepted_input(st.id, s.key, f"position to radio {name}: {pos.distance_m:g} m at "
                               f"{pos.angle_deg:g} deg ({'in range' if link.in_range else 'out of range'})",
                               {"distance_m": pos.distance_m, "angle_deg": pos.angle_deg})

    def drives(self, st: Radios, s: Sample) -> bool:
        return st.start is not None

    def on_drive(self, st: Radios, state: DriveState, s: Sample) -> None:
        for name in self.follow(st, state.x_m, state.y_m):
            self.publish_link(st, name)  # on a change of in_range at once, else with the heartbeat

    def radio_loads(self) -> list[str]:
        return [keys.load_power(st.id, load) for st in self.rovers.values() for load in st.powering]

    def powers_radios(self, st: Radios, s: Sample) -> bool:
        return s.parts[1] in st.powering

    def on_load(self, st: Radios, power: LoadPower, s: Sample) -> None:
        load = s.parts[1]
        if st.load_on[load] != power.on:
            st.load_on[load] = power.on
            self.power_radios(st, load)

    def if_powered(self) -> list[str]:
        return [keys.faults_active("*", "loads")] if any(
            st.powering for st in self.rovers.values()) else []

    def has_powered(self, st: Radios, s: Sample) -> bool:
        return bool(st.powering)

    def on_load_faults(self, st: Radios, active: ActiveFaults, s: Sample) -> None:
        st.load_faults = active.faults
        for load in st.powering:
            self.power_radios(st, load)

    # -- faults and state -------------------------------------------------------------------

    def radio_names(self, st: Radios) -> list[str]:
        return list(st.models)

    def apply_faults(self, st: Radios, name: str | None, faults: tuple[Fault, ...]) -> None:
        assert name is not None  # a radio fault names its radio
        st.models[name].set_faults(faults)
        self.publish_link(st, name, force=True)

    def get_state(self, st: Radios) -> dict[str, Any]:
        return {name: m.state() for name, m in st.models.items()}

    def set_state(self, st: Radios, state: dict[str, Any]) -> None:
        for name, m in st.models.items():
            m.set_state(state.get(name, {}))

    def reset(self, st: Radios) -> None:
        self.set_state(st, {})
        if st.start is not None:
            self.follow(st, *st.start)

    def republish(self, st: Radios) -> None:
        for name in st.models:
            self.publish_link(st, name, force=True)

    def start(self) -> None:
        for st in self.rovers.values():  # as the rover file starts the loads' rails
            for load in st.powering:
                self.power_radios(st, load)
        self.heartbeat()


NODE = RadioNode
