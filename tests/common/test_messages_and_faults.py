"""Strict input decoding and the fault catalogue: every bad input is refused with a reason."""

from __future__ import annotations

import msgspec
import pytest

from common.faults import (
    CATALOGUE,
    DERIVED,
    FAULT_CODES,
    RETIRED_CODES,
    CapacityLoss,
    Degraded,
    Disconnect,
    Dust,
    Fail,
    Failure,
    Fault,
    Heating,
    Open,
    Resistance,
    Short,
    Stuck,
    battery_fault_code,
    injected,
    kind_of,
    parse_fault_key,
    parse_params,
    supplies_device,
)
from common.messages import ActiveFault, BadInput, RadioPosition, RailCommand, SunAngle, decode_input


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


@pytest.mark.parametrize(("path", "payload", "typed", "params"), [
    ("battery/heating", b"25", Heating(heat_w=25.0), {"heat_w": 25.0}),
    ("battery/heating", b"0", Heating(heat_w=0.0), {"heat_w": 0.0}),  # changes nothing: a fault
    ("battery/capacity_loss", b'{"fraction": 0.25}', CapacityLoss(fraction=0.25), {"fraction": 0.25}),
    ("battery/resistance", b"1", Resistance(factor=1.0), {"factor": 1.0}),
    ("load/x/short", b"", Short(resistance_ohm=0.05), {"resistance_ohm": 0.05}),  # the default
    ("load/x/short", b"0.5", Short(resistance_ohm=0.5), {"resistance_ohm": 0.5}),
    ("load/x/open", b"", Open(), {}),
    ("load/x/stuck", b"7", Stuck(power_w=7.0), {"power_w": 7.0}),
    ("rail/x/fail", b"{}", Fail(), {}),
    ("solar/x/dust", b"0", Dust(fraction=0.0), {"fraction": 0.0}),
    ("solar/x/disconnect", b"", Disconnect(), {}),
    ("umbilical/disconnect", b"", Disconnect(), {}),
    ("radio/x/failure", b"", Failure(), {}),
    ("radio/x/degraded", b"0.5", Degraded(range_scale=0.5), {"range_scale": 0.5}),
    ("battery/disconnect", b"", Disconnect(), {}),
    ("battery/disconnect", b"{}", Disconnect(), {}),
])
def test_fault_params_are_decoded_once_into_their_kind_s_struct(path, payload, typed, params):
    """Decoded at the boundary into the kind's Struct (a member of the tagged union Fault);
    on the wire the parameters are the object without the tag, as before."""
    got = parse_params(parse_fault_key(path.split("/")), payload)
    assert got == typed and type(got) is type(typed) and kind_of(got) == path.split("/")[-1]
    assert msgspec.structs.asdict(got) == params
    assert msgspec.convert({"kind": kind_of(got), **params}, Fault) == typed  # the tagged union


def test_the_catalogue_names_each_kind_by_its_struct():
    structs = {spec.params for kinds in CATALOGUE.values() for spec in kinds.values()}
    assert structs == set(Fault.__args__)  # every kind of the union, and nothing else
    for kinds in CATALOGUE.values():
        for kind, spec in kinds.items():
            assert kind_of(spec.params) == kind


def test_injected_reads_a_record_of_faults_in_effect_typed():
    record = [
        ActiveFault("lunaris/r/fault/load/imu/open", {}, 1.0, "injected"),
        ActiveFault("lunaris/r/fault/load/imu/stuck", {"power_w": 2.0}, 2.0, "injected"),
        ActiveFault("lunaris/r/fault/load/cam/short", {"resistance_ohm": 1.0}, 3.0, "injected"),
        ActiveFault("lunaris/r/load/imu/over_current", {}, 4.0, "derived", "critical"),
    ]
    assert injected(record, "load", "imu") == [Open(), Stuck(power_w=2.0)]
    assert injected(record, "load", "cam") == [Short(resistance_ohm=1.0)]
    assert injected(record, "battery") == [] and injected([], "load", "imu") == []
    assert not supplies_device(True, injected(record, "load", "imu"))
    assert supplies_device(True, [Stuck(power_w=0.0)]) and not supplies_device(False, [])


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
    retired = [code for code, _ in RETIRED_CODES]
    assert len(set(codes + retired)) == len(codes) + len(retired) and 0 not in codes
    # the pack's own alarms only (SPEC §12b): every one has a code, no injected kind has one
    assert {name for name, _, _ in FAULT_CODES} == set(DERIVED["battery"])
    assert battery_fault_code([]) == 0
    assert battery_fault_code(["depleted"]) == 5
    assert battery_fault_code(["no_output"]) == 7
    assert battery_fault_code(["over_temperature", "depleted"]) == 5  # the most severe wins
    assert battery_fault_code(["heating", "over_temperature"]) == 1
    assert battery_fault_code(["heating", "resistance", "capacity_loss", "disconnect"]) == 0
