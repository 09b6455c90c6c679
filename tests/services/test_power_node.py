"""The PDM node's one publication per tick of loads, driven by hand: no Zenoh, no process. A
stand-in runtime records what the node publishes; the samples are given as the runtime's
worker hands them over (a batch, then ``flush``)."""

from __future__ import annotations

from typing import Any

import msgspec

from common import keys
from common.config import load_rover
from common.messages import LoadPower, RailCommand, RailState
from common.runtime import Sample
from services.power.service import PowerNode
from testbed.twin import static_rover

ROVER = "mapp-1"


class _Faults:
    def sync_derived(self, *_: Any) -> None:
        pass


class _Runtime:
    """What PowerNode uses of a Runtime: the rover's time, publish, the fault book's derived
    faults, urgent_first."""

    def __init__(self) -> None:
        self.t_s = {ROVER: 0.0}
        self.epoch = {ROVER: 0}
        self.faults = _Faults()
        self.published: list[tuple[str, Any]] = []
        self.events: list[tuple[str, str, float]] = []  # (kind, message, t_s as the event says)

    def event(self, rover: str, severity: str, kind: str, key: str, message: str,
              params: dict | None = None, *, actor: str | None = None, t_s: float | None = None) -> None:
        self.events.append((kind, message, self.t_s[rover] if t_s is None or t_s > self.t_s[rover] else t_s))

    def actor(self, _sample: Any) -> str:
        return "crew"

    def publish(self, key: str, msg: msgspec.Struct, **_: Any) -> None:
        self.published.append((key, msg))

    def urgent_first(self) -> None:
        pass


def _node() -> tuple[PowerNode, _Runtime, list[str]]:
    rover = load_rover(static_rover("mapp.yaml"))
    node = PowerNode([rover])
    rt = _Runtime()
    node.rt = rt  # type: ignore[assignment]
    return node, rt, [ld.name for ld in rover.loads]


def _loads(node: PowerNode, names: list[str], t_s: float) -> None:
    pdm = node.rovers[ROVER]
    for name in names:
        key = keys.load_power(ROVER, name)
        msg = LoadPower(t_s=t_s, power_w=1.0, rail="12V", on=True, faults=[])
        node.on_load(pdm, msg, Sample(key, ROVER, ["load", name, "power"],
                                      msgspec.json.encode(msg), False))


def _rail_times(rt: _Runtime) -> list[float]:
    rail = keys.rail_state(ROVER, "5V_CH2")
    return [m.t_s for k, m in rt.published if k == rail and isinstance(m, RailState)]


def test_each_tick_of_loads_is_published_once_when_its_burst_is_whole() -> None:
    node, rt, names = _node()
    for t in (0.1, 0.2, 0.3):
        rt.t_s[ROVER] = t
        _loads(node, names, t)
        node.flush()
    assert _rail_times(rt) == [0.1, 0.2, 0.3]


def test_a_batch_holding_two_ticks_of_a_rover_publishes_both_each_with_its_own_time() -> None:
    """Found in the fleet test under a load average of 11: a power service behind by a tick
    folded two ticks of a rover's loads into one publication, and a tick had no rail state."""
    node, rt, names = _node()
    rt.t_s[ROVER] = 0.2  # the service has heard the clock's 0.2 already
    _loads(node, names, 0.1)
    _loads(node, names, 0.2)  # the same batch: no flush between
    node.flush()
    assert _rail_times(rt) == [0.1, 0.2]


def test_news_between_ticks_does_not_double_a_tick_already_out() -> None:
    node, rt, names = _node()
    rt.t_s[ROVER] = 0.1
    _loads(node, names, 0.1)
    node.flush()
    node.dirty.add(ROVER)  # a battery state changed the shedding between ticks
    rt.t_s[ROVER] = 0.2
    _loads(node, names, 0.2)
    node.flush()
    assert _rail_times(rt) == [0.1, 0.2]


def test_a_service_ahead_of_its_loads_stamps_their_tick_and_never_goes_back() -> None:
    """The rails of a tick of loads carry that tick's time, not a later one the service has
    heard from the clock meanwhile (a tick had no rail state, the next two); news already out
    at a later time is never followed by an earlier stamp in the same epoch (Found:
    tests/reliability/test_time_never_back.py saw 101.3 then 100.9 once the catch-up stamped
    the loads' tick as it was)."""
    node, rt, names = _node()
    rt.t_s[ROVER] = 0.4  # the clock's 0.4 heard before the loads of 0.3
    _loads(node, names, 0.3)
    node.flush()
    assert _rail_times(rt) == [0.3]
    node.apply_faults(node.rovers[ROVER], "5V_CH2", ())  # news between ticks: at 0.4
    rt.t_s[ROVER] = 0.5
    _loads(node, names, 0.35)  # a tick older than the news (its loads late): not back
    node.flush()
    assert _rail_times(rt) == [0.3, 0.4, 0.4]
    rt.epoch[ROVER], rt.t_s[ROVER] = 1, 0.0  # a reset: a new epoch starts again at 0
    _loads(node, names, 0.0)
    node.flush()
    assert _rail_times(rt)[-1] == 0.0


def _command(node: PowerNode, rail: str, **cmd: Any) -> None:
    key = keys.cmd_rail(ROVER, rail)
    msg = RailCommand(**cmd)
    node.on_command(node.rovers[ROVER], msg, Sample(key, ROVER, ["cmd", "rail", rail],
                                                    msgspec.json.encode(msg), False))


def test_a_reset_answered_a_tick_later_is_stamped_when_the_rail_came_back() -> None:
    """SPEC 13a: a command's event carries the time of the tick it was applied at. Found by an
    instructor: 'rail 5V: reset; the rail is now on' at 8.6 s, the rail on at 8.5 s, and the
    debrief had the fault settled before the action that settled it."""
    node, rt, names = _node()
    rail = keys.rail_state(ROVER, "5V_CH2")
    rt.t_s[ROVER] = 0.1
    _loads(node, names, 0.1)
    node.flush()
    _command(node, "5V_CH2", on=False)
    rt.t_s[ROVER] = 0.2
    _loads(node, names, 0.2)
    node.flush()
    _command(node, "5V_CH2", on=True, reset=True)  # held for the next tick's loads
    for t in (0.3, 0.4):
        rt.t_s[ROVER] = t
        _loads(node, names, t)
        node.flush()
    on_at = next(m.t_s for k, m in rt.published if k == rail and m.state == "on" and m.t_s > 0.1)
    said = [(m, t) for kind, m, t in rt.events if kind == "command" and "reset" in m]
    assert said == [("rail 5V_CH2: on=true, reset; the rail is now on", on_at)], (said, on_at)
    assert on_at == 0.3  # applied on the tick after it came, answered at 0.4
