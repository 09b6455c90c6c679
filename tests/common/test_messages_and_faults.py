"""Strict input decoding and the fault catalogue: every bad input is refused with a reason."""

from __future__ import annotations

import re

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
    parameters,
    parse_fault_key,
    parse_params,
    supplies_device,
)
from common.messages import (
    ActiveFault,
    BadInput,
    ClockControl,
    DriveTraverse,
    PredictionRequest,
    RadioPosition,
    RailCommand,
    ScenarioMark,
    SunAngle,
    decode_input,
    decode_parameters,
    humane,
)


def test_bare_number_and_object_inputs():
    assert decode_input(b"60", SunAngle, bare="angle_deg").angle_deg == 60.0
    assert decode_input(b'{"angle_deg": -12.5}', SunAngle, bare="angle_deg").angle_deg == -12.5
    assert decode_input(b"true", RailCommand, bare="on").on is True
    assert decode_input(b'{"reset": true}', RailCommand).reset is True


@pytest.mark.parametrize(("payload", "typ", "reason"), [
    (b"{", SunAngle, "not valid JSON: a field name in double quotes is expected at character 2"),
    (b"NaN", SunAngle, "NaN is not a number (JSON has no NaN or infinity)"),
    (b'{"angle_deg": 1e999}', SunAngle, "the number 1e999 is too large (it overflows to infinity)"),
    (b'"sixty"', SunAngle, "'sixty' is not a number, true/false or a JSON object"),
    (b"maybe", SunAngle, "'maybe' is not a number, true/false or a JSON object"),
    (b'{"angle_deg": "60"}', SunAngle, "angle_deg must be a number (got '60')"),
    (b'{"angle_deg": 60, "x": 1}', SunAngle, "'x' is not a field of this input (it takes angle_deg)"),
    (b'{"angle_deg": 1000}', SunAngle, "angle_deg must be at most 360 (got 1000)"),
    (b'{"distance_m": -2e9, "angle_deg": 0}', RadioPosition,
     "distance_m must be at least -1000000000 (got -2000000000)"),
    (b'{"distance_m": 5}', RadioPosition, "angle_deg is missing"),
    (b"", SunAngle, "the payload is empty: give a JSON object or a bare value of angle_deg"),
    (b"[1, 2]", SunAngle, "[1, 2] is not a number, true/false or a JSON object"),
    (b'{"on": 1}', RailCommand, "on must be true or false (got 1)"),
    (b'{"angle_deg": 1, "angle_deg": 2}', SunAngle, "the field 'angle_deg' appears twice"),
    (b"\xff\xfe", SunAngle, "not text: byte 1 is not UTF-8"),
    (b"1" + b"0" * 5000, SunAngle, "has 5,001 digits: far too long for an input"),
    (b"-" + b"9" * 4301, SunAngle, "has 4,301 digits"),
    (b'{"angle_deg": ' + b"1" * 400 + b"}", SunAngle, "has 400 digits"),
    (b'"\\ud800"', SunAngle, "half of a character (a lone surrogate)"),
    (b'{"angle_deg": 1, "\\udfff": 2}', SunAngle, "half of a character (a lone surrogate)"),
    (b'{"angle_deg": ["\\ud800x"]}', SunAngle, "half of a character (a lone surrogate)"),
    (b"[" * 100 + b"]" * 100, SunAngle, "nested more than 32 levels deep"),
    (b'{"a": 1 2}', SunAngle, "not valid JSON: a comma is missing at character 9"),
])
def test_bad_inputs_are_refused_in_plain_words(payload, typ, reason):
    bare = "angle_deg" if typ is SunAngle else None
    with pytest.raises(BadInput) as err:
        decode_input(payload, typ, bare=bare)
    assert reason in str(err.value)
    assert_plain(str(err.value))


def assert_plain(reason: str) -> None:
    """No parser or validator jargon: no JSON paths, Python reprs, types in backticks."""
    for jargon in ("$.", "b'", 'b"', "`", "Traceback", "Expected", "Expecting", "NoneType",
                   "line 1 column", "(char "):
        assert jargon not in reason, (jargon, reason)


def test_a_surrogate_pair_is_one_character_and_accepted():
    mark = decode_input(b'{"scenario": "\\ud83d\\ude00", "what": "start", "message": "go"}',
                        ScenarioMark)
    assert mark.scenario == "\U0001f600"


@pytest.mark.parametrize(("payload", "typ", "reason"), [
    (b'{"waypoints": [{"x_m": 1e9, "y_m": 0, "z_m": 0}]}', DriveTraverse,
     "x_m of waypoint 1 must be at most 10000000 (got 1000000000)"),
    (b'{"waypoints": [{"x_m": 1, "y_m": 0}]}', DriveTraverse, "z_m is missing in waypoint 1"),
    (b'{"waypoints": 5}', DriveTraverse, "waypoints must be a list (got 5)"),
    (b'{"scenario": "s", "what": "later", "message": "m"}', ScenarioMark,
     "what must be one of 'end', 'expect', 'start', 'step' (got 'later')"),
    (b'{"scenario": "", "what": "start", "message": "m"}', ScenarioMark, "scenario must not be empty"),
    (b'{"time_scale": 0}', ClockControl, "time_scale must be above 0 (got 0)"),
    (b'{"time_scale": "fast"}', ClockControl, "time_scale must be a number (got 'fast')"),
    (b"maybe", RailCommand, "'maybe' is not a JSON object"),
])
def test_nested_and_enumerated_fields_are_named_plainly(payload, typ, reason):
    with pytest.raises(BadInput) as err:
        decode_input(payload, typ)
    assert str(err.value) == reason
    assert_plain(reason)


@pytest.mark.parametrize(("text", "reason"), [
    ("hours=500", "hours must be at most 168 (got 500)"),
    ("hours=x", "hours must be a number (got 'x')"),
    ("samples=2.5", "samples must be a whole number (got 2.5)"),
    ("zz=1", "'zz' is not a field of this input (it takes hours, samples, seed, timeout_s)"),
    ("hours=1;hours=2", "hours is given twice"),
])
def test_query_parameters_are_refused_in_plain_words(text, reason):
    with pytest.raises(BadInput) as err:
        decode_parameters(text, PredictionRequest)
    assert str(err.value) == reason
    assert_plain(reason)


def test_humane_keeps_plain_words_and_reads_msgspec_messages():
    assert humane("Expected `float` <= 1.0 - at `$.fraction`") == "fraction must be at most 1"
    assert humane("Expected `float` <= 1.0 - at `$.fraction`", {"fraction": 30}) == \
        "fraction must be at most 1 (got 30)"
    assert humane("fraction must be at most 1 (got 30)") == "fraction must be at most 1 (got 30)"
    # the value not at hand (a forged telemetry payload, []) is not said to be null
    assert humane("Expected `object`, got `array`") == "the input must be a JSON object, not a list"
    assert humane("Expected `object`, got `null`", None) == "the input must be a JSON object (got null)"


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


# Words an instructor does not use: model symbols, field names, JSON paths.
_TECHNICAL = re.compile(r"[_^$={}]|V_rail|\bR\b")


def test_the_catalogue_speaks_plainly_of_every_kind_and_parameter():
    """Issue 26.5: a plain name and effect per kind, a label, unit and hint per parameter, in
    words without model symbols or field names; the limits are the ones the decoder checks."""
    for component, kinds in CATALOGUE.items():
        for kind, spec in kinds.items():
            where = f"{component}/{kind}"
            assert spec.name and spec.name[0].isupper() and not _TECHNICAL.search(spec.name), where
            assert spec.effect and not _TECHNICAL.search(spec.effect), where
            fields = [f.name for f in msgspec.structs.fields(spec.params)]
            params = parameters(spec.params)
            assert [p.name for p in params] == fields, where
            for p in params:
                assert p.label and p.unit and p.hint, f"{where}/{p.name}"
                assert not _TECHNICAL.search(p.label + p.hint), f"{where}/{p.name}"
    assert CATALOGUE["load"]["short"][3:] == (
        "Short circuit", "draws far more than it should: normally trips its rail")
    heat, = parameters(Heating)
    assert heat == ("heat_w", "Extra heat", "W", "what the failed thermal control adds, 0 or more",
                    {"ge": 0.0, "le": 1e9}, None)
    short, = parameters(Short)
    assert (short.unit, short.limits, short.default) == ("Ω", {"gt": 0.0, "le": 1e9}, 0.05)
    assert parameters(Disconnect) == []
    with pytest.raises(BadInput, match="heat_w"):  # the words change nothing of the checks
        parse_params(parse_fault_key(["battery", "heating"]), b"-1")


def test_the_console_and_the_cli_show_the_plain_catalogue():
    from lunaris.console.api import catalogue
    from lunaris.fault import catalogue_help
    short = catalogue()["components"]["load"]["kinds"]["short"]
    assert (short["name"], short["effect"]) == ("Short circuit", CATALOGUE["load"]["short"].effect)
    assert short["params"] == [{"name": "resistance_ohm", "type": "number", "gt": 0.0, "le": 1e9,
                                "default": 0.05, "label": "Resistance of the short", "unit": "Ω",
                                "hint": parameters(Short)[0].hint}]
    text = catalogue_help()
    assert "  battery heating VALUE\n      Overheating: extra heat in the pack" in text
    assert "VALUE: Extra heat [W] - what the failed thermal control adds" in text
    assert "  load/<name> short [VALUE]\n      Short circuit: draws far more" in text
    assert all(len(line) <= 79 for line in text.splitlines())


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
    ("battery/disconnect", b"1", "battery disconnect takes no parameters (got '1')"),
    ("battery/disconnect", b"\xff\xfecb'", "takes no parameters (got 5 bytes that are not text)"),
    ("solar/left/dust", b"1.5", "fraction must be at most 1 (got 1.5)"),
    ("battery/resistance", b"0.5", "factor must be at least 1 (got 0.5)"),
    ("load/x/short", b"0", "resistance_ohm must be above 0 (got 0)"),
    ("battery/heating", b"-1", "heat_w must be at least 0 (got -1)"),
    ("battery/heating", b'{"heat": 5}', "'heat' is not a field of this input (it takes heat_w)"),
    ("battery/heating", b"", "the payload is empty"),
    ("radio/lander/degraded", b"true", "range_scale must be a number (got true)"),
])
def test_bad_fault_params(path, payload, reason):
    with pytest.raises(BadInput) as err:
        parse_params(parse_fault_key(path.split("/")), payload)
    assert reason in str(err.value)
    assert_plain(str(err.value))


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


def test_a_trainee_name_refused_names_every_character_it_cannot_have():
    """Found by an instructor: "Ana <3;/x>" was refused naming '<', '3'... the first three
    only, and ';' never."""
    from common.messages import trainee_problem

    assert trainee_problem("Ana Silva-O'Neil & co.") is None and trainee_problem("Zoë 2") is None
    said = trainee_problem("Ana <b>;/x\x07")
    assert said is not None and said.endswith("this one has '<', '>', ';', '/', a control character")
