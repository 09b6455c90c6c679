"""Radio service: link in range or not, published on change and at least once a second.

A link sample is sent reliably (it waits rather than being dropped under congestion): it is
rare, a lost change of ``in_range`` would stand for a second, and a dashboard marks a radio
whose samples stop as stale.

The rover's position relative to a radio comes from ``input/radio/<radio>/position``, except
for a radio with a ``site`` on a rover with a ``drive`` section: that radio follows the
rover, with the distance and bearing from its site to the position ``drive/state`` reports
(the rover file's ``drive.start`` until the drive says otherwise). Its position input is
refused then, with the reason: two sources of one position would contradict each other.

A radio with a ``load`` needs it powered (SPEC §12e): this service follows that load's
``load/<load>/power`` (``on``: its rail is on) and the loads' faults in effect
(``faults/active/loads``, the fault book's record: an open or shorted load powers nothing);
without power the radio is out of range, with the alarm ``unpowered``.
"""

from __future__ import annotations

import time
from typing import Any

from common import keys
from common.config import Rover
from common.faults import Fault, injected, supplies_device
from common.messages import (
    ActiveFault,
    ActiveFaults,
    BadInput,
    DriveState,
    LoadPower,
    RadioLink,
    RadioPosition,
    decode,
    decode_input,
)
from common.runtime import Runtime, Sample
from services.radio.model import RadioModel, relative_to_site

__all__ = ["serve"]

HEARTBEAT_S = 1.0


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    radios = {r.id: {c.name: RadioModel(c) for c in r.radios} for r in rovers}
    last: dict[tuple[str, str], tuple[bool, float]] = {}  # -> (in_range, wall time published)
    # rover -> the radios that follow its drive, and where the rover starts
    following = {r.id: [c for c in r.radios if c.site is not None] for r in rovers if r.drive is not None}
    starts = {r.id: (r.drive.start.x_m, r.drive.start.y_m) for r in rovers if r.drive is not None}
    # rover -> load -> the radios it powers; whether each load's rail is on (as the file
    # starts it until the loads service says); the loads' faults in effect
    powering: dict[str, dict[str, list[str]]] = {}
    load_on: dict[tuple[str, str], bool] = {}
    for r in rovers:
        rail_of = {ld.name: ld.rail for ld in r.loads}
        initially_on = {rl.name: rl.initially_on for rl in r.rails}
        for c in r.radios:
            if c.load is not None:
                powering.setdefault(r.id, {}).setdefault(c.load, []).append(c.name)
                load_on[(r.id, c.load)] = initially_on.get(rail_of[c.load], False)
    load_faults: dict[str, list[ActiveFault]] = {}
    alarmed: dict[tuple[str, str], list[str]] = {}

    def power_radios(rover: str, load: str) -> None:
        powered = supplies_device(load_on[(rover, load)],
                                  injected(load_faults.get(rover, []), "load", load))
        for name in powering[rover][load]:
            if radios[rover][name].set_powered(powered):
                publish(rover, name, force=True)

    def follow(rover: str, x_m: float, y_m: float) -> list[str]:
        """Move the radios that follow the drive to the rover at (x, y); their names."""
        names = []
        for c in following.get(rover, []):
            assert c.site is not None  # following holds radios with a site
            radios[rover][c.name].set_position(*relative_to_site(c.site.x_m, c.site.y_m, x_m, y_m))
            names.append(c.name)
        return names

    def publish(rover: str, name: str, force: bool = False) -> None:
        m = radios[rover][name]
        link = m.link()
        prev = last.get((rover, name))
        now = time.monotonic()
        if force or prev is None or prev[0] != link.in_range or now - prev[1] >= HEARTBEAT_S:
            last[(rover, name)] = (link.in_range, now)
            alarms = m.alarms()
            rt.publish(keys.radio_link(rover, name), RadioLink(
                t_s=rt.t_s[rover], faults=alarms, **link._asdict()), reliable=True)
            if alarmed.get((rover, name), []) != alarms:
                alarmed[(rover, name)] = alarms
                rt.faults.sync_derived(rover, f"radio/{name}", {a: (
                    "warning", f"radio {name}: its load {m.cfg.load} has no power") for a in alarms})

    def heartbeat() -> None:
        for rover, named in radios.items():
            for name in named:
                publish(rover, name)

    def on_position(s: Sample) -> None:
        name = s.parts[2]
        if name not in radios[s.rover]:
            known = ", ".join(radios[s.rover]) or "none"
            raise BadInput(f"rover {s.rover} has no radio {name!r} (radios: {known})")
        if any(c.name == name for c in following.get(s.rover, [])):
            raise BadInput(f"radio {name} of {s.rover} follows the rover's drive (its site and "
                           "drive/state give the position); move the rover with a traverse on "
                           "input/drive/traverse")
        if s.deleted:
            raise BadInput("a radio position is a put: {\"distance_m\": D, \"angle_deg\": A}")
        pos = decode_input(s.payload, RadioPosition)
        radios[s.rover][name].set_position(pos.distance_m, pos.angle_deg)
        publish(s.rover, name, force=True)
        link = radios[s.rover][name].link()
        rt.accepted_input(s.rover, s.key, f"position to radio {name}: {pos.distance_m:g} m at "
                          f"{pos.angle_deg:g} deg ({'in range' if link.in_range else 'out of range'})",
                          {"distance_m": pos.distance_m, "angle_deg": pos.angle_deg})

    def on_drive(s: Sample) -> None:
        if s.deleted or s.rover not in following:
            return
        state = decode(s.payload, DriveState)
        for name in follow(s.rover, state.x_m, state.y_m):
            publish(s.rover, name)  # on a change of in_range at once, else with the heartbeat

    def apply_faults(rover: str, name: str | None, faults: tuple[Fault, ...]) -> None:
        assert name is not None  # a radio fault names its radio
        radios[rover][name].set_faults(faults)
        publish(rover, name, force=True)

    def on_load(s: Sample) -> None:
        load = s.parts[1]
        if s.deleted or load not in powering.get(s.rover, {}):
            return
        on = decode(s.payload, LoadPower).on
        if load_on[(s.rover, load)] != on:
            load_on[(s.rover, load)] = on
            power_radios(s.rover, load)

    def on_load_faults(s: Sample) -> None:
        if s.deleted or s.rover not in powering:
            return
        load_faults[s.rover] = decode(s.payload, ActiveFaults).faults
        for load in powering[s.rover]:
            power_radios(s.rover, load)

    def get_state(rover: str) -> dict[str, Any]:
        return {name: m.state() for name, m in radios[rover].items()}

    def set_state(rover: str, state: dict[str, Any]) -> None:
        for name, m in radios[rover].items():
            m.set_state(state.get(name, {}))

    def reset(rover: str) -> None:
        set_state(rover, {})
        if rover in starts:
            follow(rover, *starts[rover])

    def republish(rover: str) -> None:
        for name in radios[rover]:
            publish(rover, name, force=True)

    rt.subscribe(keys.input_radio_position("*", "*"), on_position)
    rt.subscribe(keys.drive_state("*"), on_drive, telemetry=True)
    for rover, loads in powering.items():  # each radio's load only, not every load's samples
        for load in loads:
            rt.subscribe(keys.load_power(rover, load), on_load, telemetry=True)
    if powering:
        rt.subscribe(keys.faults_active("*", "loads"), on_load_faults, history=True)
    rt.faults.own("radio", lambda rover: radios[rover], apply_faults)
    for rover in starts:
        follow(rover, *starts[rover])
    rt.own_state(get_state, set_state, reset, after=republish)
    rt.faults.restore()
    for rover, loads in powering.items():  # as the rover file starts the loads' rails
        for load in loads:
            power_radios(rover, load)
    rt.every(0.2, heartbeat)
    heartbeat()
