"""2,000 bad payloads on every writable key: no crash, no internal error, no silent drop,
no change of state. (bench/reliability.py runs 10,000.)

Found: nesting a thousand deep raised RecursionError and an encoded surrogate
UnicodeDecodeError, each reported as a critical internal error with a traceback (302 of
10,000); duplicate JSON keys were accepted, the last winning; null was accepted on the
parameterless faults.
"""

from __future__ import annotations

import random
import re
from collections import Counter

import pytest

from common import keys
from common.config import load_rover
from common.connection import write
from testbed.fuzz import bad_payloads, writable_keys
from tests.harness import Probe, wait_for
from tests.reliability.conftest import MAPP, WITH_BRIDGE, R, events

pytestmark = pytest.mark.timeout(240)

PAYLOADS = 2000


def state(p: Probe) -> dict:
    """What a bad input must not change (the clock is paused: nothing else moves)."""
    rover = load_rover(MAPP)
    snap = {k: p.value(k) for k in
            [keys.battery_state(R), keys.umbilical_state(R), keys.clock(R)]
            + [keys.rail_state(R, x.name) for x in rover.rails]
            + [keys.solar_power(R, x.name) for x in rover.solar.panels]
            + [keys.load_power(R, x.name) for x in rover.loads]}
    snap.update({keys.radio_link(R, x.name): {f: v for f, v in p.value(keys.radio_link(R, x.name)).items()
                                               if f != "t_s"} for x in rover.radios})
    snap[keys.clock(R)] = {f: v for f, v in snap[keys.clock(R)].items() if f != "seq"}
    (faults,) = p.get_json(keys.faults(R))
    snap["faults"] = faults
    return snap


def fuzz(p: Probe, n: int, seed: int = 11) -> Counter:
    rng = random.Random(seed)
    targets = writable_keys(load_rover(MAPP))
    sent: Counter = Counter()
    for _ in range(n):
        key = rng.choice(targets)
        write(p.session, key, bad_payloads(key, rng))
        sent[key] += 1
    return sent


def test_2000_bad_payloads_are_each_rejected_and_change_nothing(whole_twin):
    p, twin = whole_twin
    p.put(keys.clock_control(R), {"paused": True})
    paused = p.wait_value(keys.clock(R), lambda c: c["paused"])
    for key in (keys.battery_state(R), keys.power_summary(R)):
        p.wait_value(key, lambda v: v["t_s"] == paused["t_s"])
    p.clear_history()
    before = state(p)
    sent = fuzz(p, PAYLOADS)

    def rejected() -> Counter:  # each service's own, not the journal's summaries of a flood
        got: Counter = Counter()
        for e in events(p, "rejected"):
            if "summarised" not in (e.get("params") or {}):
                got[e["key"]] += 1
        return got
    wait_for(lambda: rejected() == sent, 120,
             lambda: f"one rejection per payload: {sum(rejected().values())} of {PAYLOADS}, "
                     f"missing {sent - rejected()}, extra {rejected() - sent}", poll_s=0.2)
    assert not events(p, "internal_error"), events(p, "internal_error")[:3]
    jargon = [e["message"] for e in events(p, "rejected") if re.search(r"\$\.|`|(?<![\w])b'", e["message"])]
    assert not jargon, jargon[:3]  # plain words
    assert not [e for e in events(p) if e["kind"] not in ("rejected", "clock")], \
        "an accepted input, command or fault"
    assert all(proc.poll() is None for proc in twin.procs.values()), "a service died"
    p.wait_services(R, WITH_BRIDGE)
    assert state(p) == before
