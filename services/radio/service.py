"""Radio service: link in range or not, published on change and at least once a second.

A link sample is sent reliably (it waits rather than being dropped under congestion): it is
rare, a lost change of ``in_range`` would stand for a second, and a dashboard marks a radio
whose samples stop as stale.

The rover's position relative to a radio comes from ``input/radio/<radio>/position``, except
for a radio with a ``site`` on a rover with a ``drive`` section: that radio follows the
rover, with the distance and bearing from its site to the position ``drive/state`` reports
(the rover file's ``drive.start`` until the drive says otherwise). Its position input is
refused then, with the reason: two sources of one position would contradict each other.
"""

from __future__ import annotations

import time
from typing import Any

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import BadInput, DriveState, RadioLink, RadioPosition, decode, decode_input
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
            rt.publish(keys.radio_link(rover, name), RadioLink(
                t_s=rt.t_s[rover], **link._asdict()), reliable=True)  # a radio has no alarm

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
    rt.faults.own("radio", lambda rover: radios[rover], apply_faults)
    for rover in starts:
        follow(rover, *starts[rover])
    rt.own_state(get_state, set_state, reset, after=republish)
    rt.faults.restore()
    rt.every(0.2, heartbeat)
    heartbeat()
