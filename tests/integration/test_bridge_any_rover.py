"""The dashboard path for any valid rover and any fleet (SPEC §7 second release).

A rover whose radio, rails, loads and panels have other names than the shipped ones passes
``lunaris check --bridge`` and runs whole under ``lunaris up``, bridge included, with its
dashboard topics following its names; a fleet shared by two bridge processes keeps the plain
topic names, one ROS 2 domain per rover. Everything is read back through Zenoh keys.
"""

from __future__ import annotations

import re
import subprocess
import threading
from pathlib import Path

import pytest
import yaml

from common import keys
from tests import rosmsg
from tests.harness import (
    ROOT,
    ROVERS,
    Probe,
    free_endpoint,
    lunaris_cmd,
    static_rover,
    stop_process,
    wait_for,
)

pytestmark = pytest.mark.timeout(120)

DEFAULT = ROOT / "config" / "bridge" / "default.yaml"
RAILS = {"12V": "MAIN", "5V_CH1": "AUX_A", "5V_CH2": "AUX_B", "3V3_CH1": "LOW_A", "3V3_CH2": "LOW_B"}
SCOUT = "scout-7"


def other_names_rover(folder: Path) -> Path:
    """The MAPP rover with every name changed: id, radio, rails (the solar one too), loads,
    panels, and the drive's and the radio's loads."""
    data = yaml.safe_load((ROVERS / "mapp.yaml").read_text())
    data["rover"]["id"] = SCOUT
    data["radios"][0]["name"] = "base_station"
    for rail in data["rails"]:
        rail["name"] = RAILS[rail["name"]]
    data["solar"]["rail"]["name"] = "PV"
    loads = {}
    for load in data["loads"]:
        loads[load["name"]] = load["name"] = f"dev_{load['name']}"
        load["rail"] = RAILS[load["rail"]]
    for panel in data["solar"]["panels"]:
        panel["name"] = f"wing_{panel['name']}"
    if data.get("drive"):
        data["drive"]["load"] = loads[data["drive"]["load"]]
    for radio in data["radios"]:  # the load that powers it
        if radio.get("load"):
            radio["load"] = loads[radio["load"]]
    path = folder / "scout.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_check_a_rover_against_a_mapping(tmp_path):
    scout = other_names_rover(tmp_path)
    ok = subprocess.run(lunaris_cmd("check", str(scout), "--bridge", str(DEFAULT)),
                        capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert ok.returncode == 0, ok.stderr
    assert re.search(rf"{re.escape(str(scout))}: bridge ok - .*: \d+ topics out, \d+ in", ok.stdout)
    strict = tmp_path / "strict.yaml"
    strict.write_text("mappings:\n  - {topic: /link, type: std_msgs/msg/Bool, "
                      "key: 'lunaris/{rover}/radio/lander/link', field: in_range}\n")
    bad = subprocess.run(lunaris_cmd("check", str(scout), "--bridge", str(strict)),
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert bad.returncode == 1
    assert "mappings[0].key: rover scout-7 has no radio 'lander' (radios: base_station)" in bad.stderr


def test_a_rover_with_other_names_runs_whole_under_up_with_a_fleet_of_two_bridges(tmp_path):
    scout = other_names_rover(tmp_path)
    mapp = static_rover("mapp.yaml")
    mapping = tmp_path / "crew.yaml"  # the default one, with another namespace for the keys
    mapping.write_text(DEFAULT.read_text().replace(
        '  topic_prefix: ""\n', '  topic_prefix: ""\n  fleet_namespace: /crew_{rover}\n'))
    endpoint = free_endpoint()
    up = subprocess.Popen(lunaris_cmd("up", "--rover", str(mapp), "--rover", str(scout),
                                      "--listen", endpoint, "--bridge-config", str(mapping),
                                      "--bridges", "2", "--no-status"),
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(up.stdout.readline, "")), daemon=True)
    reader.start()
    try:
        wait_for(lambda: any("router listening" in x for x in lines), 30, "the router of lunaris up")
        with Probe(endpoint) as probe:
            probe.watch("lunaris/**")
            samples: dict[str, bytes] = {}
            sub = probe.session.declare_subscriber(
                "**", lambda s: samples.__setitem__(str(s.key_expr), s.payload.to_bytes()))
            services = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults",
                        "bridge")
            for rover in (SCOUT, "mapp-1"):
                probe.wait_services(rover, services if rover == SCOUT else
                                    tuple(s for s in services if s != "drive"), timeout_s=60)
            link = probe.wait_value(keys.radio_link(SCOUT, "base_station"))
            # ros2dds: the rover's namespace before the plain topic; rmw_zenoh: its domain (1)
            radio_key = "crew_scout_7/final_comms_radio_bool"
            wait_for(lambda: radio_key in samples, 20, f"{radio_key} (keys: {sorted(samples)[:40]})")
            assert rosmsg.decode("std_msgs/msg/Bool", samples[radio_key]).data == link["in_range"]
            for topic in ("pdm/rail_MAIN_voltage_mv", "pdm/rail_AUX_B_current_ma",
                          "pdm/rail_PV_power_mw", "load_dev_imu_power_w", "battery_state"):
                wait_for(lambda t=topic: f"crew_scout_7/{t}" in samples, 20, topic)
            wait_for(lambda: any(k.startswith("1/final_comms_radio_bool/std_msgs::msg::dds_::Bool_/")
                                 for k in samples), 20, "the scout's rmw_zenoh topic in domain 1")
            wait_for(lambda: any(k.startswith("0/final_comms_radio_bool/") for k in samples), 20,
                     "the MAPP's rmw_zenoh topic in domain 0")
            assert "crew_mapp_1/battery_state" in samples or wait_for(
                lambda: "crew_mapp_1/battery_state" in samples, 20, "the MAPP's battery state")
            # the dashboard's position reaches the scout's base_station radio, which refuses it:
            # the scout drives, and its drive says where it is
            cdr = rosmsg.encode("std_msgs/msg/Float64MultiArray",
                                {"layout": {"dim": [], "data_offset": 0}, "data": [5000.0, 0.0]})
            probe.session.put("crew_scout_7/curr_to_receiving_radio_m", cdr)
            probe.wait_event(SCOUT, lambda e: e["kind"] == "rejected" and e["source"] == "radio"
                             and e["key"] == keys.input_radio_position(SCOUT, "base_station"))
            # the crew's controls of each rover, served by its own shard: both shards' queryables
            # match the key (open in the namespace and the rail), the other drops the call
            request = rosmsg.encode_service("std_srvs/srv/SetBool", "Request", {"data": False})
            for ns, rail in (("crew_scout_7", "AUX_B"), ("crew_mapp_1", "5V_CH2")):
                replies = list(probe.session.get(f"{ns}/pdm/rail_{rail}/set_enabled",
                                                 payload=request, timeout=8.0))
                answers = [r.ok for r in replies if r.ok is not None]
                assert len(answers) == 1, (ns, replies)
                got = rosmsg.decode_service("std_srvs/srv/SetBool", "Response",
                                            answers[0].payload.to_bytes())
                assert got.success and f"rail {rail}: on=false" in got.message, (ns, got.message)
            del sub
        started = [x for x in lines if re.search(r"\[up\] bridge-\d started", x)]
        assert len(started) == 2, lines
        assert not [x for x in lines if "FAILED" in x or "exited with" in x], lines
    finally:
        stop_process(up, timeout_s=20)
        reader.join(timeout=5)
