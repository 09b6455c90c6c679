"""Bad payloads for every key an instructor, scenario or dashboard may write (seeded, bounded).

Each payload is wrong for its key by construction, so the twin must answer every one with
a rejection event and change nothing: malformed or non-UTF-8 text, encoded surrogates, NaN
and infinity, overflowing numbers, duplicate keys, nesting a thousand deep, oversized,
wrong types, unknown fields, values out of range, deletes of what is not there.
"""

from __future__ import annotations

import json
import random

from common import keys
from common.config import Rover
from common.faults import CATALOGUE, NAMED_COMPONENTS, NoParams

__all__ = ["bad_payloads", "writable_keys"]


def writable_keys(rover: Rover) -> list[str]:
    r = rover.id
    names = {"load": [x.name for x in rover.loads], "rail": [x.name for x in rover.rails],
             "solar": [p.name for p in rover.solar.panels], "radio": [x.name for x in rover.radios]}
    out = [keys.input_sun_angle(r), keys.input_umbilical(r), keys.clock_control(r)]
    out += [keys.input_radio_position(r, x) for x in names["radio"]]
    out += [k(r, x) for x in names["solar"] for k in (keys.input_panel_sun_angle, keys.input_solar_dust)]
    out += [keys.cmd_rail(r, x) for x in names["rail"]]
    for component, kinds in CATALOGUE.items():
        targets = [f"{component}/{n}" for n in names[component]] if component in NAMED_COMPONENTS \
            else [component]
        out += [keys.fault(r, t, kind) for t in targets for kind in kinds]
    return out


def _parameterless(key: str) -> bool:
    _, parts = keys.split(key)
    if parts[0] != "fault":
        return False
    return issubclass(CATALOGUE[parts[1]][parts[-1]].params, NoParams)


def bad_payloads(key: str, rng: random.Random) -> bytes | None:
    """A payload wrong for ``key`` (None: a delete of a fault that is not active)."""
    _, parts = keys.split(key)
    choices = [
        lambda: b"{" + rng.randbytes(rng.randint(0, 20)).replace(b"}", b""),  # unclosed
        lambda: rng.choice([b"NaN", b"Infinity", b"-Infinity", b"1e999", b"-1e400"]),
        lambda: b'{"a": 1, "a": 2}',
        lambda: b"[" * 1000 + b"]" * 1000,
        lambda: b'{"x":' * 1000 + b"1" + b"}" * 1000,
        lambda: b'"\xed\xa0\x80"',  # a UTF-8 encoded surrogate
        lambda: b"\xff\xfe" + rng.randbytes(8),
        lambda: b'{"filler": "' + b"x" * 70_000 + b'"}',
        lambda: json.dumps(rng.choice(["text", [1, 2], {"zz_unknown": 1}, {"": None}])).encode(),
        lambda: json.dumps({"zz_" + str(rng.randint(0, 99)): rng.random()}).encode(),
        lambda: b"null",
    ]
    if parts[0] == "fault":
        if _parameterless(key):
            choices.append(lambda: json.dumps(rng.choice([1, True, {"on": 1}, [0]])).encode())
            choices.append(lambda: None)  # clearing what is not injected
        else:
            choices.append(lambda: json.dumps(rng.choice([-1e6, 2e9, "high"])).encode())
            choices.append(lambda: None)
    elif parts[:2] == ["input", "sun_angle"]:
        choices.append(lambda: json.dumps({"angle_deg": rng.choice([361, -1e9, "up"])}).encode())
    elif parts[:2] == ["input", "solar"] and parts[-1] == "dust":
        choices.append(lambda: json.dumps({"fraction": rng.choice([1.5, -0.1, "thick"])}).encode())
        choices.append(lambda: json.dumps(rng.choice([2, -1])).encode())
    elif parts[:2] == ["input", "solar"]:
        choices.append(lambda: json.dumps({"angle_deg": rng.choice([361, -1e9, "up"])}).encode())
    elif parts[:2] == ["input", "radio"]:
        choices.append(lambda: json.dumps({"distance_m": -2e9 - rng.random(), "angle_deg": 0}).encode())
        choices.append(lambda: b'{"distance_m": 10}')
    elif parts[0] == "cmd":
        choices.append(lambda: rng.choice([b"{}", b'{"on": 1}', b'{"reset": "now"}', b"5"]))
    elif parts[:2] == ["clock", "control"]:
        choices.append(lambda: rng.choice([b'{"time_scale": 0}', b'{"time_scale": -1}', b"{}",
                                           b'{"paused": "yes"}', b'{"time_scale": 1e9}']))
    elif parts[:2] == ["input", "umbilical"]:
        choices.append(lambda: rng.choice([b'{"connected": "yes"}', b"1", b"{}"]))
    return rng.choice(choices)()
