"""The debrief in plain words (issue 31: "the report speaks in keys and JSON"): fault names
from the catalogue, parameters as labelled values, event kinds and conditions in words; the
instructor's marks and the crew's actions drawn on the timeline; no label cut at the right
edge."""

from __future__ import annotations

import re

import pytest

from lunaris.report import load_recording
from lunaris.report_draw import draw
from lunaris.report_page import drawn_counts, html_page
from lunaris.report_words import condition_words, event_words, key_words, params_words, plain
from tests.lunaris.test_report_response import S2, R, Tape, two_trainees

pytestmark = pytest.mark.timeout(120)

MARK = "crew slow to see the heat"


def day(tape: Tape) -> None:
    """Ada's and Bob's sessions (tests.lunaris.test_report_response), and the instructor's mark
    in Bob's, as the faults service journals it."""
    two_trainees(tape)
    tape.event(26.0, "mark", "control/mark", message=f"mark: {MARK}", params={"text": MARK}, session=S2,
               source="faults")
    for i in range(1, 100):  # Bob's session goes on past the mark
        tape.tick(round(40 + i * 0.1, 3), 1)


def test_a_fault_is_said_by_the_catalogues_words():
    assert key_words("lunaris/mapp-1/fault/solar/left/dust") == "Solar panel left: Dust"
    assert params_words("solar/left", "dust", {"fraction": 0.6}) == "dust cover 60 %"
    assert params_words("battery", "heating", {"heat_w": 45}) == "extra heat 45 W"
    assert params_words("battery", "resistance", {"factor": 3.0}) == "internal resistance ×3"
    assert event_words({"kind": "fault_injected", "key": "lunaris/mapp-1/fault/solar/left/dust",
                        "params": {"fraction": 0.6}, "message": 'injected solar/left/dust {"fraction": 0.6}'}
                       ) == "Solar panel left: Dust (dust cover 60 %)"
    assert plain('injected solar/left/dust {"fraction": 0.6}', "lunaris/mapp-1/fault/solar/left/dust") == (
        "injected Solar panel left: Dust (dust cover 60 %)")
    assert key_words("lunaris/mapp-1/rail/5V_CH2/tripped").startswith("Rail 5V_CH2: tripped")
    assert "max_w" not in plain("load nav_camera draws 500.0 W, above its max_w 12 W")
    assert plain("rail 12V: on=false; the rail is now off") == "rail 12V: switch off; the rail is now off"


def test_a_condition_is_a_sentence():
    assert condition_words("rail.5V_CH2.state == off and battery.soc < 0.3") == (
        "rail 5V_CH2 is off and the battery's charge below 30 %")
    assert condition_words("radio.lander.in_range == false") == "radio lander is out of range"
    assert condition_words("something odd") == "something odd"


def _bob(tmp_path, late: bool = False):
    tape = Tape()
    day(tape)
    if late:  # a fault put in just before the end: its labels begin at the right edge
        tape.event(49.5, "fault_injected", "fault/solar/left/dust", params={"fraction": 0.6}, session=S2,
                   message='injected solar/left/dust {"fraction": 0.6}')
        tape.tick(49.6, 1)
    path = tape.write(tmp_path / "day.mcap")
    return list(load_recording(path)[R].sessions.values())[-1]


def test_the_marks_and_the_crews_actions_are_drawn_on_the_timeline(tmp_path):
    bob = _bob(tmp_path)
    fig = draw(bob, "Bob")
    timeline = fig.axes[0]
    labels = [t.get_text() for t in timeline.texts]
    assert f"mark: {MARK}" in labels, labels
    assert [t.get_text() for t in timeline.get_yticklabels()] == ["drill", "instructor", "crew",
                                                                   "faults\nand alarms"]
    assert any("rail 12V" in text and "switch off" in text for text in labels), labels
    assert "+ Battery: Overheating (extra heat 45 W)" in labels
    soc = fig.axes[2]
    dashed = [ln for ln in soc.get_lines()
              if ln.get_linestyle() == "--" and list(ln.get_xdata()) == [26.0, 26.0]]
    assert dashed, "the mark is a line across the plots"
    assert drawn_counts(bob)["marks"] == 1 and drawn_counts(bob)["crew"] == 1


def test_no_label_is_cut_at_the_right_edge(tmp_path):
    fig = draw(_bob(tmp_path, late=True), "Bob")
    for ax in fig.axes[:2]:  # the timeline and the score sheet
        box = ax.get_window_extent()
        for text in ax.texts:
            ext = text.get_window_extent()
            assert box.x0 - 1 <= ext.x0 and ext.x1 <= box.x1 + 1, (text.get_text(), ext, box)


def test_the_page_speaks_in_words(tmp_path):
    bob = _bob(tmp_path)
    page = html_page(bob, "Bob", b"\x89PNG", [])
    shown = re.sub(r"<[^>]+>", " ", page.split("<body>", 1)[1])
    for word in ("Battery: Overheating", "extra heat 45 W", "rail 12V is off", "your mark", MARK,
                 "fault injected", "1 mark(s) of yours", "no response"):
        assert word in shown, word
    for code in ("fault_injected", "heat_w", "battery/heating", "rail.12V.state", "{", "on=false"):
        assert code not in shown, code
