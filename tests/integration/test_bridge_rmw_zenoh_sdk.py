"""The ``rmw_zenoh`` flavour read by an independent rmw_zenoh client from PyPI.

``zenoh-ros2-sdk`` (tests/ros2/rmw_zenoh_client.py, given the local ``.msg`` files of
tests/msgdefs and forbidden to fetch any) lists the topics from the bridge's liveliness tokens,
subscribes to every published one with the type hash it computes itself, decodes each message,
and publishes the inbound topic. Every attachment's GID must be XXH3-128 of its publisher's
token (low 64 bits, then high), as rmw_zenoh computes it. Its service client calls the crew's
controls (SPEC §12a) with the service type hash it computes itself.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import xxhash

from common import keys
from tests.harness import ALL_SERVICES, ROOT, stop_process, wait_for

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
SERVICES = (*ALL_SERVICES, "bridge")
CLIENT = ROOT / "tests" / "ros2" / "rmw_zenoh_client.py"
MSGDEFS = ROOT / "tests" / "msgdefs"


class Client:
    def __init__(self, port: int, config: Path):
        env = {"ZENOH_SESSION_CONFIG_URI": str(config), "PATH": "/usr/bin:/bin"}
        self.proc = subprocess.Popen([sys.executable, str(CLIENT), str(port), "0", str(MSGDEFS)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env, cwd="/")
        self.items: list[dict] = []
        self._lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                with self._lock:
                    self.items.append(json.loads(line))

    def find(self, pred) -> list[dict]:
        with self._lock:
            return [i for i in self.items if pred(i)]

    def call(self, service: str, typename: str, request: dict) -> dict:
        """A service call by the SDK's client: its response's fields (None: no answer)."""
        assert self.proc.stdin is not None
        n = len(self.find(lambda i: i.get("call") == service))
        self.proc.stdin.write(json.dumps({"call": service, "type": typename, "request": request}) + "\n")
        self.proc.stdin.flush()
        got = wait_for(lambda: self.find(lambda i: i.get("call") == service)[n:], 30,
                       f"the SDK's call of {service}")[0]
        assert got["response"] is not None, f"{service}: no answer to the SDK's call ({got})"
        return got["response"]

    def publish(self, topic: str, typename: str, msg: dict) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"topic": topic, "type": typename, "msg": msg}) + "\n")
        self.proc.stdin.flush()


def test_an_independent_rmw_zenoh_client_reads_every_topic_and_drives_the_radio(
        probe, twin_factory, mapp_file, router, tmp_path):
    probe.watch(f"lunaris/{R}/**")
    probe.watch("final_comms_radio_bool")
    twin_factory([mapp_file], services=SERVICES)
    probe.wait_services(R, SERVICES)
    # a topic is advertised with its first message; the radio's comes within its 1 s heartbeat
    wait_for(lambda: probe.value("final_comms_radio_bool") is not None, 10, "the radio's first topic")
    config = tmp_path / "session.json5"
    # a client of the test's router: no scouting (multicast or gossip), nothing to listen on
    config.write_text(json.dumps({"mode": "client", "connect": {"endpoints": [router]},
                                  "listen": {"endpoints": []},
                                  "scouting": {"multicast": {"enabled": False},
                                               "gossip": {"enabled": False}}}))
    port = int(router.rsplit(":", 1)[1])
    client = Client(port, config)
    try:
        wait_for(lambda: client.find(lambda i: "ready" in i), 60,
                 lambda: f"the client to start ({client.proc.stderr and client.proc.poll()})")
        listing = client.find(lambda i: "topics" in i)[0]
        topics, tokens = listing["topics"], listing["tokens"]
        # what `ros2 topic list -t` shows, from the bridge's tokens
        assert topics["/battery_state"] == ["sensor_msgs/msg/BatteryState"]
        assert topics["/final_comms_radio_bool"] == ["std_msgs/msg/Bool"]
        assert topics["/curr_to_receiving_radio_m"] == ["std_msgs/msg/Float64MultiArray"]
        assert topics["/diagnostics"] == ["diagnostic_msgs/msg/DiagnosticArray"]
        assert "/pdm/rail_SOLAR_current_limit_ma" not in topics  # never published
        published = {t.split("/")[9].replace("%", "/"): t for t in tokens if t.split("/")[5] == "MP"}
        # every published topic decoded by the SDK (its own type hash picked the key)
        wait_for(lambda: set(published) <= {i["topic"] for i in client.find(lambda i: "msg" in i)},
                 30, lambda: f"a message on every topic; missing "
                 f"{set(published) - {i['topic'] for i in client.find(lambda i: 'msg' in i)}}")
        # every attachment: 33 bytes, and the GID is XXH3-128 of the publisher's token
        for topic, token in published.items():
            want = xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little").hex()
            atts = [i["attachment"] for i in client.find(lambda i, t=topic: i.get("topic") == t
                                                         and "attachment" in i)]
            assert atts and all(a["length"] == 33 and a["gid"] == want for a in atts), topic
        b = probe.wait_value(keys.battery_state(R))
        msg = client.find(lambda i: i.get("topic") == "/battery_state" and "msg" in i)[-1]["msg"]
        assert msg["design_capacity"] > 0 and 0.0 < msg["percentage"] <= 1.0
        assert math.isclose(msg["voltage"], b["voltage_v"], rel_tol=0.05)
        # the SDK's publisher drives the inbound topic: the radio moves out of range and back
        for distance_m, in_range in ((1000.0, False), (50.0, True)):
            client.publish("/curr_to_receiving_radio_m", "std_msgs/msg/Float64MultiArray",
                           {"data": [distance_m, 0.0]})
            probe.wait_value(keys.radio_link(R, "lander"),
                             lambda v, r=in_range, d=distance_m: v["in_range"] is r
                             and math.isclose(v["x_m"], d, abs_tol=1e-6))
            wait_for(lambda r=in_range: client.find(
                lambda i: i.get("topic") == "/final_comms_radio_bool" and "msg" in i)[-1]["msg"]["data"] is r,
                     10, f"the SDK to read /final_comms_radio_bool {in_range}")
        # the crew's controls through the SDK's service client: a short trips 5V_CH2; the crew
        # safes the channel, the instructor clears the short, the crew resets and switches on
        rail = keys.rail_state(R, "5V_CH2")
        probe.put(keys.fault(R, "load/nav_camera", "short"), {"resistance_ohm": 0.05})
        probe.wait_value(rail, lambda v: v["state"] == "tripped")
        off = client.call("/pdm/rail_5V_CH2/set_enabled", "std_srvs/srv/SetBool", {"data": False})
        assert off["success"] is True and off["message"].startswith("rail 5V_CH2: on=false"), off
        probe.delete(keys.fault(R, "load/nav_camera", "short"))
        reset = client.call("/pdm/rail_5V_CH2/reset", "std_srvs/srv/Trigger", {})
        assert reset["success"] is True, reset
        assert "rail 5V_CH2: reset; the rail is now off" in reset["message"], reset
        on = client.call("/pdm/rail_5V_CH2/set_enabled", "std_srvs/srv/SetBool", {"data": True})
        assert on["success"] is True and "the rail is now on" in on["message"], on
        probe.wait_value(rail, lambda v: v["state"] == "on")
        assert [e["actor"] for e in probe.events(R) if e["kind"] == "command"][-3:] == ["crew"] * 3
    finally:
        if client.proc.stdin:
            client.proc.stdin.close()
        stop_process(client.proc)
        err = client.proc.stderr.read() if client.proc.stderr else ""
        if err.strip():
            print(f"--- rmw_zenoh client stderr ---\n{err[-3000:]}")
