"""Strict input decoding and the fault catalogue: every bad input is refused with a reason."""

from __future__ import annotations

import msgspec
import pytest

from common.faults import FAULT_CODES, battery_fault_code, parse_fault_key, parse_params
from common.messages import BadInput, RadioPosition, RailCommand, SunAngle, decode_input


def test_bare_number_and_object_inputs():
    assert decode_input(b"60", SunAngle, bare="angle_deg").angle_deg == 60.0
    assert decode_input(b'{"angle_deg": -12.5}', SunAngle, bare="angle_deg").angle_deg == -12.5
    assert decode_input(b"true", RailCommand, bare="on").on is True
    assert decode_input(b'{"reset": true}', RailCommand).reset is True


@pytest.mark.parametrize(("payload", "typ", "reason"), [
    (b"{", SunAngle, "malformed JSON"),
    (b"NaN", SunAngle, "malformed JSON"),
    (b'{"angle_deg": 1e999}', SunAngle, "Number out of range"),
    (b'"sixty"', SunAngle, "expected a JSON object"),
    (b'{"angle_deg": "60"}', SunAngle, "Expected `float`, got `str`"),
    (b'{"angle_deg": 60, "x": 1}', SunAngle, "unknown field `x`"),
    (b'{"angle_deg": 1000}', SunAngle, "Expected `float` <= 360"),
    (b'{"distance_m": -2e9, "angle_deg": 0}', RadioPosition, ">= -1000000000"),
    (b'{"distance_m": 5}', RadioPosition, "missing required field `angle_deg`"),
    (b"", SunAngle, "empty payload"),
    (b"[1, 2]", SunAngle, "expected a JSON object"),
    (b'{"on": 1}', RailCommand, "Expected `bool | null`, got `int`"),
])
def test_bad_inputs_are_refused_with_a_reason(payload, typ, reason):
    bare = "angle_deg" if typ is SunAngle else None
    with pytest.raises(BadInput, match=reason.replace("|", r"\|").replace("(", r"\(")):
        decode_input(payload, typ, bare=bare)


@pytest.mark.parametrize(("parts", "expected"), [
    (["battery", "heating"], ("battery", None, "heating")),
    (["load", "nav_camera", "short"], ("load", "nav_camera", "short")),
    (["umbilical", "disconnect"], ("umbilical", None, "disconnect")),
    (["radio", "lander", "degraded"], ("radio", "lander", "degraded")),
])
def test_fault_keys_parse(parts, expected):
    assert tuple(parse_fault_key(parts)) == expected


@pytest.mark.parametrize(("parts", "reason"), [
    (["wheel", "flat"], "unknown component 'wheel'"),
    (["battery", "melt"], "unknown battery fault kind 'melt'"),
    (["load", "short"], "fault/load/<name>/<kind>"),
    (["battery", "x", "heating"], "fault/battery/<kind>"),
    ([], "no component"),
])
def test_bad_fault_keys(parts, reason):
    with pytest.raises(BadInput, match=reason):
        parse_fault_key(parts)


@pytest.mark.parametrize(("path", "payload", "params"), [
    ("battery/heating", b"25", {"heat_w": 25.0}),
    ("battery/capacity_loss", b'{"fraction": 0.25}', {"fraction": 0.25}),
    ("load/x/short", b"", {"resistance_ohm": 0.05}),     # the default
    ("load/x/short", b"0.5", {"resistance_ohm": 0.5}),
    ("battery/disconnect", b"", {}),
    ("battery/disconnect", b"{}", {}),
])
def test_fault_params(path, payload, params):
    assert msgspec.structs.asdict(parse_params(parse_fault_key(path.split("/")), payload)) == params


@pytest.mark.parametrize(("path", "payload", "reason"), [
    ("battery/disconnect", b"1", "takes no parameters"),
    ("solar/left/dust", b"1.5", "<= 1.0"),
    ("battery/resistance", b"0.5", ">= 1.0"),
    ("load/x/short", b"0", "> 0.0"),
    ("battery/heating", b"-1", ">= 0.0"),
    ("battery/heating", b'{"heat": 5}', "unknown field `heat`"),
    ("battery/heating", b"", "empty payload"),
    ("radio/lander/degraded", b"true", "Expected `float`, got `bool`"),
])
def test_bad_fault_params(path, payload, reason):
    with pytest.raises(BadInput, match=reason):
        parse_params(parse_fault_key(path.split("/")), payload)


def test_fault_code_table():
    codes = [code for _, code, _ in FAULT_CODES]
    assert len(set(codes)) == len(codes) and 0 not in codes
    assert battery_fault_code([]) == 0
    assert battery_fault_code(["depleted"]) == 5
    assert battery_fault_code(["over_temperature", "depleted"]) == 5  # the most severe wins
    assert battery_fault_code(["heating", "over_temperature"]) == 1
