"""``lunaris report`` of the crew's response (SPEC 12d) from recordings made without a twin: two
sessions in one recording, each reported without anything of the other; ``--json``,
``--session``, the score sheet drawn and tabled."""

from __future__ import annotations

import io
import itertools
import json
from pathlib import Path

import msgspec
import pytest

from common.messages import BatteryState, Clock, Event, LoadPower, RailState, encode
from lunaris.record import Recorder, read_messages
from lunaris.report import load_recording
from tests.lunaris.conftest import run_tool

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
P = f"lunaris/{R}/"
WALL = 1_700_000_000_000_000_000


class Tape:
    """A recording made by hand: samples in the order a recorder would receive them."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, bytes, bool, int]] = []
        self.seq = itertools.count(1)

    def put(self, key: str, payload: bytes) -> None:
        self.samples.append((P + key, payload, False, WALL + len(self.samples)))

    def tick(self, t: float, epoch: int, *, camera_w: float = 3.5, rail: str = "on",
             temperature_c: float = 20.0) -> None:
        session = S2 if epoch else S1
        self.put("clock", encode(Clock(t, 0.1, 0, 1.0, False, epoch, "reset" if epoch else "", session)))
        self.put("battery/state", encode(BatteryState(t, 5e5, 5.3e5, 0.9, 16.6, 16.5, 2.0, 33.0,
                                                      temperature_c, True, 0, [], 3600.0)))
        self.put("load/nav_camera/power", encode(LoadPower(t, camera_w, "5V_CH2", rail == "on", [])))
        self.put("rail/5V_CH2/state", encode(RailState(t, 5.0, 1.0, 5.0, 5.0, rail)))  # type: ignore[arg-type]

    def event(self, t: float, kind: str, key: str, *, actor: str = "instructor", params=None,
              message: str = "", session: str = "", source: str = "power") -> None:
        ev = Event(t_s=t, severity="info", source=source, kind=kind, key=P + key,
                   message=message or kind, params=params, source_id="abc", seq=next(self.seq),
                   actor=actor)
        raw = msgspec.to_builtins(ev) | ({"session": session} if session else {})
        data = msgspec.json.encode(raw)
        self.put(f"event/{source}", data)  # heard twice: the service's key and the journal's
        self.put("event", data)

    def write(self, path: Path) -> Path:
        buf = io.BytesIO()
        rec = Recorder(buf, "test")
        for s in self.samples:
            assert rec.write(*s)
        rec.finish()
        path.write_bytes(buf.getvalue())
        return path


S1, S2 = "20261125-090000", "20261125-100000"  # the clock's session ids (UTC, growing)


def _opened(sid: str, trainee: str, t: float) -> dict:
    """The params of the clock's event that opens a session (SPEC 12c)."""
    return {"session": sid, "trainee": trainee, "from_snapshot": None, "started_wall": 1.7e9,
            "start_t_s": t}


def two_trainees(tape: Tape) -> None:
    """Trainee 1: a short on the navigation camera (0.05 ohm), the crew safes 5V_CH2.
    Trainee 2 (a new session, begun by the clock): the pack heating, a scenario's expectation
    met. The crew's and some of the twin's events carry no session (a service that had heard no
    tick yet): the running session's."""
    s1, s2 = S1, S2
    tape.event(0.0, "session", "control/session", params=_opened(s1, "Ada", 0.0), session=s1, source="clock")
    for i in range(300):
        tape.tick(round(i * 0.1, 3), 0)
    tape.event(30.0, "fault_injected", "fault/load/nav_camera/short", params={"resistance_ohm": 0.05},
               session=s1)
    tape.tick(30.0, 0, camera_w=500.0, rail="tripped")
    tape.event(30.0, "fault_raised", "rail/5V_CH2/tripped", actor="twin", session=s1)
    for i in range(1, 100):
        tape.tick(round(30 + i * 0.1, 3), 0, camera_w=0.0, rail="tripped")
    tape.event(40.0, "command", "cmd/rail/5V_CH2", actor="crew", params={"on": False, "reset": False},
               message="rail 5V_CH2: on=false; the rail is now tripped")
    tape.event(41.0, "rejected", "cmd/rail/5V_CH9", actor="crew",
               message="rejected: rover mapp-1 has no rail '5V_CH9'")
    tape.event(42.0, "command", "cmd/rail/5V_CH2", actor="crew", params={"on": None, "reset": True},
               message="rail 5V_CH2: reset; the rail is now off")
    tape.event(42.0, "fault_resolved", "rail/5V_CH2/tripped", actor="twin", session=s1)
    tape.tick(42.1, 0, camera_w=0.0, rail="off")
    # the next trainee: the clock closes the session, its first tick, the event that opens it
    tape.event(42.5, "session", "sessions", params={"session": s1, "trainee": "Ada", "end_t_s": 42.5},
               session=s1)
    tape.tick(0.0, 1)
    tape.event(0.0, "session", "control/session", params=_opened(s2, "Bob", 0.0), session=s2, source="clock")
    tape.event(0.0, "fault_cleared", "fault/load/nav_camera/short", session=s1)  # the end's, late
    for i in range(1, 200):
        tape.tick(round(i * 0.1, 3), 1)
    tape.event(20.0, "fault_injected", "fault/battery/heating", actor="scenario", params={"heat_w": 45},
               session=s2)
    for i in range(200):
        t = round(20 + i * 0.1, 3)
        tape.tick(t, 1, temperature_c=20.0 + 0.05 * (t - 20.0))
    tape.event(30.0, "command", "cmd/rail/12V", actor="crew", params={"on": False, "reset": False},
               message="rail 12V: on=false; the rail is now off")
    tape.event(31.0, "scenario", "control/scenario", actor="scenario", session=s2, params={
        "scenario": "heater", "what": "expect", "step": 3, "expectation": {
            "index": 2, "label": "isolate the heater", "condition": "rail.12V.state == off",
            "within_s": 600.0, "met": True, "at_t_s": 30.1, "armed_t_s": 20.0, "start_t_s": 0.0}})
    tape.event(32.0, "fault_cleared", "fault/battery/heating", actor="scenario", session=s2)


def _report(path: Path, *args: str) -> list[dict]:
    done = run_tool("report", str(path), "--json", *args)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_two_trainees_in_one_recording_each_reported_with_nothing_of_the_other(tmp_path):
    tape = Tape()
    two_trainees(tape)
    path = tape.write(tmp_path / "day.mcap")
    first, second = _report(path)
    assert [first["session"], second["session"]] == [S1, S2]
    assert (first["trainee"], second["trainee"]) == ("Ada", "Bob")

    (short,) = first["faults"]
    assert short["key"] == P + "fault/load/nav_camera/short"
    assert (short["injected_t_s"], short["first_symptom_t_s"], short["first_crew_action_t_s"]) == (
        30.0, 30.0, 40.0)
    assert short["resolved_t_s"] is None  # the rail was off, not on, when the session ended
    assert [(a["t_s"], a["action"], a["target"], a["accepted"]) for a in short["crew_actions"]] == [
        (40.0, "rail off", "5V_CH2", True),  # (41.0: a refused command to 5V_CH9, not the short's)
        (42.0, "rail reset", "5V_CH2", True)]
    assert first["expectations"] == []

    (heating,) = second["faults"]
    assert heating["key"] == P + "fault/battery/heating" and heating["injected_by"] == "scenario"
    # 0.05 C/s from 20 C: 0.2 C above the band after 4 s
    assert heating["first_symptom_t_s"] == pytest.approx(24.1, abs=0.15)
    # the 12 V rail is nothing the pack's heating touches (SPEC 13a): no action on it, though the
    # drill's own expectation (below) scores the rail's switching off
    assert heating["first_crew_action_t_s"] is None and heating["resolved_t_s"] == 32.0
    assert heating["crew_actions"] == [] and heating["response_s"] is None
    (expect,) = second["expectations"]
    assert (expect["label"], expect["met"], expect["at_t_s"], expect["within_s"]) == (
        "isolate the heater", True, 30.1, 600.0)
    text = json.dumps(second)
    assert "nav_camera" not in text and "5V_CH" not in text  # nothing of the first trainee's

    (only,) = _report(path, "--session", second["session"])
    assert only == second
    done = run_tool("report", str(path), "--json", "--session", "nope")
    assert done.returncode == 2 and "no session 'nope'" in done.stderr and second["session"] in done.stderr


def test_the_score_sheet_is_drawn_under_the_timeline_and_tabled_in_the_page(tmp_path):
    tape = Tape()
    two_trainees(tape)
    path = tape.write(tmp_path / "day.mcap")
    recs = load_recording(path)
    one, two = recs[R].sessions.values()
    assert one.score is not None and [f.fault for f in one.score.faults] == ["load/nav_camera/short"]
    assert two.score is not None and [f.fault for f in two.score.faults] == ["battery/heating"]
    assert all("nav_camera" not in e.get("key", "") for e in two.events)

    page = tmp_path / "second.html"
    done = run_tool("report", str(path), "-o", str(page))
    assert done.returncode == 0, done.stderr
    assert f"session {S2} (1 other session(s) in the recording)" in done.stdout
    assert "1 fault(s), 1 of 1 expectation(s) met" in done.stdout
    html = page.read_text()
    assert f"The crew's response: Bob's session <small>({S2})</small>" in html
    assert "It began at 2023-11-14 22:13:20 UTC." in html  # its wall-clock start beside its times
    assert "Battery: Overheating" in html
    assert "isolate the heater" in html
    assert "met at 30.1" in html and "nav_camera" not in html
    assert "<td>no response</td>" in html  # the heating: no crew action on what it touches
    # every trainee's report a link away, and who acted in the events (found by an instructor:
    # only the last session's report could be opened from the console, and the crew's actions
    # read like the instructor's)
    assert f'<a href="?session={S1}">Ada - session {S1}</a>' in html
    assert f"<b>Bob - session {S2} (this report)</b>" in html
    assert "<td>crew</td><td>command</td>" in html and "<td>the drill</td><td>fault injected</td>" in html
    png = tmp_path / "first.png"
    done = run_tool("report", str(path), "--session", S1, "-o", str(png))
    assert done.returncode == 0 and png.read_bytes()[:4] == b"\x89PNG"
    assert "1 fault(s), 0 of 0 expectation(s) met" in done.stdout

    from lunaris.report_draw import draw
    fig = draw(one, "first")
    sheet = fig.axes[1]
    assert sheet.get_title(loc="left") == "the crew's response: 1 fault(s); 0 of 0 expectation(s) met"
    assert [t.get_text() for t in sheet.get_yticklabels()] == ["Load nav camera: Short circuit"]
    assert any("(2 action(s))" in t.get_text() for t in sheet.texts)  # (not 5V_CH9: another rail)


def test_a_recording_is_read_fast_and_whole_and_a_cut_one_as_far_as_it_goes(tmp_path):
    tape = Tape()
    two_trainees(tape)
    path = tape.write(tmp_path / "day.mcap")
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        expected = [(c.topic, m.data) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert [(t, bytes(d)) for t, d in read_messages(path)] == expected
    with open(path, "rb") as f:  # a service's own event key is recorded as an event
        summary = make_reader(f).get_summary()
    schema = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schema[P + "event/power"] == schema[P + "event"] == "lunaris.Event"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 4])  # inside its chunk
    assert len(list(read_messages(cut))) < len(expected)
    (tmp_path / "junk.mcap").write_text("not mcap")
    with pytest.raises(ValueError, match="not an MCAP file"):
        list(read_messages(tmp_path / "junk.mcap"))


def test_the_json_gives_times_without_float_noise(tmp_path):
    """Sim times add a tenth of a second at a time: 30.100000000000158 is said 30.1."""
    tape = Tape()
    t = 0.0
    for _ in range(301):
        tape.tick(t, 0)
        t += 0.1
    assert t != round(t, 6)  # the noise the twin's clock has
    tape.event(t, "fault_injected", "fault/load/nav_camera/short", params={"resistance_ohm": 0.05},
               session=S1, source="loads")
    tape.tick(t, 0)
    (only,) = _report(tape.write(tmp_path / "noise.mcap"))
    (fault,) = only["faults"]
    assert fault["injected_t_s"] == round(t, 6) == 30.1
