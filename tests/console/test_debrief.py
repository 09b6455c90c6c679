"""The debrief from the console's Recordings view (issue 31): a recording of a training day with
two trainees, Ada then Bob, in the console's folder; in a real browser at 1280x800 the
instructor opens the Recordings view: the recording is listed with its trainees' names; the
instructor picks the recording and Bob's session, asks for the debrief, sees that it is being
prepared (it takes seconds the first time) and then reads it in the view: Bob's session, never
Ada's, the instructor's mark on it, in words a person without a technical background reads.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support.select import Select

from tests.console.conftest import Live, console_page, console_site, save_shot
from tests.console.pages import WebDriverWait, click, view
from tests.lunaris.test_report_response import S1, S2, Tape, two_trainees

pytestmark = pytest.mark.timeout(240)

MARK = "crew slow to see the heat"


def day(tape: Tape) -> None:
    """Ada's and Bob's sessions (tests.lunaris.test_report_response), and the instructor's mark
    in Bob's, as the faults service journals it."""
    two_trainees(tape)
    tape.event(26.0, "mark", "control/mark", message=f"mark: {MARK}", params={"text": MARK}, session=S2,
               source="faults")
    for i in range(1, 100):  # Bob's session goes on past the mark
        tape.tick(round(40 + i * 0.1, 3), 1)


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
    finally:
        page.switch_to.default_content()
    assert re.search(r"\bBob\b", page.find_element(By.ID, "debrief-card").text)
