"""``lunaris record`` and ``lunaris report`` against a running twin."""

from __future__ import annotations

import json
import re
import signal
import subprocess
from pathlib import Path

import msgspec
import pytest
from mcap.reader import make_reader

from common import keys
from tests.harness import ROOT, env_without_zenoh_config, lunaris_cmd, wait_for
from tests.lunaris.conftest import R, run_tool

pytestmark = pytest.mark.timeout(90)

FAMILY_SCHEMA = {
    "clock": "lunaris.Clock", "battery/state": "lunaris.BatteryState",
    "power/summary": "lunaris.PowerSummary", "umbilical/state": "lunaris.UmbilicalState",
    "event": "lunaris.Event",
}
LOADS = ["drive_motors", "survival_heater", "flight_computer", "uhf_radio", "nav_camera", "hazard_cameras",
         "imu", "sun_sensor", "nir_spectrometer", "thermal_imager"]
RAILS = ["12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2", "SOLAR"]


def _start_recorder(path: Path, *args: str) -> subprocess.Popen:
    proc = subprocess.Popen(lunaris_cmd("record", str(path), *args), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env_without_zenoh_config())
    line = proc.stderr.readline()  # printed once the subscription is declared
    assert line.startswith("recording lunaris/"), line + proc.stderr.read()
    return proc


def _read(path: Path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = [(ch.topic, schema.name, msg) for schema, ch, msg in reader.iter_messages()]
    return summary, messages


def test_a_session_recorded_to_mcap_reads_back_and_renders(live, tmp_path):
    p, ep = live.probe, live.endpoint
    path = tmp_path / "session.mcap"
    rec = _start_recorder(path, "--connect", ep)
    try:
        t_start = p.wait_value(keys.clock(R))["t_s"]
        assert run_tool("fault", "inject", R, "load/imu", "stuck", "1.4", "--connect", ep).returncode == 0
        p.put(keys.input_sun_angle(R), 55)
        assert run_tool("fault", "clear", R, "load/imu", "stuck", "--connect", ep).returncode == 0
        p.put(keys.input_sun_angle(R), 60)
        p.wait_value(keys.clock(R), lambda c: c["t_s"] >= t_start + 2.0)  # two seconds of telemetry
    finally:
        rec.send_signal(signal.SIGINT)
        out, err = rec.communicate(timeout=20)
    assert rec.returncode == 0, err
    assert not (tmp_path / "session.mcap.part").exists()

    summary, messages = _read(path)
    stats = summary.statistics
    assert f"wrote {path}: {stats.message_count} messages on {len(summary.channels)} channels" in out
    topics = {c.topic: c for c in summary.channels.values()}
    prefix = f"lunaris/{R}/"
    expected = {prefix + f for f in FAMILY_SCHEMA}
    expected |= {prefix + f"load/{n}/power" for n in LOADS} | {prefix + f"rail/{n}/state" for n in RAILS}
    expected |= {prefix + f"solar/{n}/power" for n in ("left", "right")}
    expected |= {prefix + "radio/lander/link", prefix + "fault/load/imu/stuck", prefix + "input/sun_angle"}
    assert expected <= set(topics), sorted(expected - set(topics))
    schema_of = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    for family, name in FAMILY_SCHEMA.items():
        assert schema_of[prefix + family].name == name
    assert schema_of[prefix + "rail/5V_CH2/state"].name == "lunaris.RailState"
    assert schema_of[prefix + "load/imu/power"].name == "lunaris.LoadPower"
    assert schema_of[prefix + "fault/load/imu/stuck"].name == "lunaris.KeyWrite"
    for channel in summary.channels.values():
        assert channel.message_encoding == "json" and schema_of[channel.topic].encoding == "jsonschema"

    counted: dict[str, int] = {}
    for topic, _, _ in messages:
        counted[topic] = counted.get(topic, 0) + 1
    assert sum(counted.values()) == stats.message_count
    assert {topics[t].id: n for t, n in counted.items()} == dict(stats.channel_message_counts)
    assert counted[prefix + "clock"] >= 15  # 10 Hz for two seconds and more
    assert counted[prefix + "battery/state"] >= 15 and counted[prefix + "load/nav_camera/power"] >= 15

    fault = [msgspec.json.decode(m.data) for t, _, m in messages if t == prefix + "fault/load/imu/stuck"]
    # checked, and sent as the Struct
    assert [(f["op"], f["value"]) for f in fault] == [("put", {"power_w": 1.4}), ("delete", None)]
    sun = [msgspec.json.decode(m.data)["value"] for t, _, m in messages if t == prefix + "input/sun_angle"]
    assert sun == [55, 60]
    events = [msgspec.json.decode(m.data) for t, _, m in messages if t == prefix + "event"]
    kinds = [(e["kind"], e["key"]) for e in events]
    assert ("fault_injected", prefix + "fault/load/imu/stuck") in kinds
    assert ("fault_cleared", prefix + "fault/load/imu/stuck") in kinds
    clocks = [(m.publish_time, msgspec.json.decode(m.data)["t_s"], m.log_time)
              for t, _, m in messages if t == prefix + "clock"]
    assert all(pt == round(t_s * 1e9) for pt, t_s, _ in clocks)  # publish_time: sim time
    assert [lt for _, _, lt in clocks] == sorted(lt for _, _, lt in clocks)  # log_time: wall, in order
    assert clocks[-1][2] - clocks[0][2] >= 1.5e9

    png = tmp_path / "debrief.png"
    done = run_tool("report", str(path), "-o", str(png))
    assert done.returncode == 0, done.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    assert f"wrote {png}: {R}," in done.stdout and "10 loads" in done.stdout
    page = tmp_path / "debrief.html"
    assert run_tool("report", str(path), "-o", str(page)).returncode == 0
    text = page.read_text()
    assert "data:image/png;base64," in text and "<td>fault injected</td>" in text
    assert "Load imu: Stuck power draw (power drawn 1.4 W)" in text


def test_recording_stops_after_its_duration_and_on_sigterm(live, tmp_path):
    done = run_tool("record", str(tmp_path / "a.mcap"), "--duration", "1", "--rover", R,
                    "--connect", live.endpoint)
    assert done.returncode == 0, done.stderr
    summary, messages = _read(tmp_path / "a.mcap")
    assert summary.statistics.message_count == len(messages) > 0
    assert all(c.topic.startswith(f"lunaris/{R}/") for c in summary.channels.values())

    rec = _start_recorder(tmp_path / "b.mcap", "--connect", live.endpoint, "--progress", "0.2")
    progress = rec.stderr.readline()  # a progress line a fifth of a second later
    while not re.match(r"recording: [1-9]\d* messages on [1-9]\d* channels", progress):
        progress = rec.stderr.readline()
        assert progress, "the recorder stopped"
    rec.send_signal(signal.SIGTERM)
    out, err = rec.communicate(timeout=20)
    assert rec.returncode == 0, err
    assert "wrote" in out and _read(tmp_path / "b.mcap")[0].statistics is not None


def test_clear_errors(tmp_path, live):
    existing = tmp_path / "x.mcap"
    existing.write_bytes(b"")
    done = run_tool("record", str(existing), "--connect", live.endpoint)
    assert done.returncode == 2 and "exists; use --force" in done.stderr
    done = run_tool("record", str(tmp_path / "no" / "x.mcap"), "--connect", live.endpoint)
    assert done.returncode == 2 and "does not exist" in done.stderr
    done = run_tool("report", str(tmp_path / "missing.mcap"))
    assert done.returncode == 2 and "does not exist" in done.stderr
    (tmp_path / "junk.mcap").write_text(json.dumps({"not": "mcap"}))
    done = run_tool("report", str(tmp_path / "junk.mcap"))
    assert done.returncode == 2 and "is not a readable MCAP file" in done.stderr
    done = run_tool("report", str(existing), "-o", str(tmp_path / "out.pdf"))
    assert done.returncode == 2 and "must end in .png or .html" in done.stderr


def test_a_recorder_killed_leaves_a_file_that_opens_with_all_but_its_last_second(live, tmp_path):
    """SPEC 13e: a recording loses at most the last second and always opens. Its chunk is
    closed and synced once a second: before, a recorder killed with kill -9 left only what
    filled its 1 MB chunks (minutes of a rover), the rest lost."""
    from lunaris.record import read_messages
    p = live.probe
    path = tmp_path / "killed.mcap"
    part = path.with_name(path.name + ".part")
    rec = _start_recorder(path, "--connect", live.endpoint, "--rover", R)
    try:
        clock_key = f"lunaris/{R}/clock"
        t0 = p.wait_value(clock_key)["t_s"]
        p.wait_value(clock_key, lambda c: c["t_s"] >= t0 + 2.0, timeout_s=30)

        def clock_times() -> list[float]:
            return [json.loads(bytes(data))["t_s"] for topic, data in read_messages(part)
                    if topic == clock_key]
        def flushed() -> bool:  # (an empty file, before the first flush, is no MCAP yet)
            try:
                return any(t >= t0 + 2.0 for t in clock_times())
            except ValueError:
                return False
        # the recorder's file holds the clock of 2 s after its start, flushed as it goes
        wait_for(flushed, 30, "the clock in the file written")
    finally:
        rec.kill()
        rec.wait(20)
    assert not path.exists() and part.exists()
    times = clock_times()  # the file as the kill left it: it opens, whole as far as it goes
    assert times and max(times) >= t0 + 2.0, times
