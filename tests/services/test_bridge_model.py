"""The bridge model: mapping validation, values, ROS 2 messages read back by an independent
decoder (tests/rosmsg.py), and rmw_zenoh names checked against published facts."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from common.config import ConfigError, load_rover
from common.messages import (
    ActiveFault,
    BadInput,
    BatteryState,
    DriveState,
    LoadPower,
    PowerSummary,
    RailState,
)
from services.bridge import bindings as bd
from services.bridge import cdr, convert, rmw_zenoh
from services.bridge import mapping as mp
from tests import rosmsg
from tests.harness import static_rover

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "bridge" / "default.yaml"
MAPP = load_rover(ROOT / "config" / "rovers" / "mapp.yaml")
LTV = load_rover(ROOT / "config" / "rovers" / "ltv.yaml")

# Published facts: std_msgs/msg/Bool's REP-2016 hash, and rmw_zenoh's design document
# (docs/design.md) examples of a topic key and of liveliness tokens.
BOOL_HASH = "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def mapping(text: str) -> mp.MappingFile:
    return mp.parse_mapping(text, source="test.yaml")


def one(extra: str = "", **fields: str) -> str:
    """A mapping file of one mapping; ``fields`` override the defaults."""
    base = {"topic": "/x", "type": "std_msgs/msg/Int32", "key": "lunaris/{rover}/battery/state",
            "field": "voltage_v", "scale": "1000"}
    base.update(fields)
    lines = "".join(f"    {k}: {v}\n" for k, v in base.items() if v is not None)
    return f"{extra}mappings:\n  -\n{lines}"


def battery_state(**kw) -> BatteryState:
    base = dict(t_s=1.0, energy_j=2.65e5, capacity_j=5.3e5, soc=0.5, ocv_v=15.4, voltage_v=15.2,
                current_a=3.0, power_w=45.6, temperature_c=25.0, operational=True, fault_code=0,
                faults=[], time_to_empty_s=1000.0)
    base.update(kw)
    return BatteryState(**base)


# -- the mapping file -----------------------------------------------------------------------------


def test_default_mapping_covers_what_the_dashboard_uses():
    mf = mp.load_mapping(DEFAULT)
    bindings = bd.expand(mf, [bd.rover_names(MAPP)])
    out = {b.topic: b for b in bindings if b.mapping.direction == "out"}
    inbound = {b.topic: b for b in bindings if b.mapping.direction == "in"}
    assert out["/final_comms_radio_bool"].mapping.type == "std_msgs/msg/Bool"
    assert out["/final_comms_radio_bool"].key == "lunaris/mapp-1/radio/lander/link"
    assert inbound["/curr_to_receiving_radio_m"].key == "lunaris/mapp-1/input/radio/lander/position"
    assert inbound["/curr_to_receiving_radio_m"].mapping.fields == ["distance_m", "angle_deg"]
    assert out["/battery_state"].mapping.type == "sensor_msgs/msg/BatteryState"
    assert out["/diagnostics"].mapping.type == "diagnostic_msgs/msg/DiagnosticArray"
    # what the DiagnosticArray is made of: every owner's faults in effect, not the journal
    assert out["/diagnostics"].mapping.key == "lunaris/{rover}/faults/active/*"
    for load in MAPP.loads:
        assert out[f"/load_{load.name}_power_w"].key == f"lunaris/mapp-1/load/{load.name}/power"
    pdm = {t: b for t, b in out.items() if b.mapping.group == "pdm"}
    assert {"/pdm/sys_bus_voltage_mv", "/pdm/battery_voltage_mv", "/pdm/battery_current_ma",
            "/pdm/battery_power_mw"} <= set(pdm)
    for rail in [r.name for r in MAPP.rails] + [MAPP.solar.rail.name]:
        for value, unit in (("voltage", "mv"), ("current", "ma"), ("power", "mw"),
                            ("current_limit", "ma")):
            b = pdm[f"/pdm/rail_{rail}_{value}_{unit}"]
            assert b.key == f"lunaris/mapp-1/rail/{rail}/state"
            assert (b.mapping.type, b.mapping.scale) == ("std_msgs/msg/Int32", 1000.0)
    assert {b.mapping.unit for b in pdm.values()} == {"mV", "mA", "mW"}


def test_the_diagnostics_converter_reads_the_faults_in_effect_and_its_old_spelling_still_works():
    for key in ("lunaris/{rover}/faults/active/*", "lunaris/{rover}/event"):
        mf = mapping(one(topic="/d", type="diagnostic_msgs/msg/DiagnosticArray", key=f"'{key}'",
                         field=None, scale=None, convert="diagnostics"))
        (b,) = bd.expand(mf, [bd.rover_names(MAPP)])
        assert (b.topic, b.item) == ("/d", None)
    with pytest.raises(ConfigError, match=r"the diagnostics converter reads "
                                          r"lunaris/\{rover\}/faults/active/\*"):
        mapping(one(topic="/d", type="diagnostic_msgs/msg/DiagnosticArray",
                    key="'lunaris/{rover}/faults/active/battery'", field=None, scale=None,
                    convert="diagnostics"))


def test_a_fleet_keeps_the_plain_topics_one_ros_domain_per_rover():
    mf = mp.load_mapping(DEFAULT)
    fleet = [MAPP.id, LTV.id]
    bindings = bd.expand(mf, [bd.rover_names(MAPP), bd.rover_names(LTV)])
    # the same topic for both rovers, each in its own domain: no renaming
    radio = {b.rover: b for b in bindings if b.topic == "/final_comms_radio_bool"}
    assert set(radio) == set(fleet)
    opts = mf.bridge
    keys_of = {(b.rover, f): bd.zenoh_key(b, opts, f) for b in radio.values()
               for f in ("ros2dds", "json", "rmw_zenoh")}
    assert keys_of[("mapp-1", "ros2dds")] == "mapp_1/final_comms_radio_bool"  # bridge namespace
    assert keys_of[("ltv-1", "json")] == "json/ltv_1/final_comms_radio_bool"
    assert keys_of[("mapp-1", "rmw_zenoh")].startswith("0/final_comms_radio_bool/")
    assert keys_of[("ltv-1", "rmw_zenoh")].startswith("1/final_comms_radio_bool/")
    # a shard serving only the LTV still knows its place in the fleet
    shard = bd.expand(mf, [bd.rover_names(LTV)], fleet=fleet)
    ltv = next(b for b in shard if b.topic == "/final_comms_radio_bool")
    assert bd.zenoh_key(ltv, opts, "rmw_zenoh").startswith("1/") and ltv.fleet
    # one rover alone: the plain keys
    solo = next(b for b in bd.expand(mf, [bd.rover_names(MAPP)]) if b.topic == "/battery_state")
    assert bd.zenoh_key(solo, opts, "ros2dds") == "battery_state"
    # rovers told to share a domain collide unless the mapping asks for a prefix
    shared = mapping(one("bridge:\n  rover_domains: {mapp-1: 3, ltv-1: 3}\n"))
    with pytest.raises(ConfigError, match="in the same ROS 2 domain"):
        bd.expand(shared, [bd.rover_names(MAPP), bd.rover_names(LTV)])
    prefixed = mapping(one("bridge:\n  rover_domains: {mapp-1: 3, ltv-1: 3}\n"
                           "  fleet_topic_prefix: /{rover}\n"))
    both = bd.expand(prefixed, [bd.rover_names(MAPP), bd.rover_names(LTV)])
    assert {b.topic for b in both} == {"/mapp_1/x", "/ltv_1/x"}
    assert {bd.domain_of(prefixed.bridge, 0, b.rover, b.place) for b in both} == {3}
    with pytest.raises(ConfigError, match="not in the fleet"):
        bd.expand(mf, [bd.rover_names(MAPP)], fleet=[LTV.id])


def test_the_default_mapping_works_for_a_rover_with_other_names():
    other = MAPP.model_copy() if hasattr(MAPP, "model_copy") else None
    assert other is None  # Structs, not pydantic: build the names directly
    names = bd.RoverNames("base-rover", load=("cam",), rail=("MAIN", "SUN"),
                          radio=("base_station", "relay"), panel=("wing",))
    mf = mp.load_mapping(DEFAULT)
    bindings = {b.topic: b for b in bd.expand(mf, [names])}
    assert bindings["/final_comms_radio_bool"].key == "lunaris/base-rover/radio/base_station/link"
    assert bindings["/curr_to_receiving_radio_m"].key == (
        "lunaris/base-rover/input/radio/base_station/position")
    assert bindings["/pdm/rail_MAIN_voltage_mv"].key == "lunaris/base-rover/rail/MAIN/state"
    assert bindings["/solar_wing_dust"].key == "lunaris/base-rover/input/solar/wing/dust"
    assert bindings["/solar_wing_sun_angle_deg"].key == "lunaris/base-rover/input/solar/wing/sun_angle"
    # without radios: no radio topic at all
    bare = bd.expand(mf, [names._replace(radio=())])
    assert not [b for b in bare if "radio" in b.topic]
    # otherwise: error (the default) names the missing radio; skip leaves it out
    strict = mapping(one(topic="/link", type="std_msgs/msg/Bool",
                         key="lunaris/{rover}/radio/lander/link", field="in_range", scale=None))
    with pytest.raises(ConfigError, match="rover base-rover has no radio 'lander'"):
        bd.expand(strict, [names])
    skip = mapping(one(topic="/link", type="std_msgs/msg/Bool", otherwise="skip",
                       key="lunaris/{rover}/radio/lander/link", field="in_range", scale=None))
    assert bd.expand(skip, [names]) == []


def test_rates_joint_states_and_their_problems():
    mf = mapping(one(rate_hz="2"))
    assert mf.mappings[0].rate_hz == 2.0
    js = mapping(one(topic="/bus", type="sensor_msgs/msg/JointState", field=None, scale=None,
                     key="lunaris/{rover}/power/summary",
                     fields="[bus_voltage_v, generation_w]", joint_names="[bus, sun]"))
    msg = convert.out_message(js.mappings[0], PowerSummary(
        t_s=1.0, load_power_w=40.0, bus_power_w=44.0, generation_w=45.0,
        net_battery_power_w=-1.0, bus_voltage_v=16.5), stamp_ns=2_500_000_000)
    assert msg["name"] == ["bus", "sun"] and msg["position"] == [16.5, 45.0]
    assert msg["header"]["stamp"] == {"sec": 2, "nanosec": 500_000_000}
    back = rosmsg.decode("sensor_msgs/msg/JointState",
                         cdr.encode_cdr("sensor_msgs/msg/JointState", msg))
    assert list(back.name) == ["bus", "sun"] and list(back.position) == [16.5, 45.0]
    for fields, want in (
        ({"rate_hz": "0"}, "mappings[0].rate_hz: must be a number > 0, got 0"),
        ({"otherwise": "maybe"}, "mappings[0].otherwise: expected error, first, skip"),
        ({"otherwise": "first"}, "mappings[0].otherwise: only for a key that names one component"),
        ({"joint_names": "[a]"}, "mappings[0].joint_names: only sensor_msgs/msg/JointState"),
        ({"type": "sensor_msgs/msg/JointState", "field": None, "scale": None,
          "fields": "[voltage_v]", "joint_names": "[a, b]"}, "mappings[0].joint_names: 2 names for 1"),
        ({"direction": "in", "key": "lunaris/{rover}/input/sun_angle", "field": "angle_deg",
          "type": "std_msgs/msg/Float64", "scale": None, "rate_hz": "1"},
         "mappings[0].rate_hz: only outbound topics have a rate"),
    ):
        with pytest.raises(ConfigError) as err:
            mapping(one(**fields))
        assert any(p.startswith(want) for p in err.value.problems), (want, err.value.problems)
    with pytest.raises(ConfigError) as err:
        mapping(one("bridge:\n  rover_domains: {a: 300}\n  outputs: {ros2: {enabled: true, "
                    "domain_id: -1, node: 1x, namespace: bad}}\n"))
    text = "\n".join(err.value.problems)
    for want in ("bridge.rover_domains.a: expected 0..232, got 300",
                 "bridge.outputs.ros2.domain_id: expected 0..232, got -1",
                 "bridge.outputs.ros2.node: '1x' is not a ROS 2 node name",
                 "bridge.outputs.ros2.namespace: 'bad' must start with '/'"):
        assert want in text, text


def test_only_flags_states_counts_and_faults_are_discrete():
    from services.bridge.service import _discrete_fields

    assert _discrete_fields(RailState) == ("state", "reason")
    assert _discrete_fields(BatteryState) == ("operational", "fault_code", "faults")
    assert _discrete_fields(PowerSummary) == ()
    assert _discrete_fields(LoadPower) == ("rail", "on", "faults")


def test_every_problem_of_a_bad_mapping_is_named():
    text = """
bridge:
  ros_distro: iron
  fleet_namespace: /fleet
  outputs: {json: {enabled: true, prefix: ""}}
mappings:
  - {topic: no_slash, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: voltage_v}
  - {topic: /a, type: std_msgs/msg/Nope, key: "lunaris/{rover}/battery/state", field: voltage_v}
  - {topic: /b, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: volts}
  - {topic: /c, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/oops", field: voltage_v}
  - {topic: /d, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: voltage_v,
     scale: 0}
  - {topic: /e, type: std_msgs/msg/Bool, key: "lunaris/{rover}/battery/state", field: voltage_v}
  - {topic: /f, type: std_msgs/msg/Int32, key: "lunaris/{rover}/rail/{rail}/state",
     field: voltage_v}
  - {topic: /g, type: sensor_msgs/msg/BatteryState, key: "lunaris/{rover}/power/summary",
     convert: battery_state, scale: 2}
  - {topic: /h, type: std_msgs/msg/Int32, key: "lunaris/{rover}/input/sun_angle",
     field: angle_deg}
  - {topic: /i, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: voltage_v,
     integer: false}
  - {topic: /j, type: std_msgs/msg/Float64MultiArray, key: "lunaris/{rover}/input/radio/{radio}/position",
     direction: in, fields: [distance_m]}
  - {topic: /k, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: voltage_v,
     colour: red}
  - {topic: /b, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", field: voltage_v}
  - {topic: /l, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", convert: battery_state}
  - {topic: /m, type: sensor_msgs/msg/BatteryState, key: "lunaris/{rover}/battery/state"}
  - {topic: /n, type: std_msgs/msg/Int32, key: "lunaris/{rover}/battery/state", convert: magic}
"""
    with pytest.raises(ConfigError) as err:
        mapping(text)
    problems = err.value.problems
    expected = [
        "bridge.ros_distro: expected jazzy or humble, got 'iron'",
        "bridge.fleet_namespace: must contain {rover}",
        "bridge.outputs.json.prefix: the json and ros2dds outputs would share",
        "mappings[0].topic: 'no_slash' must start with '/'",
        "mappings[1].type: unknown ROS 2 message type 'std_msgs/msg/Nope'",
        "mappings[2].field: BatteryState has no field 'volts'",
        "mappings[3].key: 'lunaris/{rover}/battery/oops' is not a twin key",
        "mappings[4].scale: must be a finite non-zero number, got 0",
        "mappings[5].field: BatteryState.voltage_v is not a boolean",
        "mappings[6].topic: must contain {rail}",
        "mappings[7].key: the battery_state converter reads lunaris/{rover}/battery/state",
        "mappings[7].scale: not used with convert",
        "mappings[8].direction: lunaris/{rover}/input/sun_angle is an input, so the direction is in",
        "mappings[9].integer: std_msgs/msg/Int32 holds integers",
        "mappings[10].fields: the input RadioPosition needs angle_deg",
        "mappings[10].topic: must contain {radio}",
        "mappings[11].colour: unknown field",
        "mappings[12].topic: /b is already mapped by mappings[2]",
        "mappings[13].type: the battery_state converter makes sensor_msgs/msg/BatteryState, not "
        "std_msgs/msg/Int32",
        "mappings[14].type: sensor_msgs/msg/BatteryState needs a converter",
        "mappings[15].convert: unknown converter 'magic' (known: battery_state, diagnostics, odometry)",
    ]
    for want in expected:
        assert any(p.startswith(want) for p in problems), f"{want!r} not in {problems}"
    assert str(err.value).startswith("test.yaml: ")


def test_mapping_files_are_found_from_anywhere(tmp_path, monkeypatch):
    from services.bridge.mapping import DEFAULT_MAPPING, resolve_mapping

    assert resolve_mapping(None) == DEFAULT == DEFAULT_MAPPING
    monkeypatch.chdir(tmp_path)
    assert resolve_mapping("config/bridge/default.yaml") == DEFAULT  # relative to the repository
    (tmp_path / "mine.yaml").write_text("")
    assert resolve_mapping("mine.yaml") == Path("mine.yaml")  # relative to the working directory
    with pytest.raises(ConfigError, match="cannot read file"):
        mp.load_mapping(tmp_path / "missing.yaml")
    # An installed package run from a folder holding config/ (the container image) uses it.
    (tmp_path / "config/bridge").mkdir(parents=True)
    (tmp_path / "config/bridge/default.yaml").write_text("")
    assert resolve_mapping(None) == tmp_path / "config/bridge/default.yaml"


def test_outputs_and_distro_options():
    mf = mapping(one('bridge:\n  ros_distro: humble\n  outputs: {ros2dds: {enabled: false},'
                     ' json: {prefix: ""}, rmw_zenoh: {domain_id: 7, node: dash}}\n'))
    out = mf.bridge.outputs
    assert (out.ros2dds.enabled, out.json.prefix, out.rmw_zenoh.domain_id) == (False, "", 7)
    with pytest.raises(ConfigError) as err:
        mapping(one("bridge:\n  outputs: {ros2dds: {enabled: false}, json: {enabled: false},"
                    " rmw_zenoh: {enabled: false, domain_id: 300, node: 9lives}}\n"))
    text = "\n".join(err.value.problems)
    assert "bridge.outputs: every output is disabled" in text
    assert "bridge.outputs.rmw_zenoh.domain_id: expected 0..232, got 300" in text
    assert "bridge.outputs.rmw_zenoh.node: '9lives' is not a ROS 2 node name" in text


def test_expansion_names_components_a_rover_lacks_and_bad_ros_names():
    mf = mapping("""
mappings:
  - {topic: /link, type: std_msgs/msg/Bool, key: "lunaris/{rover}/radio/hls_relay/link", field: in_range}
  - {topic: "/{rail}_mv", type: std_msgs/msg/Int32, key: "lunaris/{rover}/rail/{rail}/state",
     field: voltage_v, scale: 1000}
""")
    with pytest.raises(ConfigError) as err:
        bd.expand(mf, [bd.rover_names(MAPP)], source="m.yaml")
    text = "\n".join(err.value.problems)
    assert "rover mapp-1 has no radio 'hls_relay' (radios: lander)" in text
    assert "'/12V_mv' (rover mapp-1) is not a ROS 2 name" in text
    link_only = mp.MappingFile(mappings=mf.mappings[:1])
    assert bd.expand(link_only, [bd.rover_names(LTV)])[0].key == "lunaris/ltv-1/radio/hls_relay/link"


def test_placeholders_in_topics_become_ros_safe():
    assert mp.ros_name("mapp-1") == "mapp_1"
    assert mp.ros_name("cam.left-2") == "cam_left_2"
    mf = mapping("""
bridge: {topic_prefix: "/{rover}"}
mappings:
  - {topic: "/load/{load}", type: std_msgs/msg/Float32, key: "lunaris/{rover}/load/{load}/power",
     field: power_w, label: "{load} on {rover}"}
""")
    b = bd.expand(mf, [bd.rover_names(MAPP)])[0]
    assert (b.topic, b.label) == ("/mapp_1/load/drive_motors", "drive_motors on mapp-1")


# -- values ------------------------------------------------------------------------------------------


def test_scale_rounds_half_away_from_zero_and_clamps():
    m = mapping(one()).mappings[0]
    rail = RailState(t_s=0, voltage_v=12.0, current_a=0.0, power_w=0.0, current_limit_a=None,
                     state="on")
    assert convert.out_value(m, rail) == 12000
    for volts, mv in ((0.0125, 13), (-0.0125, -13), (0.0124, 12), (2.5e-4, 0), (5e-4, 1),
                      (1e9, 2**31 - 1), (-1e9, -(2**31))):
        assert convert.out_value(m, battery_state(voltage_v=volts)) == mv, volts
    assert isinstance(convert.out_value(m, battery_state()), int)


def test_a_null_field_publishes_nothing_unless_a_default_is_given():
    rail = RailState(t_s=0, voltage_v=18.0, current_a=1.0, power_w=18.0, current_limit_a=None,
                     state="on")
    plain = mapping(one(key="lunaris/{rover}/rail/SOLAR/state", field="current_limit_a")).mappings[0]
    assert convert.out_message(plain, rail) is None
    with_default = mapping(one(key="lunaris/{rover}/rail/SOLAR/state", field="current_limit_a",
                               default="-1")).mappings[0]
    assert convert.out_message(with_default, rail) == {"data": -1000}


def test_float_and_bool_values():
    load = LoadPower(t_s=0, power_w=3.25, rail="5V", on=True, faults=[])
    m = mapping(one(type="std_msgs/msg/Float32", key="lunaris/{rover}/load/x/power",
                    field="power_w", scale=None)).mappings[0]
    assert convert.out_message(m, load) == {"data": 3.25}
    rounded = mapping(one(type="std_msgs/msg/Float32", key="lunaris/{rover}/load/x/power",
                          field="power_w", integer="true")).mappings[0]
    assert convert.out_value(rounded, load) == 3250.0
    summary = PowerSummary(t_s=0, load_power_w=1, bus_power_w=1, generation_w=0,
                           net_battery_power_w=1, bus_voltage_v=16.7)
    m = mapping(one(key="lunaris/{rover}/power/summary", field="bus_voltage_v")).mappings[0]
    assert convert.out_message(m, summary) == {"data": 16700}


def test_inbound_values():
    m = mp.load_mapping(DEFAULT).mappings[1]
    assert m.direction == "in"
    assert convert.in_payload(m, {"data": [1200.0, 45.0]}) == {"distance_m": 1200.0, "angle_deg": 45.0}
    with pytest.raises(BadInput, match="expected 2 values"):
        convert.in_payload(m, {"data": [1.0]})
    with pytest.raises(BadInput, match="not a finite number"):
        convert.in_payload(m, {"data": [math.nan, 0.0]})
    with pytest.raises(BadInput, match="expected a number"):
        convert.in_payload(m, {"data": ["far", 0.0]})
    km = mapping(one(topic="/km", type="std_msgs/msg/Float64MultiArray",
                     key="lunaris/{rover}/input/radio/lander/position", direction="in",
                     field=None, fields="[distance_m, angle_deg]", scale="1000")).mappings[0]
    assert convert.in_payload(km, {"data": [1.5, 0.01]}) == {"distance_m": 1500.0, "angle_deg": 10.0}


# -- BatteryState: ROS conventions ---------------------------------------------------------------


def test_battery_state_follows_ros_conventions():
    # Mean of the MAPP per-cell curve by the trapezoid rule on its 0.1 steps:
    # 0.1 * (sum of the 11 points - (first + last) / 2) = 0.1 * (42.64 - 3.90) = 3.874 V.
    v_nom = MAPP.battery.cells_series * 3.874
    assert_allclose(convert.nominal_voltage_v(MAPP.battery), v_nom, rtol=1e-4)
    msg = convert.battery_state_message(battery_state(), MAPP.battery, 1_700_000_000_123_456_789,
                                   frame_id="base", options={"location": "bay 1"})
    assert msg["header"] == {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789},
                             "frame_id": "base"}
    assert msg["current"] == -3.0  # discharging: negative
    assert_allclose(msg["charge"], 2.65e5 / v_nom / 3600, rtol=1e-4)
    assert_allclose(msg["capacity"], 5.3e5 / v_nom / 3600, rtol=1e-4)
    assert_allclose(msg["design_capacity"], MAPP.battery.capacity_j / v_nom / 3600, rtol=1e-4)
    assert (msg["percentage"], msg["voltage"], msg["temperature"]) == (0.5, 15.2, 25.0)
    assert (msg["power_supply_status"], msg["power_supply_health"],
            msg["power_supply_technology"]) == (2, 1, 2)  # DISCHARGING, GOOD, LION
    assert len(msg["cell_voltage"]) == 4 and all(math.isnan(v) for v in msg["cell_voltage"])
    assert msg["location"] == "bay 1"


@pytest.mark.parametrize(("kw", "status", "health"), [
    ({"current_a": -2.0}, 1, 1),  # CHARGING, GOOD
    ({"current_a": 0.0, "soc": 1.0}, 4, 1),  # FULL
    ({"current_a": 0.0}, 3, 1),  # NOT_CHARGING
    ({"faults": ["over_temperature"]}, 2, 2),  # OVERHEAT
    ({"faults": ["thermal_cutoff"], "operational": False}, 3, 2),
    ({"faults": ["depleted"], "operational": False, "current_a": 0.0}, 3, 3),  # DEAD
    ({"faults": ["under_voltage_cutoff"], "operational": False, "current_a": 0.0}, 3, 3),  # DEAD
    ({"faults": ["under_temperature"]}, 2, 6),  # COLD
    ({"faults": ["disconnected"], "operational": False}, 3, 5),  # UNSPEC_FAILURE
    ({"faults": ["capacity_loss", "over_temperature"]}, 2, 2),
])
def test_battery_status_and_health_codes(kw, status, health):
    msg = convert.battery_state_message(battery_state(**kw), MAPP.battery, 0)
    assert (msg["power_supply_status"], msg["power_supply_health"]) == (status, health)


# -- DiagnosticArray -----------------------------------------------------------------------------------


def test_diagnostic_levels_follow_faults_and_staleness():
    comps = convert.components(MAPP)
    assert comps[:2] == ["battery", "rail/12V"] and "rail/SOLAR" in comps
    assert "load/nav_camera" in comps and "radio/lander" in comps and "umbilical" in comps
    active = [
        ActiveFault("lunaris/mapp-1/fault/load/nav_camera/short", {"resistance_ohm": 0.05}, 3.0,
                    "injected", "warning"),
        ActiveFault("lunaris/mapp-1/rail/5V_CH2/tripped", {}, 3.1, "derived", "critical"),
    ]
    ages = dict.fromkeys(comps, 0.1)
    ages["radio/lander"] = 5.0
    ages["umbilical"] = None
    statuses = {s["name"]: s for s in convert.diagnostic_statuses("mapp-1", comps, active, ages, 3.0)}
    assert list(statuses) == [f"mapp-1/{c}" for c in comps]
    cam = statuses["mapp-1/load/nav_camera"]
    assert (cam["level"], cam["message"], cam["hardware_id"]) == (convert.DIAG_WARN, "short", "mapp-1")
    assert cam["values"][0]["key"] == "short"
    assert '"resistance_ohm":0.05' in cam["values"][0]["value"]
    assert statuses["mapp-1/rail/5V_CH2"]["level"] == convert.DIAG_ERROR
    assert statuses["mapp-1/radio/lander"]["level"] == convert.DIAG_STALE
    assert statuses["mapp-1/radio/lander"]["message"] == "no data for 5.0 s"
    assert statuses["mapp-1/umbilical"]["level"] == convert.DIAG_STALE
    assert statuses["mapp-1/battery"] == {"level": convert.DIAG_OK, "name": "mapp-1/battery",
                                          "message": "OK", "hardware_id": "mapp-1", "values": []}
    assert [convert.level_name(x) for x in range(4)] == ["OK", "WARN", "ERROR", "STALE"]


def test_fault_component_from_either_key_form():
    assert convert.component_of_fault("lunaris/r/fault/load/cam/short") == ("load/cam", "short")
    assert convert.component_of_fault("lunaris/r/fault/battery/heating") == ("battery", "heating")
    assert convert.component_of_fault("lunaris/r/rail/12V/tripped") == ("rail/12V", "tripped")
    assert convert.component_of_fault("lunaris/r/battery/depleted") == ("battery", "depleted")


# -- the drive --------------------------------------------------------------------------------------


def test_the_drive_maps_only_for_a_rover_that_drives_and_as_odometry():
    mf = mp.load_mapping(DEFAULT)

    def drive_topics(rover) -> set[str]:
        return {b.topic for b in bd.expand(mf, [bd.rover_names(rover)]) if b.key.endswith("/drive/state")}

    assert drive_topics(MAPP) == {"/odom", "/drive_state"}
    assert drive_topics(load_rover(static_rover("mapp.yaml"))) == set()  # no drive: no topic
    # heading 90 deg (east) is yaw 0; a 10 deg climb is a pitch of -10 deg about y (REP-103):
    # q = (0, sin(-5 deg), 0, cos(-5 deg)) = (0, -0.0871557, 0, 0.9961947)
    state = DriveState(12.0, 120.0, -35.0, 6.5, 0.08, 90.0, 10.0, 4.4, 0.44, 9.5, 200.0, 1, True)
    msg = convert.odometry_message(state, 12_000_000_034, "site", {"child_frame_id": "chassis"})
    got = rosmsg.decode("nav_msgs/msg/Odometry", cdr.encode_cdr("nav_msgs/msg/Odometry", msg))
    assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (12, 34, "site")
    assert got.child_frame_id == "chassis"
    p, q = got.pose.pose.position, got.pose.pose.orientation
    assert (p.x, p.y, p.z) == (120.0, -35.0, 6.5)
    assert_allclose((q.x, q.y, q.z, q.w), (0.0, -0.0871557, 0.0, 0.9961947), atol=1e-7)
    assert got.twist.twist.linear.x == 0.08 and list(got.pose.covariance) == [0.0] * 36
    # heading 0 (north) on the flat: yaw 90 deg, q = (0, 0, sin 45 deg, cos 45 deg)
    north = convert.odometry_message(DriveState(0, 0, 0, 0, 0, 0.0, 0.0, 0, 0, 0, 0, None, False), 0)
    o = north["pose"]["pose"]["orientation"]
    assert_allclose((o["x"], o["y"], o["z"], o["w"]), (0, 0, 0.70710678, 0.70710678), atol=1e-8)
    assert north["header"]["frame_id"] == "site" and north["child_frame_id"] == "base_link"


# -- CDR, read back by the independent decoder ----------------------------------------------------


def test_cdr_of_every_default_type_reads_back_independently():
    battery = convert.battery_state_message(battery_state(), MAPP.battery, 12_000_000_034, "f")
    diag = convert.diagnostic_array_message(convert.diagnostic_statuses(
        "mapp-1", ["battery"], [ActiveFault("lunaris/mapp-1/fault/battery/heating",
                                            {"heat_w": 5.0}, 1.0, "injected", "warning")],
        {}, 3.0), 12_000_000_034, "f")
    cases = {
        "std_msgs/msg/Bool": {"data": True},
        "std_msgs/msg/Int32": {"data": -123456},
        "std_msgs/msg/Float32": {"data": 3.25},
        "std_msgs/msg/Float64MultiArray": convert._multi_array(["distance_m", "angle_deg"], [1.5, -2.0]),
        "sensor_msgs/msg/BatteryState": battery,
        "diagnostic_msgs/msg/DiagnosticArray": diag,
    }
    for typename, msg in cases.items():
        data = cdr.encode_cdr(typename, msg)
        assert data[:4] == b"\x00\x01\x00\x00", typename  # CDR little endian encapsulation
        got = rosmsg.decode(typename, data)
        if typename == "sensor_msgs/msg/BatteryState":
            assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (
                12, 34, "f")
            for name in ("voltage", "temperature", "current", "charge", "capacity",
                         "design_capacity", "percentage"):
                assert_allclose(getattr(got, name), msg[name], rtol=1e-6, err_msg=name)
            assert (got.power_supply_status, got.power_supply_health, got.present) == (2, 1, True)
            assert len(got.cell_voltage) == 4 and all(math.isnan(v) for v in got.cell_voltage)
        elif typename == "diagnostic_msgs/msg/DiagnosticArray":
            assert got.header.stamp.sec == 12
            (status,) = got.status
            assert (status.level, status.name, status.message) == (1, "mapp-1/battery", "heating")
            assert (status.values[0].key, status.hardware_id) == ("heating", "mapp-1")
        elif typename == "std_msgs/msg/Float64MultiArray":
            assert list(got.data) == [1.5, -2.0]
            assert got.layout.dim[0].label == "distance_m,angle_deg"
            assert (got.layout.dim[0].size, got.layout.dim[0].stride) == (2, 2)
        else:
            assert got.data == msg["data"], typename


def _through_rosbags(typename: str, msg: dict) -> bytes:
    store = cdr.typestore("jazzy")
    return bytes(store.serialize_cdr(cdr._to_ros(store, typename, msg), typename))


@settings(max_examples=300, deadline=None)
@given(typename=st.sampled_from(sorted(cdr.SCALAR_TYPES)),
       value=st.one_of(st.none(), st.booleans(), st.integers(-(2**64), 2**64),
                       st.floats(allow_nan=False, width=64)))
def test_a_scalar_packed_directly_is_what_rosbags_makes(typename, value):
    """The short cut for std_msgs scalars gives rosbags' bytes, or rosbags' own answer."""
    try:
        expected: bytes | type = _through_rosbags(typename, {"data": value})
    except Exception as exc:  # out of range: the short cut must fail the same way
        expected = type(exc)
    try:
        got: bytes | type = cdr.encode_cdr(typename, {"data": value})
    except Exception as exc:
        got = type(exc)
    assert got == expected


_TEXT = st.text(max_size=12)


@settings(max_examples=200, deadline=None)
@given(sec=st.integers(-(2**31), 2**31 - 1), nanosec=st.integers(0, 2**32 - 1), frame=_TEXT,
       statuses=st.lists(st.fixed_dictionaries({
           "level": st.integers(0, 127), "name": _TEXT, "message": _TEXT, "hardware_id": _TEXT,
           "values": st.lists(st.fixed_dictionaries({"key": _TEXT, "value": _TEXT}), max_size=3),
       }), max_size=6))
def test_a_diagnostic_array_written_directly_is_what_rosbags_makes(sec, nanosec, frame, statuses):
    typename = "diagnostic_msgs/msg/DiagnosticArray"
    msg = {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame},
           "status": statuses}
    assert cdr.encode_cdr(typename, msg) == _through_rosbags(typename, msg)


def test_a_restamped_diagnostic_array_is_the_one_encoded_with_that_stamp():
    statuses = convert.diagnostic_statuses(
        "mapp-1", ["battery", "load/cam"],
        [ActiveFault("lunaris/mapp-1/fault/load/cam/short", None, 3.0, "injected", "warning")],
        {"battery": 0.1, "load/cam": 0.2}, 3.0)
    typename = "diagnostic_msgs/msg/DiagnosticArray"
    first = cdr.encode_cdr(typename, convert.diagnostic_array_message(statuses, 12_000_000_034, "f"))
    for t_ns in (0, 13_500_000_001, 2**31 * 1_000_000_000 - 1):
        assert cdr.restamp(first, t_ns) == _through_rosbags(
            typename, convert.diagnostic_array_message(statuses, t_ns, "f"))


def test_inbound_cdr_from_an_independent_encoder_and_garbage():
    data = rosmsg.encode("std_msgs/msg/Float64MultiArray",
                         {"layout": {"dim": [], "data_offset": 0}, "data": [250.0, 30.0]})
    msg = cdr.decode_cdr("std_msgs/msg/Float64MultiArray", data)
    assert msg["data"] == [250.0, 30.0]
    with pytest.raises(BadInput, match="not a CDR std_msgs/msg/Float64MultiArray"):
        cdr.decode_cdr("std_msgs/msg/Float64MultiArray", b"\x00\x01\x00\x00\xff")


# -- rmw_zenoh names -----------------------------------------------------------------------------------


def test_rmw_zenoh_topic_key_and_published_type_hashes():
    assert rmw_zenoh.type_hash("std_msgs/msg/Bool") == BOOL_HASH
    assert rmw_zenoh.type_hash("std_msgs/msg/String") == STRING_HASH
    assert rmw_zenoh.rmw_topic_key(0, "/final_comms_radio_bool", "std_msgs/msg/Bool") == (
        f"0/final_comms_radio_bool/std_msgs::msg::dds_::Bool_/{BOOL_HASH}")
    assert rmw_zenoh.rmw_topic_key(0, "/robot1/chatter", "std_msgs/msg/String") == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    assert rmw_zenoh.rmw_topic_key(2, "/x", "std_msgs/msg/Bool", "humble") == (
        "2/x/std_msgs::msg::dds_::Bool_/TypeHashNotSupported")
    assert rmw_zenoh.type_hash("sensor_msgs/msg/BatteryState").startswith("RIHS01_")


def test_liveliness_tokens_match_the_rmw_zenoh_design_examples():
    assert rmw_zenoh.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener") == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener")
    talker = rmw_zenoh.entity_token(2, "8b20917502ee955ac4476e0266340d5c", 0, 10, "MP", "/", "talker",
                             "/chatter", "std_msgs/msg/String", rmw_zenoh.qos_keyexpr(False, 7))
    assert talker == ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
                      f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
    assert rmw_zenoh.qos_keyexpr(True, 1) == ":1:,1:,:,:,,"  # TRANSIENT_LOCAL, KEEP_LAST 1
    assert rmw_zenoh.qos_keyexpr(False, 42) == "::,:,:,:,,"  # every rmw_zenoh default
    assert rmw_zenoh.mangle("/pdm/rail_12V_voltage_mv") == "%pdm%rail_12V_voltage_mv"
    assert rmw_zenoh.mangle("/") == "%"


def test_the_gid_is_xxh3_128_of_the_token_low_then_high_64_bits():
    # XXH3-128 of the empty input (seed 0) is 0x99aa06d3014798d8_6001c324468d497f (the xxHash
    # test vector): rmw_zenoh copies the low 64 bits, then the high 64 bits, little endian.
    assert rmw_zenoh.gid_of("") == (bytes.fromhex("6001c324468d497f")[::-1]
                                    + bytes.fromhex("99aa06d3014798d8")[::-1])


def test_attachment_layout():
    gid = rmw_zenoh.gid_of("@ros2_lv/0/z/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::Bool_/h/q")
    assert len(gid) == 16 and gid != rmw_zenoh.gid_of("@ros2_lv/0/z/0/2/MP/%/%/n/%t/x/h/q")
    raw = rmw_zenoh.attachment(1, 1_700_000_000_000_000_001, gid)
    assert len(raw) == rmw_zenoh.ATTACHMENT_LEN == 33
    assert struct.unpack("<qqB", raw[:17]) == (1, 1_700_000_000_000_000_001, 16)
    assert raw[17:] == gid
    assert rosmsg.parse_attachment(raw) == (1, 1_700_000_000_000_000_001, gid)
    with pytest.raises(ValueError, match="gid must be 16 bytes"):
        rmw_zenoh.attachment(1, 0, b"short")


def test_one_key_expression_hears_a_topic_of_several_rovers():
    assert bd.open_keyexpr(["mapp_01/curr_to_receiving_radio_m",
                            "mapp_03/curr_to_receiving_radio_m"]) == "mapp_0$*/curr_to_receiving_radio_m"
    assert bd.open_keyexpr(["0/solar_left_dust/std_msgs::msg::dds_::Float64_",
                            "4/solar_left_dust/std_msgs::msg::dds_::Float64_"]) == \
        "*/solar_left_dust/std_msgs::msg::dds_::Float64_"
    assert bd.open_keyexpr(["fleet/a/x", "fleet/b/x"]) == "fleet/*/x"
    assert bd.open_keyexpr(["mapp_1/x"]) == "mapp_1/x"  # one rover: its own key
    assert bd.open_keyexpr(["a/x", "b/c/x"]) is None
    # what they share around a sub-chunk wildcard: the generated rules allow the bridge
    # pdm/rail_$*/set_enabled (a plain * was refused, and the crew's calls went unanswered)
    assert bd.open_keyexpr(["pdm/rail_12V/set_enabled", "pdm/rail_5V_CH2/set_enabled",
                            "pdm/rail_3V3_CH1/set_enabled"]) == "pdm/rail_$*/set_enabled"
    assert bd.open_keyexpr(["mapp_1/x", "ltv_1/x"]) == "$*_1/x"
    assert bd.open_keyexpr(["ab/x", "abab/x"]) == "ab$*/x"  # head and tail never overlap
    assert bd.open_keyexpr(["a$*/x", "b/x"]) == "*/x"  # a wildcard already


# -- the crew's controls: services in the mapping (SPEC §12a) -----------------------------------

# Published: the REP-2016 hashes of the std_srvs service types (share/std_srvs/srv/*.json of
# ros-std-srvs 5.3.6 Jazzy and 5.5.1 Kilted, and *__description.c).
SET_BOOL_HASH = "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a"
TRIGGER_HASH = "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
EMPTY_HASH = "RIHS01_5888399dedec5ccc85ea6451949fd2c9f97bfdf963f9a588821639fcd31b5d19"


def test_service_type_hashes_are_the_published_ones_and_key_the_rmw_zenoh_service():
    from services.bridge import srv

    for distro in ("jazzy", "humble"):  # rosbags' own ServiceEventInfo gives others (char[16])
        if distro == "humble":
            assert srv.service_type_hash("std_srvs/srv/SetBool", distro) == "TypeHashNotSupported"
            continue
        assert srv.service_type_hash("std_srvs/srv/SetBool", distro) == SET_BOOL_HASH
        assert srv.service_type_hash("std_srvs/srv/Trigger", distro) == TRIGGER_HASH
        assert srv.service_type_hash("std_srvs/srv/Empty", distro) == EMPTY_HASH
    assert rmw_zenoh.rmw_topic_key(0, "/pdm/rail_5V_CH2/set_enabled", "std_srvs/srv/SetBool") == (
        f"0/pdm/rail_5V_CH2/set_enabled/std_srvs::srv::dds_::SetBool_/{SET_BOOL_HASH}")
    # rmw_zenoh's service server token (research notes §2.2, worked example)
    token = rmw_zenoh.entity_token(0, "0123456789abcdef0123456789abcdef", 0, 41, "SS", "/",
                                   "lunaris_bridge", "/pdm/rail_5V_CH2/reset", "std_srvs/srv/Trigger",
                                   rmw_zenoh.qos_keyexpr(False, 10))
    assert token == ("@ros2_lv/0/0123456789abcdef0123456789abcdef/0/41/SS/%/%/lunaris_bridge/"
                     f"%pdm%rail_5V_CH2%reset/std_srvs::srv::dds_::Trigger_/{TRIGGER_HASH}/::,10:,:,:,,")
    # the standard type store is left as it was (its ServiceEventInfo is rosbags' own)
    assert cdr.typestore("jazzy").fielddefs["service_msgs/msg/ServiceEventInfo"]


def test_service_requests_and_responses_as_an_independent_codec_has_them():
    from services.bridge import srv

    for data in (True, False):
        raw = rosmsg.encode_service("std_srvs/srv/SetBool", "Request", {"data": data})
        assert raw == b"\x00\x01\x00\x00" + bytes([data])  # rmw_zenoh's bytes (research §2.3)
        assert srv.decode_request("std_srvs/srv/SetBool", raw) == {"data": data}
    # a request without fields: whatever a client sends for it (the dummy byte, or nothing)
    for raw in (b"\x00\x01\x00\x00\x00", b"\x00\x01\x00\x00", b""):
        assert srv.decode_request("std_srvs/srv/Trigger", raw) == {}
    with pytest.raises(BadInput, match="not a CDR std_srvs/srv/SetBool request"):
        srv.decode_request("std_srvs/srv/SetBool", b"\x00\x01")
    words = "rail 5V_CH2: reset; the rail is now tripped (over-current 50.53 A > 3 A)"
    for typename in ("std_srvs/srv/SetBool", "std_srvs/srv/Trigger"):
        raw = srv.encode_response(typename, {"success": True, "message": words})
        back = rosmsg.decode_service(typename, "Response", raw)
        assert (back.success, back.message) == (True, words) and raw[:4] == b"\x00\x01\x00\x00"
    assert srv.encode_response("std_srvs/srv/Empty", {}) == b"\x00\x01\x00\x00\x00"


def test_the_default_mapping_offers_the_crews_controls_for_every_rover():
    mf = mp.load_mapping(DEFAULT)
    for rover in (MAPP, LTV, load_rover(static_rover("mapp.yaml"))):
        bindings = bd.expand(mf, [bd.rover_names(rover)])
        services = {b.topic: b for b in bindings if b.mapping.kind == "service"}
        switched = [r.name for r in rover.rails]  # not the solar rail: it cannot be switched
        want = {f"/pdm/rail_{r}/{s}" for r in switched for s in ("set_enabled", "reset")}
        if rover.drive is not None:
            want.add("/drive/stop")
        assert set(services) == want, rover.id
        for r in switched:
            on = services[f"/pdm/rail_{r}/set_enabled"]
            assert (on.key, on.mapping.type, on.mapping.request) == (
                f"lunaris/{rover.id}/cmd/rail/{r}", "std_srvs/srv/SetBool", {"on": "data"})
            reset = services[f"/pdm/rail_{r}/reset"]
            assert (reset.mapping.type, reset.mapping.payload) == ("std_srvs/srv/Trigger", {"reset": True})
            assert mp.service_response(on.mapping) == {"success": "accepted", "message": "reason"}
        if rover.drive is not None:
            stop = services["/drive/stop"]
            assert (stop.key, stop.mapping.write) == (f"lunaris/{rover.id}/input/drive/traverse", "delete")
        # the same switch as a topic, for a dashboard that publishes instead of calling
        enable = {b.topic: b for b in bindings if b.mapping.kind == "topic" and b.mapping.direction == "in"}
        assert {t for t in enable if t.endswith("/enable")} == {f"/pdm/rail_{r}/enable" for r in switched}
        from services.bridge import convert
        b = enable[f"/pdm/rail_{switched[0]}/enable"]
        assert convert.in_payload(b.mapping, {"data": False}) == {"on": False}
    assert mf.bridge.crew_view == "symptoms"


def test_every_problem_of_a_bad_service_entry_is_named():
    text = """
bridge: {crew_view: everything}
mappings:
  - {topic: /a, kind: service, type: std_srvs/srv/Nope, key: "lunaris/{rover}/cmd/rail/{rail}",
     request: {on: data}}
  - {topic: /b, kind: service, type: std_srvs/srv/SetBool, key: "lunaris/{rover}/battery/state"}
  - {topic: "/c/{rail}", kind: service, type: std_srvs/srv/SetBool, key: "lunaris/{rover}/cmd/rail/{rail}",
     request: {on: value, colour: data}, field: on}
  - {topic: /d, kind: service, type: std_srvs/srv/Trigger, key: "lunaris/{rover}/cmd/rail/{rail}",
     payload: {reset: true}}
  - {topic: "/e/{rail}", kind: service, type: std_srvs/srv/Trigger, key: "lunaris/{rover}/cmd/rail/{rail}",
     write: delete}
  - {topic: /f, kind: service, type: std_srvs/srv/Trigger, key: "lunaris/{rover}/input/drive/traverse"}
  - {topic: "/g/{rail}", kind: service, type: std_srvs/srv/Trigger, key: "lunaris/{rover}/cmd/rail/{rail}",
     payload: {reset: 1}, response: {success: reason, status: accepted}}
  - {topic: /h, kind: gadget, type: std_msgs/msg/Bool, key: "lunaris/{rover}/battery/state",
     field: operational}
  - {topic: /i, type: std_msgs/msg/Bool, key: "lunaris/{rover}/battery/state", field: operational,
     request: {on: data}, payload: {reset: true}}
  - {topic: "/j/{rail}", type: std_msgs/msg/Bool, key: "lunaris/{rover}/cmd/rail/{rail}", direction: in,
     field: on, payload: {on: true, volts: 3}}
  - {topic: /i, kind: service, type: std_srvs/srv/Trigger, key: "lunaris/{rover}/input/drive/traverse",
     write: delete}
"""
    with pytest.raises(ConfigError) as err:
        mapping(text)
    problems = err.value.problems
    expected = [
        "bridge.crew_view: expected symptoms or full, got 'everything'",
        "mappings[0].type: unknown ROS 2 service type 'std_srvs/srv/Nope'",
        "mappings[0].topic: must contain {rail} like the key",
        "mappings[1].key: a service writes a key the twin reads",
        "mappings[2].field: not used by a service",
        "mappings[2].request.on: the std_srvs/srv/SetBool request has no field 'value'",
        "mappings[2].request.colour: RailCommand has no field 'colour'",
        "mappings[3].topic: must contain {rail} like the key",
        "mappings[4].write: cmd/rail/* takes a put, not a delete",
        "mappings[5].request: the write DriveTraverse needs waypoints",
        "mappings[6].payload.reset: RailCommand.reset is a bool, not 1",
        "mappings[6].response.success: reason is a string, the response's success a bool",
        "mappings[6].response.status: the std_srvs/srv/Trigger response has no field 'status'",
        "mappings[7].kind: expected topic or service, got 'gadget'",
        "mappings[8].request: only a service (kind: service) has a request",
        "mappings[8].payload: only an inbound topic or a service writes a payload",
        "mappings[9].payload.on: also taken from the message",
        "mappings[9].payload.volts: RailCommand has no field 'volts'",
        "mappings[10].topic: the service /i has the name of the topic of mappings[8]",
    ]
    for want in expected:
        assert any(p.startswith(want) for p in problems), f"{want!r} not in {problems}"
