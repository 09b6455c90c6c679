"""The debrief from the console's Recordings view (issue 31): a recording of a training day with
two trainees, Ada then Bob, in the console's folder; in a real browser at 1280x800 the
instructor opens the Recordings view: the recording is listed with its trainees' names; the
instructor picks the recording and Bob's session, asks for the debrief, sees that it is being
prepared (it takes seconds the first time) and then reads it in the view: Bob's session, never
Ada's, the instructor's mark on it and drawn on its timeline, in words a person without a
technical background reads (fault names, their strength, conditions; no key, no JSON).
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support.select import Select

from tests.console.conftest import Live, console_page, console_site, save_shot
from tests.console.pages import WebDriverWait, click, view
from tests.lunaris.test_report_response import S1, S2, Tape
from tests.lunaris.test_report_words import MARK, day

pytestmark = pytest.mark.timeout(240)

@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    folder = tmp_path_factory.mktemp("console-debrief")
    (folder / "recordings").mkdir()
    tape = Tape()
    day(tape)
    tape.write(folder / "recordings" / "day.mcap")
    with console_site(folder, services=("clock", "battery")) as live:
        yield live


@pytest.fixture(scope="module")
def page(site) -> Iterator:
    with console_page(site) as driver:
        yield driver


def test_the_debrief_of_the_second_trainee_opens_from_the_recordings_view(site, page, artefacts):
    view(page, "recordings")
    row = '#rec-list tr[data-recording="day.mcap"] td.trainees'
    WebDriverWait(page, 60).until(lambda d: d.find_element(By.CSS_SELECTOR, row).text == "Ada, Bob",
                                  "the recording listed with its trainees")
    Select(page.find_element(By.ID, "debrief-recording")).select_by_value("day.mcap")
    sessions = lambda d: Select(d.find_element(By.ID, "debrief-session")).options  # noqa: E731
    WebDriverWait(page, 10).until(lambda d: len(sessions(d)) == 2, "the recording's two sessions offered")
    offered = [o.text for o in sessions(page)]
    assert offered[0].startswith("Bob (") and offered[1].startswith("Ada ("), offered
    Select(page.find_element(By.ID, "debrief-session")).select_by_value(S1)  # Ada, then Bob
    Select(page.find_element(By.ID, "debrief-session")).select_by_value(S2)
    click(page, "#debrief-open")
    preparing = WebDriverWait(page, 10).until(lambda d: d.find_elements(By.ID, "debrief-preparing"),
                                              "the view says the report is being prepared")[0]
    assert "Preparing the report of Bob's session" in preparing.text, preparing.text
    save_shot(page, artefacts, "debrief-preparing", doc=False)
    WebDriverWait(page, 120).until(lambda d: d.find_elements(By.ID, "debrief-frame"), "the debrief shown")
    assert "Bob's session" in page.find_element(By.ID, "debrief-shown").text
    page.execute_script("document.getElementById('debrief-frame').scrollIntoView()")
    save_shot(page, artefacts, "debrief", doc=False)
    page.switch_to.frame(page.find_element(By.ID, "debrief-frame"))
    try:
        text = WebDriverWait(page, 30).until(lambda d: d.find_element(By.TAG_NAME, "body").text,
                                             "the report in the frame")
        assert f"Bob - session {S2} (this report)" in text
        assert MARK in text  # the mark of Bob's session, in the report
        assert "nav_camera" not in text.split("Events (")[-1]  # nothing of Ada's session
        img = page.find_element(By.CSS_SELECTOR, "img[alt='session plots']")
        assert img.get_property("naturalWidth") > 1000
        # in words a person without a technical background reads, the mark drawn
        for words in ("Debrief of Bob's session", "Battery: Overheating", "extra heat 45 W", "your mark",
                      "rail 12V is off", "On the timeline: 1 mark(s) of yours, 1 action(s) of the crew"):
            assert words in text, words
        for code in ("fault_injected", "heat_w", "battery/heating", "rail.12V.state", '{"', "on=false"):
            assert code not in text, code
        page.execute_script("arguments[0].scrollIntoView()", img)
    finally:
        page.switch_to.default_content()
    save_shot(page, artefacts, "debrief-timeline", doc=False)
    page.switch_to.frame(page.find_element(By.ID, "debrief-frame"))
    try:
        page.execute_script("document.querySelector('h2').scrollIntoView()")
    finally:
        page.switch_to.default_content()
    save_shot(page, artefacts, "debrief-score", doc=False)
    assert re.search(r"\bBob\b", page.find_element(By.ID, "debrief-card").text)
