"""Power service: the PDM. Folds load, battery and solar updates into rail states and totals.

One recomputation per tick: the loads publish every load of a rover each tick, and the rover's
rails and summary are published once all of that tick's loads have arrived (or ``HOLD_S``
after the first, should one be missing), however the burst is split between batches. News
between ticks (a command, a fault, a load republished when its rail changes) is published at
once.

A rail reset waits for the rover's next tick of loads (at most ``RESET_HOLD_S``): it is
judged on what the loads draw now, not on a sample the loads have since replaced. The loads'
news travels as telemetry, behind an instructor's command: a short cleared and the rail reset
at once had the reset judged on the short's 500 W still, and the rail tripped again (1 in
~400 shorts with a fleet of 100 rovers).

A reset that leaves its rail on is answered one tick of loads later (at most ``RESET_HOLD_S``):
the loads of a tripped rail draw nothing, so what the rail feeds shows only once they have seen
it on again. A short still there has tripped the rail by then, and the answer says so (SPEC
§12a: the crew hears that its reset did not hold), never "the rail is now on".
"""

from __future__ import annotations

import time
from typing import NamedTuple

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import (
    BARE_FIELD,
    BadInput,
    BatteryState,
    LoadPower,
    PowerSummary,
    RailCommand,
    RailState,
    SolarPower,
    UmbilicalState,
    decode,
    decode_input,
)
from common.runtime import Runtime, Sample
from services.power.model import PowerModel

__all__ = ["serve"]

HOLD_S = 0.04  # the longest a rover's recomputation waits for the rest of its tick's loads [s]
RESET_HOLD_S = 0.25  # the longest a rail reset waits for its rover's next tick (a paused clock) [s]


class _Held(NamedTuple):
    """A rail command waiting for the rover's next tick of loads: a reset, or one behind it."""
    key: str
    rail: str
    cmd: RailCommand
    tick_t: float | None  # the rover's newest tick of loads when it came
    until: float  # monotonic time it is applied anyway
    actor: str = "instructor"  # who sent it (its answer says so)


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None) -> None:
    models = {r.id: PowerModel(r) for r in rovers}
    dirty: set[str] = set()
    due: dict[str, float] = {}  # rover -> monotonic time it is recomputed anyway
    newest: dict[str, float] = {}  # rover -> sim time of its newest load sample
    at_newest: dict[str, set[str]] = {r.id: set() for r in rovers}  # the loads of that tick
    last_state: dict[tuple[str, str], str] = {}

    rail_keys = {rover: [keys.rail_state(rover, name) for name in m.rail_names()]
                 for rover, m in models.items()}

    def publish(rover: str) -> None:
        m = models[rover]
        readings, summary = m.compute()
        t = rt.t_s[rover]
        for key, r in zip(rail_keys[rover], readings, strict=True):
            rt.publish(key, RailState(t, *r[1:]))  # the reading's fields but its name, in order
            if last_state.get((rover, r.name)) != r.state:
                last_state[(rover, r.name)] = r.state
                rt.faults.sync_derived(rover, f"rail/{r.name}", m.derived_faults(r.name))
        rt.publish(keys.power_summary(rover), PowerSummary(t, *summary))

    held: dict[str, list[_Held]] = {}  # rover -> its rail commands waiting for a tick, in order
    # rover -> the resets applied whose answer waits for the loads to follow (tick_t: the tick
    # they were applied on)
    answering: dict[str, list[_Held]] = {}

    def answer_due(rover: str, now: float) -> None:
        pending = answering.get(rover)
        if pending and (newest.get(rover) != pending[0].tick_t or now >= pending[0].until):
            answer(rover, answering.pop(rover))

    def flush() -> None:
        now = time.monotonic()
        ready = [r for r in sorted(dirty) if len(at_newest[r]) == len(models[r].load_power_w)
                 or now >= due.setdefault(r, now + HOLD_S)]
        for rover in ready:
            rt.urgent_first()  # a fleet's PDMs: a fault must not wait for the rest
            dirty.discard(rover)
            due.pop(rover, None)
            if rover in held and (newest.get(rover) != held[rover][0].tick_t
                                  or now >= held[rover][0].until):
                command(rover, held.pop(rover))
            publish(rover)
            answer_due(rover, now)
        for rover in [r for r, cmds in held.items() if now >= cmds[0].until]:  # no tick came
            command(rover, held.pop(rover))
            publish(rover)
        for rover in list(answering):
            answer_due(rover, now)

    def command(rover: str, cmds: list[_Held]) -> None:
        """Apply rail commands, each answered by an event with the rail's state after it."""
        m = models[rover]
        for c in cmds:
            m.command(c.rail, on=c.cmd.on, reset=bool(c.cmd.reset))
        readings = {r.name: r for r in m.compute()[0]}  # trips a rail a reset cannot hold
        if any(c.cmd.reset and (r := readings.get(c.rail)) is not None and r.state == "on"
               for c in cmds):  # answered, in order, once the loads have seen the rail on
            until = time.monotonic() + RESET_HOLD_S
            answering.setdefault(rover, []).extend(
                c._replace(tick_t=newest.get(rover), until=until) for c in cmds)
            return
        answer(rover, cmds)

    def answer(rover: str, cmds: list[_Held]) -> None:
        """Each command's event: the rail's state now, in words the crew can act on."""
        readings = {r.name: r for r in models[rover].compute()[0]}
        for c in cmds:
            what = ", ".join(w for w in (None if c.cmd.on is None else f"on={c.cmd.on}".lower(),
                                         "reset" if c.cmd.reset else None) if w)
            r = readings.get(c.rail)
            now, why = (r.state, r.reason) if r is not None else ("?", "")
            said = f"rail {c.rail}: {what}; the rail is now {now}"
            if now == "tripped" and c.cmd.reset:  # what the crew must hear: the fault is still there
                said += f": it tripped again at once ({why}), what draws that current is still there"
            elif now != "on" and why:
                said += f" ({why})"
            rt.event(rover, "info", "command", c.key, said,
                     {"on": c.cmd.on, "reset": bool(c.cmd.reset), "state": now}, actor=c.actor)

    def on_load(s: Sample) -> None:
        m = models[s.rover]
        name = s.parts[1]
        if name in m.load_power_w:  # the loads publish every tick: the PDM follows them
            load = decode(s.payload, LoadPower)
            m.load_power_w[name] = load.power_w
            if load.t_s != newest.get(s.rover):  # a new tick (or time put back by a reset)
                newest[s.rover] = load.t_s
                at_newest[s.rover].clear()
            at_newest[s.rover].add(name)
            dirty.add(s.rover)

    def on_battery(s: Sample) -> None:
        b = decode(s.payload, BatteryState)
        m = models[s.rover]
        before = (m.battery_ok, [sw.shed for sw in m.switches.values()])
        m.set_battery(b.soc, b.operational, b.voltage_v)
        if before != (m.battery_ok, [sw.shed for sw in m.switches.values()]):
            dirty.add(s.rover)

    def on_solar(s: Sample) -> None:
        m = models[s.rover]
        power_w = decode(s.payload, SolarPower).power_w
        if m.panel_power_w.get(s.parts[1], power_w) != power_w:
            m.panel_power_w[s.parts[1]] = power_w
            dirty.add(s.rover)

    def on_umbilical(s: Sample) -> None:
        m = models[s.rover]
        power_w = decode(s.payload, UmbilicalState).power_w
        if m.umbilical_w != power_w:
            m.umbilical_w = power_w
            dirty.add(s.rover)

    def on_command(s: Sample) -> None:
        m = models[s.rover]
        rail = s.parts[2]
        if rail not in m.switches:
            if rail == m.solar_rail.name:
                raise BadInput(f"the solar rail {rail} cannot be switched")
            raise BadInput(f"rover {s.rover} has no rail {rail!r} "
                           f"(rails: {', '.join(m.switches)})")
        if s.deleted:
            raise BadInput("a rail command is a put, not a delete")
        cmd = decode_input(s.payload, RailCommand, bare=BARE_FIELD[RailCommand])
        if cmd.on is None and not cmd.reset:
            raise BadInput('give {"on": true|false} or {"reset": true}')
        c = _Held(s.key, rail, cmd, newest.get(s.rover), time.monotonic() + RESET_HOLD_S, rt.actor(s))
        if cmd.reset or s.rover in held:  # judged on the next tick's loads (in order)
            held.setdefault(s.rover, []).append(c)
            return
        command(s.rover, [c])
        publish(s.rover)  # at once: the loads follow the new rail state

    def apply_faults(rover: str, rail: str | None, faults: tuple[Fault, ...]) -> None:
        assert rail is not None  # a rail fault names its rail
        models[rover].set_faults(rail, faults)
        publish(rover)

    rt.subscribe(keys.load_power("*", "*"), on_load, telemetry=True)
    rt.subscribe(keys.battery_state("*"), on_battery, telemetry=True)
    rt.subscribe(keys.solar_power("*", "*"), on_solar, telemetry=True)
    rt.subscribe(keys.umbilical_state("*"), on_umbilical, telemetry=True)
    rt.subscribe(keys.cmd_rail("*", "*"), on_command)
    rt.faults.own("rail", lambda rover: models[rover].rail_names(), apply_faults)
    def reset(rover: str) -> None:
        held.pop(rover, None)  # a command from before a session reset does not outlive it
        answering.pop(rover, None)
        models[rover].reset()

    rt.own_state(lambda rover: models[rover].state(), lambda rover, st: models[rover].set_state(st),
                 reset, after=publish)
    rt.faults.restore()
    # The loads of a rover arrive as a burst each tick: fold it into one recomputation.
    rt.after_batch(flush)
    rt.every(HOLD_S / 4, flush)
    for rover in models:
        publish(rover)
