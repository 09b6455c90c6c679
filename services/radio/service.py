"""Radio service: link in range or not, published on change and at least once a second."""

from __future__ import annotations

import time
from typing import Any

from common import keys
from common.config import Rover
from common.faults import FaultKey, Params
from common.messages import BadInput, RadioLink, RadioPosition, decode_input
from common.runtime import Runtime, Sample
from services.radio.model import RadioModel

__all__ = ["serve"]

HEARTBEAT_S = 1.0


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    radios = {r.id: {c.name: RadioModel(c) for c in r.radios} for r in rovers}
    last: dict[tuple[str, str], tuple[bool, float]] = {}  # -> (in_range, wall time published)

    def publish(rover: str, name: str, force: bool = False) -> None:
        m = radios[rover][name]
        link = m.link()
        prev = last.get((rover, name))
        now = time.monotonic()
        if force or prev is None or prev[0] != link.in_range or now - prev[1] >= HEARTBEAT_S:
            last[(rover, name)] = (link.in_range, now)
            rt.publish(keys.radio_link(rover, name), RadioLink(
                t_s=rt.t_s[rover], faults=m.faults(), **link._asdict()))

    def heartbeat() -> None:
        for rover, named in radios.items():
            for name in named:
                publish(rover, name)

    def on_position(s: Sample) -> None:
        name = s.parts[2]
        if name not in radios[s.rover]:
            known = ", ".join(radios[s.rover]) or "none"
            raise BadInput(f"rover {s.rover} has no radio {name!r} (radios: {known})")
        pos = decode_input(s.payload, RadioPosition)
        radios[s.rover][name].set_position(pos.distance_m, pos.angle_deg)
        publish(s.rover, name, force=True)

    def apply_fault(rover: str, fk: FaultKey, params: Params | None) -> None:
        assert fk.name is not None
        radios[rover][fk.name].apply_fault(fk, params)
        publish(rover, fk.name, force=True)

    def get_state(rover: str) -> dict[str, Any]:
        return {name: m.state() for name, m in radios[rover].items()}

    def set_state(rover: str, state: dict[str, Any]) -> None:
        for name, m in radios[rover].items():
            m.set_state(state.get(name, {}))

    def republish(rover: str) -> None:
        for name in radios[rover]:
            publish(rover, name, force=True)

    rt.subscribe(keys.input_radio_position("*", "*"), on_position)
    rt.faults.own("radio", lambda rover: radios[rover], apply_fault)
    rt.own_state(get_state, set_state, lambda rover: set_state(rover, {}), after=republish)
    rt.faults.restore()
    rt.every(0.2, heartbeat)
    heartbeat()
