"""The ``ros2`` flavour against real ROS 2 (SPEC §7 second release).

The bridge runs as a ROS 2 node (rclpy, Fast DDS over shared memory only) beside the twin; a
crew dashboard, a plain rclpy process that knows nothing of Lunaris (tests/ros2/dashboard.py),
receives ``/battery_state``, ``/final_comms_radio_bool``, ``/diagnostics`` and the PDM values
and checks them against the twin's own keys, and its ``Float64MultiArray`` on
``/curr_to_receiving_radio_m`` moves the radio. No process started here opens a UDP socket.
"""

from __future__ import annotations

import json
import math
import os
import platform
import random
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from common import keys
from tests.harness import ALL_SERVICES, ROOT, stop_process, wait_for

pytestmark = [
    pytest.mark.timeout(120),
    pytest.mark.skipif(sys.platform != "linux" or platform.machine() != "x86_64",
                       reason="the ROS 2 wheels on PyPI are for Linux x86_64"),
]

R = "mapp-1"
SERVICES = (*ALL_SERVICES, "bridge")
DASHBOARD = ROOT / "tests" / "ros2" / "dashboard.py"
TOPICS = {
    "/battery_state": "sensor_msgs/msg/BatteryState",
    "/final_comms_radio_bool": "std_msgs/msg/Bool",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/pdm/battery_voltage_mv": "std_msgs/msg/Int32",
    "/pdm/sys_bus_voltage_mv": "std_msgs/msg/Int32",
    "/pdm/rail_5V_CH2_current_ma": "std_msgs/msg/Int32",
    "/pdm/rail_12V_voltage_mv": "std_msgs/msg/Int32",
}


def ros2_env(domain: int) -> dict[str, str]:
    """Fast DDS over shared memory only: no UDP socket. ROS_AUTOMATIC_DISCOVERY_RANGE is
    never set to LOCALHOST here (Fast DDS then binds UDP ports on every interface)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_AUTOMATIC_DISCOVERY")}
    env.update(FASTDDS_BUILTIN_TRANSPORTS="SHM", ROS_DOMAIN_ID=str(domain),
               RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    return env


def udp_sockets(pids: list[int]) -> dict[int, list[str]]:
    """The UDP sockets (IPv4 and IPv6) each process holds, from /proc."""
    inodes: dict[str, str] = {}
    for table in ("udp", "udp6"):
        path = Path(f"/proc/net/{table}")
        if path.exists():
            for line in path.read_text().splitlines()[1:]:
                cols = line.split()
                inodes[cols[9]] = f"{table} {cols[1]}"
    held: dict[int, list[str]] = {}
    for pid in pids:
        fd_dir = Path(f"/proc/{pid}/fd")
        for fd in fd_dir.iterdir() if fd_dir.exists() else []:
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:[") and target[8:-1] in inodes:
                held.setdefault(pid, []).append(inodes[target[8:-1]])
    return held


class Dashboard:
    """The rclpy dashboard process: every message it prints, and a way to publish."""

    def __init__(self, env: dict[str, str]):
        self.proc = subprocess.Popen(
            [sys.executable, str(DASHBOARD), *(f"{t}={ty}" for t, ty in TOPICS.items())],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env, cwd="/")  # cwd /: it imports nothing of Lunaris
        self.messages: dict[str, list[tuple[float, dict]]] = {}
        self.ready = threading.Event()
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.strip() == "ready":
                self.ready.set()
                continue
            item = json.loads(line)
            with self._lock:
                self.messages.setdefault(item["topic"], []).append((item["t"], item["msg"]))

    def latest(self, topic: str, after: float = 0.0) -> dict | None:
        with self._lock:
            got = [m for t, m in self.messages.get(topic, []) if t >= after]
        return got[-1] if got else None

    def call(self, service: str, typename: str, request: dict, timeout_s: float = 25.0) -> dict:
        """Call a service from the dashboard; its response's fields."""
        assert self.proc.stdin is not None
        sent = time.monotonic()
        self.proc.stdin.write(json.dumps({"call": service, "type": typename, "request": request}) + "\n")
        self.proc.stdin.flush()
        got = wait_for(lambda: (self.latest(service, sent),) if service in self.messages
                       and any(t >= sent for t, _ in self.messages[service]) else None,
                       timeout_s, f"the answer to {service}")[0]
        assert got is not None, f"{service}: no answer within 10 s"
        return got

    def subscribe(self, on: bool) -> None:
        """Make (``on``) or destroy the dashboard's subscriptions, and wait until it has."""
        assert self.proc.stdin is not None
        sent = time.monotonic()
        self.proc.stdin.write(json.dumps({"subscribe": on}) + "\n")
        self.proc.stdin.flush()
        wait_for(lambda: (m := self.latest("subscribed", sent)) is not None and m is on, 10,
                 f"the dashboard's subscriptions {'made' if on else 'destroyed'}")

    def publish(self, topic: str, typename: str, msg: dict) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"topic": topic, "type": typename, "msg": msg}) + "\n")
        self.proc.stdin.flush()

    def stop(self) -> str:
        """Its stdin closed, the dashboard shuts its executor and rclpy down and exits (a
        clean exit: an rclpy node killed is an unclean death to Fast DDS, see
        /work/shared/tools/fastdds-shm); SIGINT only if it has not gone within 10 s."""
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            stop_process(self.proc)
        return self.proc.stderr.read() if self.proc.stderr else ""


SHM = Path("/dev/shm")
FASTDDS_SHM = ("fastdds_*", "fast_datasharing_*", "sem.fastdds_*")


def _fastdds_files() -> set[Path]:
    return {p for pattern in FASTDDS_SHM for p in SHM.glob(pattern)}


def _mapped_anywhere() -> set[str]:
    """The /dev/shm files some process of this machine we may look at has open or mapped."""
    used: set[str] = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            used |= {line.split(maxsplit=5)[-1] for line in (proc / "maps").read_text().splitlines()
                     if "/dev/shm/" in line}
            fds = list((proc / "fd").iterdir())
        except OSError:  # gone, or not ours to look at
            continue
        for fd in fds:
            try:
                used.add(os.readlink(fd))
            except OSError:  # closed meanwhile
                continue
    return used


@pytest.fixture(autouse=True)
def fastdds_shm_cleaned():
    """Remove the Fast DDS shared-memory files this test left in /dev/shm: those that appeared
    during it and that no process holds when it ends (another user's participants, on this
    shared machine, keep theirs)."""
    before = _fastdds_files()
    yield
    used = _mapped_anywhere()
    for path in sorted(_fastdds_files() - before):
        if str(path) not in used:
            path.unlink(missing_ok=True)


def milli(x: float) -> int:
    return int(math.copysign(math.floor(abs(x) * 1000 + 0.5), x))


@pytest.fixture
def ros2_twin(probe, twin_factory, mapp_file, tmp_path, monkeypatch):
    """The twin and the bridge with the ros2 flavour only, and the rclpy dashboard."""
    domain = random.randint(1, 100)  # apart from any other ROS 2 test on this machine
    env = ros2_env(domain)
    for name in ("ROS_DOMAIN_ID", "FASTDDS_BUILTIN_TRANSPORTS", "RMW_IMPLEMENTATION"):
        monkeypatch.setenv(name, env[name])
    mapping = tmp_path / "ros2.yaml"
    text = (ROOT / "config/bridge/default.yaml").read_text()
    for old, new in (("ros2dds: {enabled: true}", "ros2dds: {enabled: false}"),
                     ("rmw_zenoh: {enabled: true,", "rmw_zenoh: {enabled: false,"),
                     ("ros2: {enabled: false,", "ros2: {enabled: true,")):
        assert old in text
        text = text.replace(old, new)
    mapping.write_text(text)
    probe.watch(f"lunaris/{R}/**")
    dash = Dashboard(env)
    twin = twin_factory([mapp_file], services=SERVICES, extra={"bridge": ["--bridge-config", str(mapping)]})
    try:
        assert dash.ready.wait(30), "the dashboard did not start"
        probe.wait_services(R, SERVICES)
        yield probe, twin, dash
    finally:
        err = dash.stop()
        if err.strip():
            print(f"--- dashboard stderr ---\n{err[-3000:]}")


def _mismatches(probe, dash: Dashboard) -> list[str]:
    b = probe.value(keys.battery_state(R))
    s = probe.value(keys.power_summary(R))
    link = probe.value(keys.radio_link(R, "lander"))
    rail12, rail5 = probe.value(keys.rail_state(R, "12V")), probe.value(keys.rail_state(R, "5V_CH2"))
    if None in (b, s, link, rail12, rail5):
        return ["twin keys not there yet"]
    bad = []
    want: dict[str, Any] = {
        "/final_comms_radio_bool": link["in_range"],
        "/pdm/battery_voltage_mv": milli(b["voltage_v"]),
        "/pdm/sys_bus_voltage_mv": milli(s["bus_voltage_v"]),
        "/pdm/rail_5V_CH2_current_ma": milli(rail5["current_a"]),
        "/pdm/rail_12V_voltage_mv": milli(rail12["voltage_v"]),
    }
    for topic, value in want.items():
        m = dash.latest(topic)
        if m is None or m["data"] != value:
            bad.append(f"{topic}: {m and m['data']} vs {value}")
    m = dash.latest("/battery_state")
    if m is None or not (math.isclose(m["voltage"], b["voltage_v"], rel_tol=1e-6)
                         and math.isclose(m["current"], -b["current_a"], rel_tol=1e-6, abs_tol=1e-9)
                         and math.isclose(m["percentage"], b["soc"], rel_tol=1e-6)):
        bad.append(f"/battery_state {m and (m['voltage'], m['current'], m['percentage'])} vs {b}")
    m = dash.latest("/diagnostics")
    names = {st["name"]: st["level"] for st in m["status"]} if m else {}
    if names.get(f"{R}/battery") != 0 or names.get(f"{R}/rail/5V_CH2") != 0:
        bad.append(f"/diagnostics {names}")
    return bad


def _settle(check, timeout_s: float = 20.0, what: str = "the dashboard to match the twin") -> None:
    deadline = time.monotonic() + timeout_s
    while (problems := check()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not problems, f"timed out waiting for {what}: {problems[:10]}"


def test_an_rclpy_dashboard_sees_the_twin_and_moves_the_radio(ros2_twin):
    probe, twin, dash = ros2_twin
    probe.put(keys.clock_control(R), {"paused": True})
    probe.wait_value(keys.clock(R), lambda c: c["paused"])
    _settle(lambda: _mismatches(probe, dash))

    # the dashboard's own Float64MultiArray moves the radio out of range and back
    for distance_m, in_range in ((1000.0, False), (100.0, True)):
        sent = time.monotonic()
        dash.publish("/curr_to_receiving_radio_m", "std_msgs/msg/Float64MultiArray",
                     {"data": [distance_m, 0.0]})
        probe.wait_value(keys.radio_link(R, "lander"),
                         lambda v, r=in_range, d=distance_m: v["in_range"] is r
                         and math.isclose(v["x_m"], d, abs_tol=1e-6))
        wait_for(lambda t0=sent, r=in_range: (m := dash.latest("/final_comms_radio_bool", t0))
                 and m["data"] is r, 10, f"/final_comms_radio_bool {in_range} at the dashboard")

    # a fault reaches the dashboard's /diagnostics and its PDM values
    t0 = time.monotonic()
    probe.put(keys.fault(R, "load/nav_camera", "short"), {"resistance_ohm": 0.05})

    def tripped() -> bool:
        m = dash.latest("/diagnostics", t0)
        st = {s["name"]: s for s in m["status"]} if m else {}
        rail = st.get(f"{R}/rail/5V_CH2")
        return bool(rail and rail["level"] == 2 and "tripped" in [v["key"] for v in rail["values"]])
    wait_for(tripped, 10, "the tripped rail as ERROR on the dashboard's /diagnostics")
    wait_for(lambda: (m := dash.latest("/pdm/rail_5V_CH2_current_ma", t0)) and m["data"] == 0, 10,
             "the tripped rail at 0 mA on the dashboard")

    # the crew responds from its dashboard (SPEC §12a): the channel safed, then reset once the
    # instructor has cleared the short; each answered with success and the twin's reason
    rail = keys.rail_state(R, "5V_CH2")
    off = dash.call("/pdm/rail_5V_CH2/set_enabled", "std_srvs/srv/SetBool", {"data": False})
    # (a tripped rail stays tripped, its latch held, until it is reset)
    assert off["success"] is True and off["message"].startswith("rail 5V_CH2: on=false; the rail is now"), off
    probe.delete(keys.fault(R, "load/nav_camera", "short"))
    reset = dash.call("/pdm/rail_5V_CH2/reset", "std_srvs/srv/Trigger", {})  # the trip's latch
    assert reset["success"] is True and "rail 5V_CH2: reset; the rail is now off" in reset["message"], reset
    probe.wait_event(R, lambda e: e["kind"] == "command" and e.get("actor") == "crew"
                     and (e.get("params") or {}).get("reset") is True)
    on = dash.call("/pdm/rail_5V_CH2/set_enabled", "std_srvs/srv/SetBool", {"data": True})
    assert on["success"] is True and "the rail is now on" in on["message"], on
    probe.wait_value(rail, lambda v: v["state"] == "on")

    pids = [dash.proc.pid] + [p.pid for p in twin.procs.values()]
    assert udp_sockets(pids) == {}, "a process opened a UDP socket"


def test_the_delivery_key_says_when_the_crews_dashboard_stops_hearing_the_bridge(ros2_twin):
    """SPEC §13d: ``bridge/delivery`` says the rclpy dashboard is receiving (the subscriptions
    the bridge's publishers matched); its subscriptions destroyed (the crew's dashboard gone
    from the DDS graph, as when Fast DDS' shared-memory discovery fails), the key says silent
    within 4 s, then an event says "not discovered"; subscribed again, receiving again, the
    messages flowing. Every rclpy process exits cleanly."""
    probe, twin, dash = ros2_twin
    key = keys.BRIDGE_DELIVERY.key(R)

    def ros2(v: dict) -> dict:
        return next(f for f in v["flavours"] if f["flavour"] == "ros2")
    wait_for(lambda: dash.latest("/diagnostics"), 20, "/diagnostics at the dashboard")
    first = probe.wait_value(key, lambda v: v["receiving"] and ros2(v)["readers"] >= 1
                             and ros2(v)["topics_read"] >= len(TOPICS), timeout_s=20)
    assert ros2(first)["sent"] > 0 and ros2(first)["errors"] == 0
    assert first["silent_since_wall_s"] is None and first["ever_received"]

    dash.subscribe(False)
    probe.clear_history()
    silent = probe.wait_sample(key, lambda v: not v["receiving"], timeout_s=4.0)
    assert silent["silent_since_wall_s"] is not None and ros2(silent)["readers"] == 0
    lost = probe.wait_event(R, lambda e: e["kind"] == "delivery" and e["severity"] == "warning",
                            timeout_s=10)
    assert "not discovered" in lost["message"] and lost["source"] == "bridge", lost
    assert ros2(probe.value(key))["sent"] > ros2(silent)["sent"]  # the bridge sent on, unread

    back = time.monotonic()
    dash.subscribe(True)
    again = probe.wait_value(key, lambda v: v["receiving"] and ros2(v)["readers"] >= 1,
                             timeout_s=10)
    assert again["silent_since_wall_s"] is None
    probe.wait_event(R, lambda e: e["kind"] == "delivery" and e["severity"] == "info")
    wait_for(lambda: dash.latest("/diagnostics", back), 10, "/diagnostics at the dashboard again")

    err = dash.stop()
    assert dash.proc.returncode == 0 and "terminate called" not in err, err[-2000:]
    twin.stop()
    assert "terminate called" not in twin.log("bridge"), twin.log("bridge")[-2000:]
