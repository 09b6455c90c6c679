"""Bad input never stops a service and never changes state: each is rejected with an event.

Every kind of bad payload goes to every kind of key an instructor or dashboard may put on
(:data:`CASES`). Each case is refused at the decoding layer the services decode with (the
fault catalogue's key and parameters, the input Structs of the key's family), in words, and
by the tools' own check (:func:`common.writes.plan_write`) the same way: unit tests, all of
them. Through a live twin go one case per key (and each payload wrong everywhere, once) and
the cases only the twin can refuse (names of loads, rails, panels, radios and rovers it
alone knows; commands that decode but ask for nothing): each must come back as a rejection
event naming the key, in the decoders' words, with every service alive and the state as it
was.
"""

from __future__ import annotations

import pytest

from common import keys
from common.faults import parse_fault_key, parse_params
from common.messages import BARE_FIELD, BadInput, decode_input
from common.writes import plan_write
from tests.harness import ALL_SERVICES, Probe

pytestmark = pytest.mark.timeout(60)

R = "mapp-1"
P = f"lunaris/{R}"

# Keys that take parameters or an object, with payloads that are wrong only for them.
KEYS: dict[str, list[bytes]] = {
    f"{P}/fault/battery/heating": [b"-1", b"true", b""],
    f"{P}/fault/battery/capacity_loss": [b"1.5", b'{"fraction": "half"}'],
    f"{P}/fault/battery/resistance": [b"0.5"],
    f"{P}/fault/battery/disconnect": [b"5", b'{"now": true}'],
    f"{P}/fault/load/drive_motors/short": [b"0", b"-0.1"],
    f"{P}/fault/load/drive_motors/stuck": [b"-3", b""],
    f"{P}/fault/load/drive_motors/open": [b"1"],
    f"{P}/fault/rail/12V/fail": [b"1"],
    f"{P}/fault/solar/left/dust": [b"2", b"-0.5"],
    f"{P}/fault/solar/left/disconnect": [b"true"],
    f"{P}/fault/umbilical/disconnect": [b"1"],
    f"{P}/fault/radio/lander/failure": [b"0"],
    f"{P}/fault/radio/lander/degraded": [b"1.2", b"false"],
    f"{P}/input/sun_angle": [b"1000", b"true", b""],
    f"{P}/input/radio/lander/position": [b'{"distance_m": -2e9, "angle_deg": 0}', b"5",
                                          b'{"distance_m": 10}'],
    f"{P}/input/umbilical": [b"1", b'{"connected": "yes"}'],
    f"{P}/cmd/rail/12V": [b"{}", b'{"on": 1}', b'{"reset": "now"}'],
    f"{P}/clock/control": [b'{"time_scale": 0}', b'{"time_scale": -1}', b"{}",
                           b'{"paused": "yes"}'],
}
# Payloads that are wrong for every key.
EVERYWHERE = [b"{", b"NaN", b"Infinity", b"1e999", b'"text"', b"[1, 2]", b'{"bogus": 1}',
              b"\xff\xfe\x00"]
# Keys that are wrong whatever the payload.
UNKNOWN = [
    f"{P}/fault/load/no_such_load/short",
    f"{P}/fault/rail/no_such_rail/fail",
    f"{P}/fault/solar/no_such_panel/dust",
    f"{P}/fault/radio/no_such_radio/failure",
    f"{P}/fault/battery/melt",
    f"{P}/fault/wheel/flat",
    f"{P}/fault/battery/extra/heating",
    f"{P}/fault/load/short",
    f"{P}/input/radio/no_such_radio/position",
    f"{P}/input/gravity",
    f"{P}/cmd/rail/no_such_rail",
    f"{P}/cmd/rail/SOLAR",
    f"{P}/cmd/self_destruct",
    "lunaris/no-such-rover/fault/battery/heating",
    "lunaris/no-such-rover/input/sun_angle",
]

CASES = ([(k, p) for k, ps in KEYS.items() for p in ps]
         + [(k, p) for k in KEYS for p in EVERYWHERE]
         + [(k, b'{"fraction": 0.5}') for k in UNKNOWN])

# Refused by the twin alone: a well-formed key naming what this rover (or this twin) does not
# have, and commands that decode but ask for nothing. The decoders cannot know either.
TWIN_ONLY = {
    *((k, b'{"fraction": 0.5}') for k in UNKNOWN if "no_such" in k or "no-such" in k),
    (f"{P}/cmd/rail/SOLAR", b'{"fraction": 0.5}'),  # the solar rail exists but is not switched
    (f"{P}/cmd/rail/12V", b"{}"),
    (f"{P}/clock/control", b"{}"),
}
DECODED = [c for c in CASES if c not in TWIN_ONLY]


def decoders_say(key: str, payload: bytes) -> str | None:
    """Why the services' decoders refuse a put of ``payload`` on ``key`` (None: they accept
    it): the owner of a fault parses its key and parameters with the catalogue
    (:mod:`common.faults`), the owner of an input or command decodes the Struct of the key's
    family (:func:`common.messages.decode_input`), and the gatekeeper refuses a key of no
    family."""
    _, parts = keys.split(key)
    try:
        if parts[0] == "fault":
            parse_params(parse_fault_key(parts[1:]), payload)
            return None
        family = keys.family_of(parts)
        if family is None or family.direction != "in":
            return f"no such input or command {'/'.join(parts)!r}"
        decode_input(payload, family.payload, bare=BARE_FIELD.get(family.payload))
    except BadInput as exc:
        return str(exc)
    return None


# Through the twin: each key with a payload of its own the decoders refuse, each payload wrong
# everywhere once (on a key of its own), and every case only the twin can refuse.
LIVE = list(dict.fromkeys(
    [(k, next((p for p in ps if decoders_say(k, p)), ps[0])) for k, ps in KEYS.items()]
    + [(k, p) for k, p in zip(KEYS, EVERYWHERE, strict=False)]
    + sorted(TWIN_ONLY)))


def case_id(x: object) -> str:
    return x if isinstance(x, str) else repr(x)[:24]


# -- the decoding layer: every case --------------------------------------------------------------


@pytest.mark.unit
@pytest.mark.parametrize(("key", "payload"), DECODED, ids=case_id)
def test_the_decoders_refuse_it_in_words_and_so_do_the_tools(key, payload):
    reason = decoders_say(key, payload)
    assert reason is not None, "decoded as a valid write"
    assert len(reason) > 5 and "\n" not in reason and "Traceback" not in reason, reason
    rover, parts = keys.split(key)
    with pytest.raises(BadInput) as refused:  # lunaris rail / clock / input / fault, the console
        plan_write(rover, parts, payload)
    assert str(refused.value).startswith(reason), (str(refused.value), reason)


@pytest.mark.unit
def test_the_matrix_is_whole():
    """Every case is refused by the decoders or is the twin's alone: a key of the right shape
    (what it names, the twin alone knows) or a payload the decoders accept; every key has a
    live case, and so has every payload wrong everywhere."""
    assert TWIN_ONLY <= set(CASES) and len(DECODED) == len(CASES) - len(TWIN_ONLY)
    for key, payload in TWIN_ONLY:
        _, parts = keys.split(key)
        shaped = parse_fault_key(parts[1:]) if parts[0] == "fault" else keys.family_of(parts)
        assert shaped and (payload != b"{}" or decoders_say(key, payload) is None), key
    assert {k for k, _ in LIVE} >= set(KEYS) and {p for _, p in LIVE} >= set(EVERYWHERE)


# -- through a live twin: one case per key, and what only the twin can refuse -----------------


def snapshot(p: Probe) -> dict:
    """Everything a bad input could have changed, as last published."""
    def v(key):
        return p.value(key) or {}
    b = v(keys.battery_state(R))
    return {
        "battery": (b.get("capacity_j"), b.get("faults"), b.get("operational")),
        "rails": {r: v(keys.rail_state(R, r)).get("state")
                  for r in ("12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2", "SOLAR")},
        "load_faults": {ld: v(keys.load_power(R, ld)).get("faults")
                        for ld in ("drive_motors", "nav_camera")},
        "solar": {s: (v(keys.solar_power(R, s)).get("dust"), v(keys.solar_power(R, s)).get("power_w"),
                      v(keys.solar_power(R, s)).get("sun_angle_deg")) for s in ("left", "right")},
        "umbilical": v(keys.umbilical_state(R)).get("connected"),
        "radio": {k: v(keys.radio_link(R, "lander")).get(k) for k in ("in_range", "x_m", "y_m",
                                                                     "faults")},
        "clock": {k: v(keys.clock(R)).get(k) for k in ("time_scale", "paused")},
    }


def fresh_tick(p: Probe) -> None:
    """Wait until every per-tick publisher has published twice more (state settled)."""
    seq = p.value(keys.clock(R))["seq"]
    p.wait_value(keys.clock(R), lambda c: c["seq"] >= seq + 2)
    t = p.value(keys.clock(R))["t_s"]
    for key in (keys.battery_state(R), keys.solar_power(R, "left"), keys.rail_state(R, "12V")):
        p.wait_value(key, lambda v, t=t: v["t_s"] >= t)


@pytest.fixture
def probe(mapp_twin):
    p, _ = mapp_twin
    return p


@pytest.mark.parametrize(("key", "payload"), LIVE, ids=case_id)
def test_bad_input_is_rejected_and_changes_nothing(probe, key, payload):
    rover = key.split("/")[1]
    fresh_tick(probe)
    before = snapshot(probe)
    seen = len(probe.events(rover))
    probe.put(key, payload)
    rejection = probe.wait_event(rover, lambda e: e["kind"] == "rejected" and e["key"] == key
                                 and probe.events(rover).index(e) >= seen)
    assert rejection["severity"] == "warning" and rejection["message"].startswith("rejected: ")
    assert len(rejection["message"]) > len("rejected: ") + 5  # a reason, in words
    if (key, payload) not in TWIN_ONLY:  # the twin refuses it with the decoders' own words
        assert rejection["message"].startswith(f"rejected: {decoders_say(key, payload)}")
    fresh_tick(probe)
    assert snapshot(probe) == before
    accepted = [e for e in probe.events(rover)[seen:]
                if e["kind"] in ("fault_injected", "command", "clock")]
    assert accepted == []


def test_clearing_a_fault_that_is_not_active_is_rejected(probe):
    key = f"{P}/fault/battery/heating"
    seen = len(probe.events(R))
    probe.delete(key)
    e = probe.wait_event(R, lambda e: e["key"] == key and probe.events(R).index(e) >= seen)
    assert e["kind"] == "rejected" and "no active fault" in e["message"]


def test_every_service_is_alive_and_publishing_after_all_that(probe, mapp_twin):
    _, twin = mapp_twin
    assert all(proc.poll() is None for proc in twin.procs.values())
    probe.wait_services(R, ALL_SERVICES, timeout_s=5)
    t = probe.value(keys.battery_state(R))["t_s"]
    probe.wait_value(keys.battery_state(R), lambda b: b["t_s"] > t)
    (faults,) = probe.get_json(keys.faults(R))
    assert faults == []
    assert "internal_error" not in {e["kind"] for e in probe.events(R)}
