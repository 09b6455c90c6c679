"""Recording and reporting without a twin: key families, schemas, the MCAP layout, the plots."""

from __future__ import annotations

import io
import json
from pathlib import Path

import msgspec
import pytest
from mcap.reader import make_reader

from common import keys
from common.messages import (
    BatteryState,
    Clock,
    DriveState,
    Event,
    LoadPower,
    PowerSummary,
    RadioLink,
    RailState,
    SolarPower,
    UmbilicalState,
    encode,
)
from lunaris.record import ENVELOPE, KeyWrite, Recorder, json_schema, schema_for
from lunaris.report import add_thresholds, draw, load_recording, load_session, place_labels

R = "mapp-1"


@pytest.mark.parametrize("parts, family", [
    (["clock"], "clock"),
    (["battery", "state"], "battery/state"),
    (["load", "nav_camera", "power"], "load/*/power"),
    (["rail", "5V_CH2", "state"], "rail/*/state"),
    (["power", "summary"], "power/summary"),
    (["solar", "left", "power"], "solar/*/power"),
    (["umbilical", "state"], "umbilical/state"),
    (["radio", "lander", "link"], "radio/*/link"),
    (["drive", "state"], "drive/state"),
    (["input", "drive", "traverse"], None),
    (["event"], "event"),
    (["clock", "control"], None),
    (["fault", "battery", "heating"], None),
    (["input", "sun_angle"], None),
    (["cmd", "rail", "12V"], None),
    (["load", "a", "b", "power"], None),
])
def test_every_key_has_one_family_or_none(parts, family):
    fam = keys.telemetry_family(parts)
    assert (fam.name if fam else None) == family


@pytest.mark.parametrize("family, struct", [(f.name, f.payload) for f in keys.families("out")])
def test_a_family_schema_is_the_struct_at_the_root(family, struct):
    schema = json_schema(struct)
    assert "$ref" not in schema and schema["type"] == "object" and schema["title"] == struct.__name__
    fields = {f.name for f in msgspec.structs.fields(struct)}
    assert set(schema["properties"]) == fields
    assert set(schema["required"]) <= fields and "t_s" in schema["required"]
    assert schema_for(family.replace("*", "x").split("/"))[0] == f"lunaris.{struct.__name__}"
    json.dumps(schema)  # plain JSON, as written into the file


def test_keys_without_a_struct_share_the_envelope_schema():
    name, schema = schema_for(["fault", "load", "nav_camera", "short"])
    assert name == ENVELOPE
    assert set(schema["properties"]) == {"t_s", "op", "value", "text"}
    assert schema["properties"]["op"] == {"enum": ["delete", "put"]}


def _samples() -> list[tuple[str, bytes, bool, int]]:
    wall = 1_700_000_000_000_000_000
    out = []
    for i in range(5):
        t = 10.0 + i
        out += [
            (f"lunaris/{R}/clock", encode(Clock(t, 0.1, i, 1.0, False)), False, wall + i),
            (f"lunaris/{R}/battery/state", encode(BatteryState(
                t, 5e5 - i * 100, 5.3e5, 0.95 - 0.01 * i, 16.6, 16.5, 2.0 + i, 33.0, 20.0 + i, True, 0, [],
                3600.0)), False, wall + i),
            (f"lunaris/{R}/load/imu/power", encode(LoadPower(t, 1.0, "3V3_CH1", True, [])), False, wall + i),
            (f"lunaris/{R}/load/nav_camera/power", encode(LoadPower(t, 3.5, "5V_CH2", True, [])), False,
             wall + i),
            (f"lunaris/{R}/rail/12V/state", encode(RailState(t, 12.0, 4.0, 48.0, 10.0, "on")), False,
             wall + i),
            (f"lunaris/{R}/power/summary", encode(PowerSummary(t, 70.0, 77.0, 45.0, 32.0, 16.6)), False,
             wall + i),
            (f"lunaris/{R}/solar/left/power", encode(SolarPower(t, 23.7, 60.0, 0.0)), False, wall + i),
            (f"lunaris/{R}/umbilical/state", encode(UmbilicalState(t, False, 0.0)), False, wall + i),
            (f"lunaris/{R}/radio/lander/link", encode(RadioLink(t, True, 10.0, 0.0)), False, wall + i),
        ]
    fault = f"lunaris/{R}/fault/load/nav_camera/short"
    out += [
        (fault, b"0.05", False, wall + 10),
        (f"lunaris/{R}/event", encode(Event(12.0, "warning", "loads", "fault_injected", fault,
                                            "injected load/nav_camera/short", {"resistance_ohm": 0.05})),
         False, wall + 11),
        (fault, b"", True, wall + 12),
        (f"lunaris/{R}/input/sun_angle", b"sixty", False, wall + 13),  # not JSON: kept as text
        (f"lunaris/{R}/battery/state", b"garbage", False, wall + 14),  # not JSON telemetry: skipped
    ]
    return out


def _record(samples) -> bytes:
    buf = io.BytesIO()
    rec = Recorder(buf, "test")
    written = [rec.write(*s) for s in samples]
    rec.finish()
    assert written.count(False) == 1 and rec.skipped == 1 and rec.messages == len(samples) - 1
    return buf.getvalue()


def test_a_recording_reads_back_with_channels_schemas_counts_and_both_clocks():
    data = _record(_samples())
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    topics = {c.topic: c for c in summary.channels.values()}
    assert len(topics) == 12
    assert summary.statistics.message_count == 5 * 9 + 4
    assert summary.statistics.channel_message_counts[topics[f"lunaris/{R}/battery/state"].id] == 5
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
        assert json.loads(schema.data)["type"] == "object"
    schema_of = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schema_of[f"lunaris/{R}/load/imu/power"] == "lunaris.LoadPower"
    assert schema_of[f"lunaris/{R}/fault/load/nav_camera/short"] == ENVELOPE
    assert len(summary.schemas) == 10  # one per family (9) and the envelope, never per key
    by_topic: dict[str, list] = {}
    for _schema, channel, message in reader.iter_messages():
        by_topic.setdefault(channel.topic, []).append(message)
    battery = by_topic[f"lunaris/{R}/battery/state"]
    assert [m.publish_time for m in battery] == [int((10 + i) * 1e9) for i in range(5)]  # sim time
    assert [m.log_time for m in battery] == [1_700_000_000_000_000_000 + i for i in range(5)]  # wall
    assert [m.sequence for m in battery] == [1, 2, 3, 4, 5]
    fault = [msgspec.json.decode(m.data, type=KeyWrite)
             for m in by_topic[f"lunaris/{R}/fault/load/nav_camera/short"]]
    assert [(f.op, f.value, f.t_s) for f in fault] == [("put", 0.05, 14.0), ("delete", None, 14.0)]
    (sun,) = [msgspec.json.decode(m.data) for m in by_topic[f"lunaris/{R}/input/sun_angle"]]
    assert sun["text"] == "sixty" and sun["value"] is None
    assert by_topic[f"lunaris/{R}/fault/load/nav_camera/short"][0].publish_time == int(14e9)


def test_the_report_draws_a_recording(tmp_path: Path):
    path = tmp_path / "s.mcap"
    path.write_bytes(_record(_samples()))
    sessions = load_session(path)
    s = sessions[R]
    assert s.battery["soc"][1][0] == pytest.approx(0.95) and sorted(s.loads) == ["imu", "nav_camera"]
    assert [e["kind"] for e in s.events] == ["fault_injected"] and s.span_s == (0.0, 4.0)
    fig = draw(s, "test")
    # the timeline, the score sheet, five plots, the radio links and the current's twin axis
    assert len(fig.axes) == 9
    assert fig.axes[1].get_title(loc="left") == "the crew's response: 1 fault(s); 0 of 0 expectation(s) met"
    fig.savefig(tmp_path / "out.png")
    assert (tmp_path / "out.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_report_draws_the_path_coloured_by_the_drive_power(tmp_path: Path):
    path = tmp_path / "s.mcap"
    drive = [(f"lunaris/{R}/drive/state", encode(DriveState(
        10.0 + i, 5.0, 2.0 * i, 0.0, 0.1, 0.0, 0.0, 3.25, 0.325, 9.5 + i, 2.0 * i, 0, True, "driving",
        1, 20.0 - 2 * i, 9.5 * i)), False, 1_700_000_000_000_000_100 + i) for i in range(5)]
    path.write_bytes(_record(_samples() + drive))
    s = load_session(path)[R]
    assert s.path == ([5.0] * 5, [0.0, 2.0, 4.0, 6.0, 8.0], [9.5, 10.5, 11.5, 12.5, 13.5])
    fig = draw(s, "test")
    # the timeline, the score sheet, 5 plots, radios, the twin axis, the path and its colour bar
    assert len(fig.axes) == 11
    path_ax = fig.axes[8]
    assert path_ax.get_xlabel() == "x, east [m]" and "drive's power" in path_ax.get_title()
    assert list(path_ax.collections[0].get_array()) == [9.5, 10.5, 11.5, 12.5, 13.5]  # hottest last


def test_a_parked_rover_gets_no_path(tmp_path: Path):
    """Its one point drew a path plot (4.96 to 5.04 m, a colour bar 2.7 to 3.3 W) for a rover that
    never moved."""
    path = tmp_path / "s.mcap"
    parked = [(f"lunaris/{R}/drive/state", encode(DriveState(
        10.0 + i, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0, True, "parked", 0, 0.0, 0.0)),
        False, 1_700_000_000_000_000_100 + i) for i in range(5)]
    path.write_bytes(_record(_samples() + parked))
    fig = draw(load_session(path)[R], "test")
    assert len(fig.axes) == 9  # the timeline, the score sheet, 5 plots, radios, the twin axis
    assert not [ax for ax in fig.axes if ax.get_xlabel() == "x, east [m]"]


def _event(t: float, kind: str, key: str, message: str, wall: int, params=None, session: str = ""):
    ev = Event(t_s=t, severity="info", source="x", kind=kind, key=f"lunaris/{R}/{key}", message=message,
               params=params, source_id="s", seq=int(t * 10) + len(message), session=session)
    return (f"lunaris/{R}/event", encode(ev), False, wall)


def test_the_debrief_marks_actions_steps_resets_and_what_came_before(tmp_path: Path):
    wall = 1_700_000_000_000_000_000
    samples = [_event(2.0, "fault_injected", "fault/battery/heating", "replayed", wall)]  # before
    one_id, two_id = "20261125-090000", "20261125-100000"
    for i in range(10):  # t 10..14 of session one, then the next trainee's: t 0..4 of a new epoch
        epoch, t = (0, 10.0 + i) if i < 5 else (1, float(i - 5))
        cause, sid = ("reset", two_id) if epoch else ("", one_id)
        samples += [(f"lunaris/{R}/clock", encode(Clock(t, 0.1, i, 1.0, False, epoch, cause, sid)), False,
                     wall + 10 * i),
                    (f"lunaris/{R}/battery/state", encode(BatteryState(
                        t, 5e5, 5.3e5, 0.9, 16.6, 16.5, 2.0, 33.0, 20.0, True, 0, [], 3600.0)), False,
                     wall + 10 * i + 1),
                    (f"lunaris/{R}/radio/lander/link", encode(RadioLink(t, i % 3 != 0, 1.0, 0.0)), False,
                     wall + 10 * i + 2)]
    samples += [_event(11.0, "command", "cmd/rail/12V", "rail 12V: on=false; the rail is now off", wall + 15),
                _event(12.0, "input", "input/sun_angle", "sun angle 75 deg", wall + 25),
                _event(13.0, "scenario", "control/scenario", "scenario 'd': step 1/2 dust", wall + 35,
                       {"what": "step"}),
                _event(0.0, "session", "control/session", "session of 'Bob' begins", wall + 51, {
                    "session": two_id, "trainee": "Bob", "from_snapshot": None, "started_wall": 1.7e9,
                    "start_t_s": 0.0}, session=two_id)]
    path = tmp_path / "s.mcap"
    buf = io.BytesIO()
    rec = Recorder(buf, "test")
    for sample in sorted(samples, key=lambda x: x[3]):
        assert rec.write(*sample)
    rec.finish()
    path.write_bytes(buf.getvalue())
    one, two = load_recording(path)[R].sessions.values()  # the clock began a second session
    assert (one.id, two.id) == (one_id, two_id) and one.span_s == two.span_s == (0.0, 4.0)
    assert [(e["kind"], e["at_s"]) for e in one.events] == [
        ("fault_injected", None), ("command", 1.0), ("input", 2.0), ("scenario", 3.0)]
    assert [(e["kind"], e["at_s"]) for e in two.events] == [("session", 0.0)]  # nothing of the first
    assert load_session(path)[R].id == two_id and load_session(path, one_id)[R].id == one_id  # the last
    assert load_session(path, "7") == {}
    assert "from" in add_thresholds(one, None)
    assert (60.0, "alarm 60 C") in one.thresholds["temperature"]
    assert (15.0, "5V_CH2 shed") in one.thresholds["soc"]
    fig = draw(one, "test")
    assert "1 event(s) from before the recording" in fig._suptitle.get_text()
    timeline = fig.axes[0]
    texts = [t.get_text() for t in timeline.texts]
    assert "rail 12V: switch off; the rail is now off" in texts and "step 1/2 dust" in texts
    assert "replayed" not in " ".join(texts)
    texts = [t.get_text() for t in draw(two, "test").axes[0].texts]
    assert texts == ["Bob's session began"]


def test_labels_never_overlap_and_the_rest_are_counted():
    marks = [(float(t), "label-" + "x" * 10) for t in range(100)]
    placed, dropped = place_labels(marks, 100.0, 100, 3)
    assert dropped == 100 - len(placed) > 0
    for row in range(3):
        ts = sorted(t for t, _, r in placed if r == row)
        assert all(b - a >= 18 for a, b in zip(ts, ts[1:], strict=False))  # 16 chars + 2 apart


def test_a_label_near_the_end_ends_on_the_axis():
    """A label at the axis's end began there and was cut off ("ended: ev"): it begins early
    enough to end on the axis, and still overlaps no other on its row."""
    placed, dropped = place_labels([(10.0, "a" * 20), (99.0, "ended: every step has played")], 100.0, 100, 1)
    assert dropped == 0
    (_, _, _), (start, text, _) = placed
    assert start + len(text) <= 100 and start >= 10 + 22


def test_the_score_sheet_says_a_crew_acting_before_the_symptom_as_before():
    """Found by an instructor: "first crew action +-1.4 s" and "21.5 - (-)"."""
    from lunaris.report_draw import _since, _t_since

    assert _since(20.1, 21.5) == "-1.4 s" and _since(23.0, 21.5) == "+1.5 s"
    assert _since(None, 21.5) == "-"
    assert _t_since(None, 21.5) == "-" and _t_since(23.0, 21.5) == "23.0 (+1.5 s)"


def test_a_recording_begun_after_a_short_still_ties_the_rail_trip_to_it(tmp_path: Path):
    """A recording made after the short begins with the journal's history (the short, the
    load's alarm raised and cleared at once as the trip cut the load, the rail's trip) and only
    then the loads' telemetry, which says which rail feeds the camera. The rail trip is the
    short's alarm all the same: resolved when the trip was reset (48.0), not at the injection
    (30.1), when the load's own alarm cleared."""
    wall = 1_700_000_000_000_000_000
    short = f"lunaris/{R}/fault/load/nav_camera/short"

    def event(t: float, source: str, kind: str, key: str, seq: int) -> tuple:
        ev = Event(t, "warning", source, kind, f"lunaris/{R}/{key}", kind, None, source_id=source, seq=seq,
                   session="20260101-000000")
        return (f"lunaris/{R}/event", encode(ev), False, wall + seq)
    history = [
        event(30.1, "loads", "fault_raised", "load/nav_camera/over_current", 1),
        event(30.1, "power", "fault_raised", "rail/5V_CH2/tripped", 2),
        event(30.1, "loads", "fault_injected", "fault/load/nav_camera/short", 3),
        event(30.1, "loads", "fault_resolved", "load/nav_camera/over_current", 4),
        event(48.0, "power", "fault_resolved", "rail/5V_CH2/tripped", 5),
    ]
    telemetry = []
    for i in range(3):
        t = 60.0 + i * 0.1
        telemetry += [
            (f"lunaris/{R}/clock", encode(Clock(t, 0.1, 600 + i, 1.0, False, session="20260101-000000")),
             False, wall + 100 + i),
            (f"lunaris/{R}/load/nav_camera/power", encode(LoadPower(t, 0.0, "5V_CH2", True, ["short"])),
             False, wall + 100 + i),
            (f"lunaris/{R}/load/imu/power", encode(LoadPower(t, 1.0, "3V3_CH1", True, [])), False,
             wall + 100 + i),
        ]
    buf = io.BytesIO()
    rec = Recorder(buf, "test")
    for s in history + telemetry:
        rec.write(*s)
    rec.finish()
    path = tmp_path / "late.mcap"
    path.write_bytes(buf.getvalue())
    (session,) = load_recording(path, plots=False)[R].response.sessions()
    (fault,) = session.faults
    assert fault.key == short and fault.injected_t_s == 30.1
    assert fault.resolved_t_s == 48.0, (fault.resolved_t_s, fault.resolved_by)
