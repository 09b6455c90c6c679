"""Clock service: publishes ``lunaris/<rover>/clock`` ticks; ``clock/control`` pauses and scales."""

from __future__ import annotations

from common import keys
from common.config import Rover
from common.messages import BadInput, Clock, ClockControl, decode_input
from common.runtime import Runtime, Sample
from services.clock.model import ClockModel, Tick

__all__ = ["serve"]


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    saved = rt.store.load("clock") or {}
    clocks: dict[str, ClockModel] = {}
    for rover in rovers:
        s = saved.get(rover.id, {})
        clocks[rover.id] = ClockModel(rover.tick_hz, t_s=s.get("t_s", 0.0), seq=s.get("seq", 0),
                                      time_scale=s.get("time_scale", 1.0),
                                      paused=s.get("paused", False))
        rt.t_s[rover.id] = clocks[rover.id].t_s

    def publish(rover: str, tick: Tick) -> None:
        rt.t_s[rover] = tick.t_s
        rt.publish(keys.clock(rover), Clock(**tick._asdict()))

    def ticker(rover: str, clock: ClockModel):
        return lambda: publish(rover, clock.tick())

    def on_control(s: Sample) -> None:
        ctl = decode_input(s.payload, ClockControl)
        if ctl.time_scale is None and ctl.paused is None:
            raise BadInput("give time_scale (> 0) or paused (true or false)")
        clock = clocks[s.rover]
        if ctl.time_scale is not None:
            clock.set_scale(ctl.time_scale)
        if ctl.paused is not None:
            clock.paused = ctl.paused
        rt.event(s.rover, "info", "clock", s.key,
                 f"clock {'paused' if clock.paused else 'running'} at x{clock.time_scale:g}")

    def persist() -> None:
        rt.store.save("clock", {r: {"t_s": c.t_s, "seq": c.seq, "time_scale": c.time_scale,
                                    "paused": c.paused} for r, c in clocks.items()})

    rt.subscribe(keys.clock_control("*"), on_control)
    for rover_id, clock in clocks.items():
        # A clock that falls behind skips ahead rather than bursting (see Runtime.every).
        rt.every(clock.period_s, ticker(rover_id, clock))
    rt.every(1.0, persist)
    rt.on_exit(persist)
