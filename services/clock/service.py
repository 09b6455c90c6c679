"""Clock service: publishes ``lunaris/<rover>/clock`` ticks; ``clock/control`` pauses and scales."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

import msgspec

from common import keys
from common.config import Rover
from common.messages import BadInput, Clock, ClockControl, decode_input
from common.runtime import Runtime, Sample
from common.session import RESTORE, parse_control
from services.clock.model import ClockModel, Tick

__all__ = ["serve"]


class SavedClock(msgspec.Struct):
    """What the clock saves: checked, types and ranges, when it is read back."""

    t_s: Annotated[float, msgspec.Meta(ge=0)]
    seq: Annotated[int, msgspec.Meta(ge=0)]
    epoch: Annotated[int, msgspec.Meta(ge=0)]
    time_scale: Annotated[float, msgspec.Meta(gt=0)] = 1.0
    paused: bool = False
    cause: str = ""


def check_state(rover: str, state: dict[str, Any]) -> None:
    msgspec.convert(state, SavedClock)


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    clocks = {r.id: ClockModel(r.tick_hz) for r in rovers}

    def publish(rover: str, tick: Tick) -> None:
        rt.t_s[rover] = tick.t_s
        rt.publish(keys.clock(rover), Clock(**tick._asdict()))

    def ticker(rover: str) -> Callable[[], None]:
        return lambda: publish(rover, clocks[rover].tick())

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

    def on_session(s: Sample) -> None:
        """The clock begins the new epoch of a reset or a restore; the others follow it."""
        control = parse_control(s.parts)
        if control is None or s.deleted or control[0] == "snapshot":
            return  # a snapshot is saved by every service itself; bad keys: the faults service
        action, name = control
        clock, keeper = clocks[s.rover], rt.keeper
        if action == "reset":
            keeper.reset(s.rover)  # the clock's reset begins the new epoch
        elif name in keeper.names(s.rover):
            keeper.restore(s.rover, name)
            clock.new_epoch(RESTORE + name)
        else:
            return  # no such snapshot: the faults service says so
        keeper.epoch[s.rover] = clock.epoch
        keeper.persist()
        publish(s.rover, clock.mark())

    def set_state(rover: str, state: dict[str, Any]) -> None:
        clocks[rover].set_state(state)
        rt.t_s[rover] = clocks[rover].t_s

    def damaged(rover: str) -> str:
        """Not the clock's reset, which would begin a reset of the whole twin."""
        clocks[rover] = ClockModel(clocks[rover].tick_hz)
        return "time starts at 0"

    rt.subscribe(keys.clock_control("*"), on_control)
    rt.subscribe(keys.control_reset("*"), on_session)
    rt.subscribe(keys.control_restore("*", "*"), on_session)
    # Saved every tick: a restarted clock goes on from its last tick, never back in time.
    period = min(c.period_s for c in clocks.values())
    rt.own_state(lambda rover: clocks[rover].state(), set_state,
                 lambda rover: clocks[rover].reset(), persist_every_s=period, check=check_state,
                 damaged=damaged)
    for rover_id in clocks:
        # A clock that falls behind skips ahead rather than bursting (see Runtime.every).
        rt.every(clocks[rover_id].period_s, ticker(rover_id))
