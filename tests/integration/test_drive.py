"""The drive over real processes: a traverse moves drive/state, sets the drive load's power on
the grade and moves the radio link; delete stops the rover; bad traverses change nothing.

Figures from config/rovers/mapp.yaml (m g = 10 kg * 1.625 = 16.25 N, c_rr 0.2, eta 0.05,
idle 3 W), derived by hand:

- flat at 0.1 m/s: F = 16.25 * 0.2 = 3.25 N, P = 3.25 * 0.1 / 0.05 + 3 = 9.5 W;
- 20 deg up at 0.1 m/s: F = 16.25 (0.2 * 0.93969262 + 0.34202014) = 8.6118348 N,
  P = 0.86118348 / 0.05 + 3 = 20.2236696 W;
- the lander radio stands at the site origin with a 400 m x 250 m footprint: driving east
  along y = 0 from the start (5, 0, 0), the link is lost past x = 400 m.
"""

from __future__ import annotations

import json
import math
import subprocess

import pytest

from common import keys
from lunaris.client import Mirror
from tests.harness import (
    ROOT,
    ROVERS,
    Probe,
    Twin,
    env_without_zenoh_config,
    free_endpoint,
    json_bridge_extra,
    lunaris_cmd,
    open_router,
    rover_without_drive,
    stop_process,
    wait_for,
)

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
NO_DRIVE = "ltv-1"  # the LTV without its drive section rides along
SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "faults", "drive", "bridge")
START = (5.0, 0.0, 0.0)
FLAT_W, UPHILL_W, IDLE_W = 9.5, 20.2236696, 3.0
TRAVERSE = keys.input_drive_traverse(R)
STATE = keys.drive_state(R)


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    endpoint = free_endpoint()
    router = open_router(endpoint)
    ltv = rover_without_drive(ROVERS / "ltv.yaml", tmp_path_factory.mktemp("rovers"))
    try:
        with Twin(endpoint, [ROVERS / "mapp.yaml", ltv], tmp_path_factory.mktemp("twin"),
                  services=SERVICES, extra=json_bridge_extra(tmp_path_factory.mktemp("mapping")),
                  ) as t, Probe(endpoint) as p:
            p.watch("lunaris/**")
            p.watch("json/**")  # the bridge's json flavour
            p.wait_services(R, SERVICES)
            p.wait_services(NO_DRIVE, tuple(s for s in SERVICES if s != "drive"))
            p.wait_value(STATE)
            yield p, t
    finally:
        router.close()


@pytest.fixture
def probe(twin):
    """The shared probe, the twin reset to the rover files (the rover parked at its start)."""
    p, _ = twin
    epoch = p.wait_value(keys.clock(R))["epoch"]
    p.put(keys.control_reset(R), b"")
    p.wait_value(keys.clock(R), lambda c: c["epoch"] > epoch)
    state = p.wait_value(STATE, lambda s: s["status"] == "parked" and s["odometer_m"] == 0.0)
    assert (state["x_m"], state["y_m"], state["z_m"]) == START
    p.clear_history()
    return p


def answer(p: Probe, rover: str, key: str, payload, delete: bool = False) -> dict:
    """Put (or delete) and return the event answering it: ``input`` or ``rejected``."""
    seen = len(p.events(rover))
    if delete:
        p.delete(key)
    else:
        p.put(key, payload)
    return p.wait_event(rover, lambda e: e["key"] == key and e["kind"] in ("input", "rejected")
                        and p.events(rover).index(e) >= seen)


def waypoints(*points: tuple[float, float, float]) -> list[dict]:
    return [{"x_m": x, "y_m": y, "z_m": z} for x, y, z in points]


def test_a_traverse_moves_the_rover_and_the_drive_load_follows_the_grade(probe):
    p = probe
    rise = 10.0 * math.tan(math.radians(20.0))  # 3.6397023 m over 10 m: a 20 deg leg
    p.put(keys.clock_control(R), {"time_scale": 50})  # 5 s ticks: 0.5 m each
    e = answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 10, 0), (5, 20, rise)),
                                "speed_m_per_s": 0.1})
    assert e["kind"] == "input" and "2 waypoint(s)" in e["message"], e
    flat = p.wait_value(STATE, lambda s: s["moving"] and s["waypoint"] == 0)
    assert flat["status"] == "driving" and flat["heading_deg"] == 0.0 and flat["grade_deg"] == 0.0
    assert flat["tractive_force_n"] == pytest.approx(3.25)
    assert flat["power_w"] == pytest.approx(FLAT_W) and flat["speed_m_per_s"] == 0.1
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] == pytest.approx(FLAT_W))
    up = p.wait_value(STATE, lambda s: s["waypoint"] == 1)
    assert up["grade_deg"] == pytest.approx(20.0) and up["power_w"] == pytest.approx(UPHILL_W)
    assert up["tractive_force_n"] == pytest.approx(8.6118348)
    assert up["wheel_torque_nm"] == pytest.approx(0.86118348)  # F r, r = 0.1 m
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] == pytest.approx(UPHILL_W))
    rail = p.wait_value(keys.rail_state(R, "12V"), lambda v: v["power_w"] > UPHILL_W)
    assert rail["state"] == "on"
    done = p.wait_value(STATE, lambda s: s["status"] == "arrived", timeout_s=30)
    assert (done["x_m"], done["y_m"], done["z_m"]) == pytest.approx((5.0, 20.0, rise))
    assert done["odometer_m"] == pytest.approx(10.0 + 10.0 / math.cos(math.radians(20.0)))
    assert not done["moving"] and done["waypoint"] is None and done["power_w"] == IDLE_W
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] == IDLE_W)
    # the path went north and up, through both waypoints, never backwards
    ys = [s["y_m"] for s in p.samples(STATE)]
    assert ys == sorted(ys) and len(set(ys)) > 20
    # ... and the dashboard sees it as an Odometry in the site frame (the bridge's json flavour;
    # serving two rovers, the bridge puts each one's topics under /<rover>)
    assert not [k for k in p.latest if k.startswith("json/ltv_1/") and "odom" in k]  # no drive
    odom = p.wait_value("json/mapp_1/odom",
                        lambda m: m["pose"]["pose"]["position"]["y"] == pytest.approx(20.0))
    assert odom["header"]["frame_id"] == "site" and odom["twist"]["twist"]["linear"]["x"] == 0.0


def test_the_radio_link_follows_the_rover_and_flips_at_the_computed_distance(probe):
    p = probe
    link = keys.radio_link(R, "lander")
    assert p.wait_value(link, lambda v: v["x_m"] == 5.0)["in_range"]
    # the position input is refused: the rover's drive says where it is
    e = answer(p, R, keys.input_radio_position(R, "lander"), {"distance_m": 900, "angle_deg": 0})
    assert e["kind"] == "rejected" and "follows the rover's drive" in e["message"]
    p.put(keys.clock_control(R), {"time_scale": 1000})  # 100 s ticks: 10 m each
    answer(p, R, TRAVERSE, {"waypoints": waypoints((600, 0, 0)), "speed_m_per_s": 0.1})
    lost = p.wait_value(link, lambda v: not v["in_range"], timeout_s=30)
    assert 400.0 < lost["x_m"] <= 410.0 and lost["y_m"] == 0.0  # within one tick past 400 m
    assert all(s["x_m"] <= 400.0 for s in p.samples(link) if s["in_range"])
    assert p.value(STATE)["x_m"] >= lost["x_m"]
    answer(p, R, TRAVERSE, None, delete=True)


def test_delete_stops_the_rover_where_it_is(probe):
    p = probe
    p.put(keys.clock_control(R), {"time_scale": 50})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 500, 0))})  # at the rover's max speed
    p.wait_value(STATE, lambda s: s["odometer_m"] > 2.0 and s["speed_m_per_s"] == 0.1)
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] > IDLE_W)
    # a prediction asked while it drives says it takes the traverse as going on (a vehicle
    # engineer found the horizon driven through with nothing said)
    (reply,) = [r for r in p.session.get(f"{keys.prediction(R)}?hours=0.1;samples=10", timeout=30)]
    assert reply.ok is not None, reply.err.payload.to_string()
    notes = json.loads(reply.ok.payload.to_bytes())["notes"]
    assert any("held over the whole horizon: a traverse under way is taken as going on" in n
               for n in notes), notes
    e = answer(p, R, TRAVERSE, None, delete=True)
    assert e["kind"] == "input" and "traverse stopped" in e["message"]
    stopped = p.wait_value(STATE, lambda s: s["status"] == "parked")
    assert not stopped["moving"] and stopped["power_w"] == IDLE_W and stopped["waypoint"] is None
    t = stopped["t_s"]
    later = p.wait_value(STATE, lambda s: s["t_s"] >= t + 20)  # four more ticks
    assert (later["x_m"], later["y_m"], later["odometer_m"]) == (
        stopped["x_m"], stopped["y_m"], stopped["odometer_m"])
    again = answer(p, R, TRAVERSE, None, delete=True)
    assert again["kind"] == "rejected" and "no traverse to stop" in again["message"]


def test_the_crew_stops_the_rover_from_its_dashboard(probe):
    """``/drive/stop`` (``std_srvs/srv/Trigger``, SPEC §12a), here by the bridge's json flavour:
    the traverse stops where the rover is, the call answered success in the drive's words and
    the event saying the crew acted; called again, the drive's refusal as the answer."""
    p = probe
    p.put(keys.clock_control(R), {"time_scale": 50})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 500, 0))})
    p.wait_value(STATE, lambda s: s["odometer_m"] > 2.0 and s["moving"])

    def stop() -> dict:
        replies = [r.ok for r in p.session.get("json/mapp_1/drive/stop", payload=b"{}", timeout=8.0)
                   if r.ok is not None]
        assert len(replies) == 1, "one answer to the crew's call"
        return json.loads(replies[0].payload.to_bytes())
    got = stop()
    assert got["success"] is True and "traverse stopped" in got["message"], got
    assert p.wait_value(STATE, lambda s: s["status"] == "parked")["moving"] is False
    p.wait_event(R, lambda e: e["kind"] == "input" and e["key"] == TRAVERSE and e.get("actor") == "crew")
    again = stop()
    assert again["success"] is False and "no traverse to stop" in again["message"], again


BAD = [
    (b'{"waypoints": []}', "at least one waypoint"),
    (b'{"waypoints": [{"x_m": NaN, "y_m": 0, "z_m": 0}]}', "NaN is not a number"),
    (b'{"waypoints": [{"x_m": 1e999, "y_m": 0, "z_m": 0}]}', "is too large"),
    (b'{"waypoints": [{"x_m": 50, "y_m": 0, "z_m": 0}], "speed_m_per_s": 0.5}',
     "above the rover's max_speed_m_per_s"),
    (b'{"waypoints": [{"x_m": 50, "y_m": 0, "z_m": 0, "speed_m_per_s": 0.3}]}',
     "waypoints[0].speed_m_per_s"),
    (b'{"waypoints": [{"x_m": 6, "y_m": 0, "z_m": 5}]}', "steeper than the rover's max_grade_deg"),
    (b'{"waypoints": [{"x_m": 6, "y_m": 0}]}', "z_m"),
    (b'{"waypoints": [{"x_m": 6, "y_m": 0, "z_m": 0}], "bogus": 1}', "bogus"),
    (b'{"waypoints": [{"x_m": 6, "y_m": 0, "z_m": 0}], "speed_m_per_s": -1}', "speed_m_per_s"),
    (b"5", "5 is not a JSON object"),
    (b"", "the payload is empty"),
]


def test_bad_traverses_are_rejected_and_change_nothing(probe):
    p = probe
    p.put(keys.clock_control(R), {"time_scale": 20})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 300, 0))})
    p.wait_value(STATE, lambda s: s["moving"])
    p.put(keys.clock_control(R), {"paused": True})  # nothing moves while the bad ones arrive
    paused = p.wait_value(keys.clock(R), lambda c: c["paused"])
    before = p.wait_value(STATE, lambda s: s["t_s"] == paused["t_s"])
    for payload, reason in BAD:
        e = answer(p, R, TRAVERSE, payload)
        assert e["kind"] == "rejected" and reason in e["message"], (payload, e)
        assert e["severity"] == "warning" and e["message"].startswith("rejected: ")
    e = answer(p, NO_DRIVE, keys.input_drive_traverse(NO_DRIVE), {"waypoints": waypoints((1, 1, 0))})
    assert e["kind"] == "rejected" and "has no drive section" in e["message"], e
    assert e["source"] == "faults"
    seq = p.value(keys.clock(R))["seq"]
    p.wait_value(keys.clock(R), lambda c: c["seq"] >= seq + 3)
    p.wait_value(STATE, lambda s: s["t_s"] == paused["t_s"] and p.value(keys.clock(R))["seq"] > seq)
    after = p.value(STATE)
    assert after == before  # the same traverse, from the same place, to the same waypoint
    assert NO_DRIVE not in {k.split("/")[1] for k in p.latest if k.endswith("/drive/state")}
    p.put(keys.clock_control(R), {"paused": False})
    p.wait_value(STATE, lambda s: s["odometer_m"] > before["odometer_m"])


def test_an_unpowered_drive_halts_the_rover_until_its_power_returns(probe):
    p = probe
    p.put(keys.clock_control(R), {"time_scale": 50})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 500, 0))})
    p.wait_value(STATE, lambda s: s["moving"] and s["odometer_m"] > 1.0)
    p.put(keys.fault(R, "load/drive_motors", "open"), b"")
    halted = p.wait_value(STATE, lambda s: s["status"] == "unpowered")
    assert not halted["moving"] and halted["speed_m_per_s"] == 0.0 and halted["waypoint"] == 0
    t = halted["t_s"]
    still = p.wait_value(STATE, lambda s: s["t_s"] >= t + 20)
    assert still["odometer_m"] == halted["odometer_m"]
    p.delete(keys.fault(R, "load/drive_motors", "open"))
    p.wait_value(STATE, lambda s: s["moving"] and s["odometer_m"] > halted["odometer_m"])


def test_reset_and_a_restarted_drive_service(probe, twin):
    p, t = probe, twin[1]
    p.put(keys.clock_control(R), {"time_scale": 50})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 500, 0))})
    moving = p.wait_value(STATE, lambda s: s["odometer_m"] > 2.0)
    # a restarted drive service resumes the traverse where it was (its state is kept on disk)
    stop_process(t.procs["drive"])
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > moving["t_s"] + 20)
    t.start("drive")
    resumed = p.wait_value(STATE, lambda s: s["t_s"] > moving["t_s"] + 20 and s["moving"], timeout_s=30)
    assert resumed["odometer_m"] >= moving["odometer_m"] and resumed["waypoint"] == 0
    # a session reset puts the rover back at its start, parked, the radio with it
    epoch = p.value(keys.clock(R))["epoch"]
    seen = len(p.samples(STATE))
    p.put(keys.control_reset(R), b"")
    p.wait_value(keys.clock(R), lambda c: c["epoch"] > epoch)
    # the first state parked at the start (the latest may be a tick later, its idle draw counted:
    # a loaded run read 0.3 J so)
    back = wait_for(lambda: next((s for s in p.samples(STATE)[seen:]
                                  if s["status"] == "parked" and s["odometer_m"] == 0.0), None),
                    10, "the drive parked at its start")
    assert (back["x_m"], back["y_m"], back["z_m"]) == START and back["energy_j"] == 0.0
    p.wait_value(keys.radio_link(R, "lander"), lambda v: v["x_m"] == 5.0 and v["in_range"])


def _up_lines(rover_file, until: str) -> str:
    """Run ``lunaris up`` with the clock and the drive until a line holds ``until``."""
    up = subprocess.Popen(lunaris_cmd("up", "--rover", str(rover_file), "--listen", free_endpoint(),
                                      "--no-status", "--services", "clock,drive"),
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    lines: list[str] = []
    try:
        def seen() -> bool:
            line = up.stdout.readline()
            lines.append(line)
            return until in line or not line
        wait_for(seen, 30, f"lunaris up to say {until!r}")
    finally:
        stop_process(up, timeout_s=15)
    return "".join(lines) + (up.stdout.read() or "")


def test_lunaris_up_starts_the_drive_only_for_rovers_that_drive(tmp_path):
    static = rover_without_drive(ROVERS / "mapp.yaml", tmp_path)
    done = subprocess.run(lunaris_cmd("run", "drive", "--rover", str(static), "--connect",
                                      free_endpoint()),
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 0 and "no rover to serve" in done.stdout
    out = _up_lines(static, "clock started")
    assert "drive not started: no rover needs it" in out and "drive started" not in out
    out = _up_lines(ROVERS / "mapp.yaml", "drive started")
    assert "drive started" in out and "not started" not in out


def _tool(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(lunaris_cmd(*args), capture_output=True, text=True, timeout=60, cwd=ROOT,
                          env=env_without_zenoh_config())


def test_lunaris_traverse_sends_stops_and_reports_the_answer(probe, twin):
    p, ep = probe, twin[1].endpoint
    done = _tool("traverse", R, "--to", "5", "30", "0", "--speed", "0.05", "--connect", ep)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("accepted: input") and "1 waypoint(s), 30.0 m" in done.stdout
    p.wait_value(STATE, lambda s: s["moving"] and s["speed_m_per_s"] == 0.05)
    done = _tool("traverse", R, "--stop", "--connect", ep)
    assert done.returncode == 0 and "traverse stopped" in done.stdout, done.stdout + done.stderr
    done = _tool("traverse", R, "--to", "5", "30", "20", "--connect", ep)
    assert done.returncode == 1 and "rejected" in done.stdout and "steeper" in done.stdout
    done = _tool("traverse", R, str(ROOT / "config" / "traverses" / "mapp-crater-rim.yaml"),
                 "--connect", ep)
    assert done.returncode == 0 and "8 waypoint(s)" in done.stdout, done.stdout + done.stderr
    done = _tool("traverse", NO_DRIVE, "--to", "1", "1", "0", "--connect", ep)
    assert done.returncode == 1 and "has no drive section" in done.stdout
    done = _tool("traverse", R, str(ROOT / "no-such.yaml"), "--connect", ep)
    assert done.returncode == 1 and "cannot read file" in done.stderr


def test_a_scenario_drives_and_stops_the_rover_on_a_drive_condition(probe, twin, tmp_path):
    ep = twin[1].endpoint
    path = tmp_path / "drive.yaml"
    path.write_text("""
scenario: {name: drive and stop}
rover: mapp-1
time_scale: 50
steps:
  - name: go north
    at_s: 0
    traverse: {speed_m_per_s: 0.1, waypoints: [{x_m: 5, y_m: 50, z_m: 0}]}
  - name: far enough
    when: drive.odometer_m > 2
    timeout_s: 300
    traverse: stop
  - name: parked
    after_s: 0
    when: drive.status == parked
    timeout_s: 60
    note: stopped
""")
    summary_path = tmp_path / "summary.json"
    done = _tool("scenario", "run", str(path), "--connect", ep, "--json-summary", str(summary_path))
    assert done.returncode == 0, done.stdout + done.stderr
    steps = json.loads(summary_path.read_text())["steps"]
    assert [(s["status"], s["outcome"]) for s in steps] == [
        ("fired", "accepted"), ("fired", "accepted"), ("fired", "reached")]
    state = probe.wait_value(STATE, lambda s: s["status"] == "parked")
    assert 2.0 < state["odometer_m"] < 10.0


def test_a_snapshot_restores_the_position_and_the_traverse(probe):
    p = probe
    p.put(keys.clock_control(R), {"time_scale": 50})
    answer(p, R, TRAVERSE, {"waypoints": waypoints((5, 500, 0), (5, 600, 0))})
    p.wait_value(STATE, lambda s: s["odometer_m"] > 2.0)
    p.put(keys.clock_control(R), {"paused": True})
    paused = p.wait_value(keys.clock(R), lambda c: c["paused"])
    saved = p.wait_value(STATE, lambda s: s["t_s"] == paused["t_s"])
    p.put(keys.control_snapshot(R, "mid-traverse"), b"")
    p.wait_event(R, lambda e: e["kind"] == "session" and "mid-traverse" in e["message"])
    wait_for(lambda: any(s["name"] == "mid-traverse" and "drive" in s["services"]
                         for (got,) in [p.get_json(keys.snapshots(R))] for s in got), 5, "the snapshot")
    p.put(keys.clock_control(R), {"paused": False})
    answer(p, R, TRAVERSE, None, delete=True)  # stopped, then the snapshot brings the traverse back
    p.wait_value(STATE, lambda s: s["status"] == "parked")
    p.put(keys.control_restore(R, "mid-traverse"), b"")
    back = p.wait_value(STATE, lambda s: s["status"] == "driving" and s["t_s"] == saved["t_s"])
    assert (back["x_m"], back["y_m"], back["odometer_m"], back["waypoint"], back["waypoints"]) == (
        saved["x_m"], saved["y_m"], saved["odometer_m"], 0, 2)
    p.put(keys.clock_control(R), {"paused": False})
    p.wait_value(STATE, lambda s: s["odometer_m"] > saved["odometer_m"])


def test_a_map_reads_the_twins_own_numbers(probe):
    """Issue 26.3: what a map draws, from the twin's keys (figures from the rover files)."""
    p = probe
    # the cut-off in numbers: MAPP 4 cells x 3.2 V; empty at 0 % charge
    battery = p.wait_value(keys.battery_state(R), lambda b: "cutoff_v" in b)
    assert battery["depleted_soc"] == 0.0 and battery["cutoff_v"] == pytest.approx(12.8)
    # the radios: where they stand, their nominal footprints, whether the drive moves them
    link = p.wait_value(keys.radio_link(R, "lander"), lambda v: "site" in v)
    assert (link["site"], link["a_m"], link["b_m"], link["offset_x_m"], link["offset_y_m"],
            link["follows_drive"]) == ({"x_m": 0.0, "y_m": 0.0}, 400.0, 250.0, 0.0, 0.0, True)
    relay = p.wait_value(keys.radio_link(NO_DRIVE, "hls_relay"), lambda v: "site" in v)
    assert (relay["site"], relay["a_m"], relay["b_m"], relay["offset_x_m"], relay["offset_y_m"],
            relay["follows_drive"]) == ({"x_m": -1500.0, "y_m": 1000.0}, 4000.0, 4000.0, 2500.0,
                                        -1500.0, False)
    # a degraded radio keeps its nominal footprint in what the crew reads
    degraded = keys.fault(R, "radio/lander", "degraded")
    seen = len(p.samples(keys.radio_link(R, "lander")))
    p.put(degraded, 0.5)
    p.wait_event(R, lambda e: e["key"] == degraded and e["kind"] == "fault_injected")
    wait_for(lambda: len(p.samples(keys.radio_link(R, "lander"))) > seen + 1, 5, "link samples")
    after = p.samples(keys.radio_link(R, "lander"))[seen:]
    assert {(s["a_m"], s["b_m"]) for s in after} == {(400.0, 250.0)}
    p.delete(degraded)
    # the umbilical: its cable, and where it was plugged in while it is
    cable = p.wait_value(keys.umbilical_state(R))
    assert (cable["connected"], cable["plugged_at"], cable["cable_m"]) == (False, None, 10.0)
    p.put(keys.input_umbilical(R), True)
    plugged = p.wait_value(keys.umbilical_state(R), lambda u: u["connected"])
    assert plugged["plugged_at"] == {"x_m": 5.0, "y_m": 0.0, "z_m": 0.0}
    p.put(keys.input_umbilical(R), False)
    p.wait_value(keys.umbilical_state(R), lambda u: u["plugged_at"] is None)
    # the route: empty when parked, the traverse as sent once accepted, empty again when stopped
    route = keys.drive_route(R)
    parked = p.wait_value(route)  # (read once: a later sample has another t_s)
    assert {k: v for k, v in parked.items() if k != "t_s"} == {"start": None, "waypoints": [],
                                                                "return_to_start": False}
    sent = [{"x_m": 5.0, "y_m": 10.0, "z_m": 0.0},
            {"x_m": 5.0, "y_m": 20.0, "z_m": 0.0, "speed_m_per_s": 0.05}]
    assert answer(p, R, TRAVERSE, {"waypoints": sent, "return_to_start": True})["kind"] == "input"
    driven = p.wait_value(route, lambda r: r["waypoints"])
    expected = {"start": {"x_m": 5.0, "y_m": 0.0, "z_m": 0.0}, "return_to_start": True,
                "waypoints": [{**sent[0], "speed_m_per_s": 0.1}, sent[1]]}  # 0.1: the max
    assert {k: v for k, v in driven.items() if k != "t_s"} == expected
    ticks = len(p.samples(STATE))
    wait_for(lambda: len(p.samples(STATE)) > ticks + 10, 10, "ten drive/state ticks")
    assert len(p.samples(route)) <= 3  # on change only: the reset's, the traverse's
    late = Mirror(R, families=["drive/route"], events=False).start(p.session)  # joins late
    try:
        wait_for(lambda: late.value(route) is not None, 5, "the cached route")
        assert late.value(route).waypoints[1].speed_m_per_s == 0.05
    finally:
        late.close()
    answer(p, R, TRAVERSE, None, delete=True)
    assert p.wait_value(route, lambda r: not r["waypoints"])["start"] is None
