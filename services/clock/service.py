"""Clock service: publishes ``lunaris/<rover>/clock`` ticks; ``clock/control`` pauses and scales.

It begins the epochs of the session: ``control/reset`` at once, ``control/restore/<name>``
once every service has checked its part of the snapshot (``snapshots/<service>?check=``):
all parts intact, the restore goes ahead; any part damaged or missing, it is refused with
the reason and nothing changes. The clock answers a restore (a ``session`` event, or a
``rejected`` one).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

import msgspec
import zenoh

from common import keys
from common.config import Rover
from common.messages import BadInput, Clock, ClockControl, decode_input
from common.runtime import Runtime, Sample
from common.session import NO_PART, RESTORE, parse_control
from services.clock.model import ClockModel, Tick

__all__ = ["serve"]

CHECK_TIMEOUT_S = 2.0  # how long a restore waits for the services' checks of their parts


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

    checking: dict[str, str] = {}  # rover -> the snapshot whose parts are being checked

    def on_session(s: Sample) -> None:
        """The clock begins the new epoch of a reset or a restore; the others follow it."""
        control = parse_control(s.parts)
        if control is None or s.deleted or control[0] == "snapshot":
            return  # a snapshot is saved by every service itself; bad keys: the faults service
        action, name = control
        if action == "reset":
            rt.keeper.reset(s.rover)  # the clock's reset begins the new epoch
            begin(s.rover)
            return
        if s.rover in checking:
            raise BadInput(f"snapshot {checking[s.rover]!r} is being checked for a restore: "
                           "send it again in a moment")
        checking[s.rover] = name
        answers: list[tuple[str, str | None]] = []  # (service, None: intact | NO_PART | damage)

        def on_reply(reply: zenoh.Reply) -> None:
            answers.append(_answer(reply))

        def on_done() -> None:
            rt.call_soon(decide, s.rover, s.key, name, answers)

        rt.zenoh_session.get(f"{keys.snapshots_of(s.rover, '*')}?check={name}",
                             zenoh.handlers.Callback(on_reply, on_done),
                             consolidation=zenoh.ConsolidationMode.NONE, timeout=CHECK_TIMEOUT_S)

    def decide(rover: str, key: str, name: str, answers: list[tuple[str, str | None]]) -> None:
        """Every service has checked its part (or not answered in time): all or nothing."""
        del checking[rover]
        keeper = rt.keeper
        held = sorted(svc for svc, problem in answers if problem is None)
        damaged = sorted((svc, p) for svc, p in answers if p not in (None, NO_PART) and svc != "?")
        missing = sorted(svc for svc, p in answers if p == NO_PART)
        silent = [p or "" for svc, p in answers if svc == "?"]  # a timeout: who is not known
        if not held and not damaged and not silent:
            known = keeper.names(rover)
            rt.reject(rover, key, f"no snapshot {name!r} of {rover} "
                                  f"(snapshots: {', '.join(known) or 'none'})")
            return
        if damaged or missing or silent:
            why = [f"the {svc} part is damaged ({problem})" for svc, problem in damaged]
            why += [f"the {svc} service holds no part of it" for svc in missing]
            why += [f"a service did not check its part within {CHECK_TIMEOUT_S:g} s ({problem})"
                    for problem in silent]
            rt.event(rover, "critical", "rejected", key,
                     f"rejected: snapshot {name!r} not restored: {'; '.join(why)}. Nothing "
                     f"changed (restored only when every part is intact)",
                     {"damaged": [svc for svc, _ in damaged], "missing": missing,
                      "intact": held})
            return
        if not keeper.restore(rover, name):  # checked a moment ago: changed since
            rt.event(rover, "critical", "rejected", key,
                     f"rejected: snapshot {name!r} not restored: the clock's part changed as it "
                     "was read; nothing changed")
            return
        clocks[rover].new_epoch(RESTORE + name)
        begin(rover)
        rt.event(rover, "info", "session", key, f"snapshot {name!r} restored (every part "
                 f"checked: {', '.join(held)})", {"services": held})

    def begin(rover: str) -> None:
        clock = clocks[rover]
        rt.keeper.epoch[rover] = clock.epoch
        rt.keeper.persist()
        publish(rover, clock.mark())

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


def _answer(reply: zenoh.Reply) -> tuple[str, str | None]:
    """(service, None | NO_PART | the damage) from a service's check of its part."""
    if reply.ok is not None:
        service = str(reply.ok.key_expr).rsplit("/", 1)[-1]
        try:
            infos = msgspec.json.decode(reply.ok.payload.to_bytes())
        except msgspec.DecodeError:
            return service, "its answer is not JSON"
        return service, None if infos else NO_PART
    raw = reply.err.payload.to_bytes() if reply.err is not None else b""
    try:
        err = msgspec.json.decode(raw)
        return str(err["service"]), str(err["problem"])
    except (msgspec.DecodeError, KeyError, TypeError):
        return "?", raw.decode("utf-8", "replace") or "no answer"
