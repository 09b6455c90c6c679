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
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from common import keys
from common.config import Rover
from common.faults import Fault
from common.messages import (
    BadInput,
    BatteryState,
    LoadPower,
    PowerSummary,
    RailCommand,
    RailState,
    SolarPower,
    UmbilicalState,
)
from common.node import Every, Node, Owns, PerRover, Publishes, Reads
from common.runtime import Sample
from services.power.model import PowerModel

__all__ = ["NODE", "Held", "Pdm", "PowerNode"]

HOLD_S = 0.04  # the longest a rover's recomputation waits for the rest of its tick's loads [s]
RESET_HOLD_S = 0.25  # the longest a rail reset waits for its rover's next tick (a paused clock) [s]


class Held(NamedTuple):
    """A rail command waiting for the rover's next tick of loads: a reset, or one behind it."""

    key: str
    rail: str
    cmd: RailCommand
    tick_t: float | None  # the rover's newest tick of loads when it came
    until: float  # monotonic time it is applied anyway
    actor: str = "instructor"  # who sent it (its answer says so)
    applied: list[float] | None = None  # the stamp of the rails it changed, once published


@dataclass
class Pdm(PerRover):
    """One rover's PDM and what the service remembers of its ticks and commands."""

    model: PowerModel
    rail_keys: list[str]  # rail/<name>/state of each rail, in the model's order
    due: float | None = None  # monotonic time it is recomputed anyway (while dirty)
    newest: float | None = None  # sim time of its newest load sample
    at_newest: set[str] = field(default_factory=set)  # the loads of that tick
    published: float | None = None  # the newest tick of loads when the rails last went out
    stamped: tuple[int, float] = (-1, 0.0)  # (epoch, t_s) of the last rails and summary out
    last_state: dict[str, str] = field(default_factory=dict)  # rail -> its state last published
    held: list[Held] = field(default_factory=list)  # rail commands waiting for a tick, in order
    # the resets applied whose answer waits for the loads to follow (tick_t: the tick they
    # were applied on)
    answering: list[Held] = field(default_factory=list)
    unstamped: list[Held] = field(default_factory=list)  # applied, the rails not yet published


class PowerNode(Node[Pdm]):
    """The PDM of every rover served: rails and summary once per tick of loads, commands
    answered in words."""

    name = "power"
    reads = (
        Reads("load/*/power", LoadPower, "on_load", check="feeds_rail"),
        Reads("battery/state", BatteryState, "on_battery"),
        Reads("solar/*/power", SolarPower, "on_solar"),
        Reads("umbilical/state", UmbilicalState, "on_umbilical"),
        Reads("cmd/rail/*", RailCommand, "on_command", kind="command", check="has_rail"),
    )
    publishes = (Publishes("rail/*/state", RailState), Publishes("power/summary", PowerSummary))
    owns = (Owns("rail", "apply_faults", names="rail_names"),)
    timers = (Every(HOLD_S / 4, "flush"),)
    # The loads of a rover arrive as a burst each tick: fold it into one recomputation.
    after_batch = "flush"

    def __init__(self, rovers: list[Rover], seed: int | None = None):
        self.dirty: set[str] = set()  # rovers with news not yet published
        super().__init__(rovers, seed)

    def rover_state(self, rover: Rover) -> Pdm:
        model = PowerModel(rover)
        return Pdm(rover.id, model, [keys.rail_state(rover.id, n) for n in model.rail_names()])

    def publish_pdm(self, pdm: Pdm, tick_t: float | None = None) -> None:
        """The rover's rails and summary: of the tick of loads ``tick_t`` (stamped with it), or
        news between ticks (stamped with the rover's time now). Never stamped later than the
        time this service has reached (what it saves, and starts again from), nor earlier
        than its last stamp in the same epoch."""
        m = pdm.model
        readings, summary = m.compute()
        t = self.rt.t_s[pdm.id]
        if tick_t is not None:  # a service that heard the clock before that tick's loads
            t = min(t, tick_t)
        stamp = (self.rt.epoch[pdm.id], t)
        if stamp < pdm.stamped:  # (a tick older than news already out: never back)
            stamp = pdm.stamped
        pdm.stamped, t = stamp, stamp[1]
        pdm.published = pdm.newest
        for c in pdm.unstamped:  # the time of the rails they changed: their events' time
            if c.applied is not None:
                c.applied.append(t)
        pdm.unstamped.clear()
        for key, r in zip(pdm.rail_keys, readings, strict=True):
            self.publish(key, RailState(t, *r[1:]))  # the reading's fields but its name, in order
            if pdm.last_state.get(r.name) != r.state:
                pdm.last_state[r.name] = r.state
                self.rt.faults.sync_derived(pdm.id, f"rail/{r.name}", m.derived_faults(r.name))
        self.publish(keys.power_summary(pdm.id), PowerSummary(t, *summary))

    # -- a tick's burst of loads, and news between ticks ------------------------------------

    def flush(self) -> None:
        now = time.monotonic()
        ready = []
        for rover in sorted(self.dirty):
            pdm = self.rovers[rover]
            if pdm.due is None:
                pdm.due = now + HOLD_S
            if len(pdm.at_newest) == len(pdm.model.load_power_w) or now >= pdm.due:
                ready.append(pdm)
        for pdm in ready:
            self.rt.urgent_first()  # a fleet's PDMs: a fault must not wait for the rest
            if pdm.held and (pdm.newest != pdm.held[0].tick_t or now >= pdm.held[0].until):
                self.command(pdm, self.take_held(pdm))
            self.publish_tick(pdm)
            self.answer_due(pdm, now)
        for pdm in self.rovers.values():
            if not (pdm.held or pdm.answering):  # (most rovers, most of the time)
                continue
            if pdm.held and now >= pdm.held[0].until:  # no tick came
                self.command(pdm, self.take_held(pdm))
                self.publish_pdm(pdm)
            self.answer_due(pdm, now)

    def publish_tick(self, pdm: Pdm) -> None:
        """The rover's newest tick of loads: published, stamped with it, nothing left waiting."""
        self.dirty.discard(pdm.id)
        pdm.due = None
        self.publish_pdm(pdm, pdm.newest)

    @staticmethod
    def take_held(pdm: Pdm) -> list[Held]:
        cmds, pdm.held = pdm.held, []
        return cmds

    def answer_due(self, pdm: Pdm, now: float) -> None:
        pending = pdm.answering
        if pending and (pdm.newest != pending[0].tick_t or now >= pending[0].until):
            pdm.answering = []
            self.answer(pdm, pending)

    def catch_up(self, pdm: Pdm) -> None:
        """The next tick's loads came before the last tick was published (a service behind,
        its batch holding two ticks of a rover): that tick goes out now, with its own time,
        rather than not at all. A held command waits for the tick that is coming."""
        self.publish_tick(pdm)

    def feeds_rail(self, pdm: Pdm, s: Sample) -> bool:
        return s.parts[1] in pdm.model.load_power_w

    def on_load(self, pdm: Pdm, load: LoadPower, s: Sample) -> None:
        # the loads publish every tick: the PDM follows them
        if load.t_s != pdm.newest:  # a new tick (or time put back by a reset)
            if (pdm.newest is not None and load.t_s > pdm.newest and pdm.published != pdm.newest
                    and pdm.id in self.dirty):
                self.catch_up(pdm)
            pdm.newest = load.t_s
            pdm.at_newest.clear()
        pdm.model.load_power_w[s.parts[1]] = load.power_w
        pdm.at_newest.add(s.parts[1])
        self.dirty.add(pdm.id)

    def on_battery(self, pdm: Pdm, b: BatteryState, s: Sample) -> None:
        m = pdm.model
        before = (m.battery_ok, [sw.shed for sw in m.switches.values()])
        m.set_battery(b.soc, b.operational, b.voltage_v)
        if before != (m.battery_ok, [sw.shed for sw in m.switches.values()]):
            self.dirty.add(pdm.id)

    def on_solar(self, pdm: Pdm, solar: SolarPower, s: Sample) -> None:
        m = pdm.model
        if m.panel_power_w.get(s.parts[1], solar.power_w) != solar.power_w:
            m.panel_power_w[s.parts[1]] = solar.power_w
            self.dirty.add(pdm.id)

    def on_umbilical(self, pdm: Pdm, umbilical: UmbilicalState, s: Sample) -> None:
        if pdm.model.umbilical_w != umbilical.power_w:
            pdm.model.umbilical_w = umbilical.power_w
            self.dirty.add(pdm.id)

    # -- rail commands ----------------------------------------------------------------------

    def has_rail(self, pdm: Pdm, s: Sample) -> bool:
        m, rail = pdm.model, s.parts[2]
        if rail in m.switches:
            return True
        if rail == m.solar_rail.name:
            raise BadInput(f"the solar rail {rail} cannot be switched")
        raise BadInput(f"rover {pdm.id} has no rail {rail!r} (rails: {', '.join(m.switches)})")

    def on_command(self, pdm: Pdm, cmd: RailCommand | None, s: Sample) -> None:
        if cmd is None:
            raise BadInput("a rail command is a put, not a delete")
        if cmd.on is None and not cmd.reset:
            raise BadInput('give {"on": true|false} or {"reset": true}')
        c = Held(s.key, s.parts[2], cmd, pdm.newest, time.monotonic() + RESET_HOLD_S,
                 self.rt.actor(s), [])
        if cmd.reset or pdm.held:  # judged on the next tick's loads (in order)
            pdm.held.append(c)
            return
        self.command(pdm, [c])
        self.publish_pdm(pdm)  # at once: the loads follow the new rail state

    def command(self, pdm: Pdm, cmds: list[Held]) -> None:
        """Apply rail commands, each answered by an event with the rail's state after it."""
        m = pdm.model
        for c in cmds:
            m.command(c.rail, on=c.cmd.on, reset=bool(c.cmd.reset))
        readings = {r.name: r for r in m.compute()[0]}  # trips a rail a reset cannot hold
        if any(c.cmd.reset and (r := readings.get(c.rail)) is not None and r.state == "on"
               for c in cmds):  # answered, in order, once the loads have seen the rail on
            until = time.monotonic() + RESET_HOLD_S
            waiting = [c._replace(tick_t=pdm.newest, until=until) for c in cmds]
            pdm.answering.extend(waiting)
            pdm.unstamped.extend(waiting)  # (the same lists of stamps as the commands')
            return
        self.answer(pdm, cmds)

    def answer(self, pdm: Pdm, cmds: list[Held]) -> None:
        """Each command's event: the rail's state now, in words the crew can act on, stamped
        with the time of the rails it changed (SPEC 13a: a reset answered a tick of loads later
        was stamped a tick after its effect, and the debrief had the fault settled before the
        action that settled it)."""
        readings = {r.name: r for r in pdm.model.compute()[0]}
        for c in cmds:
            what = ", ".join(w for w in (None if c.cmd.on is None else f"on={c.cmd.on}".lower(),
                                         "reset" if c.cmd.reset else None) if w)
            r = readings.get(c.rail)
            now, why = (r.state, r.reason) if r is not None else ("?", "")
            said = f"rail {c.rail}: {what}; the rail is now {now}"
            if now == "tripped" and c.cmd.reset:  # what the crew must hear: the fault is still there
                said += f": it tripped again at once ({why}), what draws that current is still there"
            elif now == "tripped" and c.cmd.on is False:  # what to do next: off is held, not shown
                said += (f" ({why}): a tripped rail stays tripped until it is reset; switched off "
                         "now, a reset leaves it off")
            elif now != "on" and why:
                said += f" ({why})"
            self.rt.event(pdm.id, "info", "command", c.key, said,
                          {"on": c.cmd.on, "reset": bool(c.cmd.reset), "state": now}, actor=c.actor,
                          t_s=c.applied[0] if c.applied else None)  # (given [] by on_command)

    # -- faults and state -------------------------------------------------------------------

    def rail_names(self, pdm: Pdm) -> list[str]:
        return pdm.model.rail_names()

    def apply_faults(self, pdm: Pdm, rail: str | None, faults: tuple[Fault, ...]) -> None:
        assert rail is not None  # a rail fault names its rail
        pdm.model.set_faults(rail, faults)
        self.publish_pdm(pdm)

    def get_state(self, pdm: Pdm) -> dict[str, Any]:
        return pdm.model.state()

    def set_state(self, pdm: Pdm, state: dict[str, Any]) -> None:
        pdm.model.set_state(state)

    def reset(self, pdm: Pdm) -> None:
        pdm.held.clear()  # a command from before a session reset does not outlive it
        pdm.answering.clear()
        pdm.model.reset()

    def republish(self, pdm: Pdm) -> None:
        self.publish_pdm(pdm)

    def start(self) -> None:
        for pdm in self.rovers.values():  # from the time reached (saved, or the clock's)
            pdm.stamped = (self.rt.epoch[pdm.id], self.rt.t_s[pdm.id])
            self.publish_pdm(pdm)


NODE = PowerNode
