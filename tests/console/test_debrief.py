"""The debrief from the console's Recordings view, and the day's sessions voided or renamed
(issue 31). A recording of a training day with two trainees, Ada then Bob, in the console's
folder; in a real browser at 1280x800 the instructor opens the Recordings view: the recording
is listed with its trainees' names; the instructor picks the recording and Bob's session, asks
for the debrief, sees that it is being prepared (it takes seconds the first time) and then
reads it in the view: Bob's session, never Ada's, the instructor's mark on it and drawn on its
timeline, in words a person without a technical background reads (fault names, their
strength, conditions; no key, no JSON). Then three sessions of Ana (retries) on the twin: two
voided from the Session view, the third renamed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.select import Select

from common import keys
from tests.console.conftest import Live, console_page, console_site, save_shot, shoot
from tests.console.page_checks import LAYOUT, TEXT, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, view
from tests.lunaris.test_report_response import S1, S2, Tape
from tests.lunaris.test_report_words import MARK, day

pytestmark = pytest.mark.timeout(240)

R = "mapp-1"

@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    folder = tmp_path_factory.mktemp("console-debrief")
    (folder / "recordings").mkdir()
    tape = Tape()
    day(tape)
    tape.write(folder / "recordings" / "day.mcap")
    with console_site(folder, services=("clock", "battery", "faults")) as live:
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
    shoot(page, artefacts, "debrief", doc=False)
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
        assert vocabulary(text, field_names()) == []
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
    problems = [f"recordings view: {x}" for x in page.execute_script(LAYOUT)]
    problems += [f"recordings view: {x}" for x in vocabulary(page.execute_script(TEXT), field_names())]
    assert not problems, problems


def started(site: Live, trainee: str, seen: set[str]) -> str:
    """A new session of ``trainee`` begun on the twin (as the Session view's New trainee does);
    its id."""
    site.probe.put(keys.control_session(R), {"trainee": trainee})
    e = site.probe.wait_event(R, lambda e: e.get("kind") == "session" and isinstance(e.get("params"), dict)
                              and e["params"].get("trainee") == trainee and "end_t_s" not in e["params"]
                              and e["params"].get("session") not in seen)
    seen.add(e["params"]["session"])
    return e["params"]["session"]


def test_retries_are_voided_and_a_name_put_right_in_the_days_list(site, page, artefacts):
    """Found by an instructor: three 'Ana' sessions from retries stayed in the day's list. Two
    are voided from the Session view (the journal keeps them; the list can show them again),
    the third renamed "Ana Silva"."""
    seen: set[str] = set()
    first, second, third = (started(site, "Ana", seen) for _ in range(3))
    view(page, "session")
    rows = lambda d: d.find_elements(By.CSS_SELECTOR, '#sessions tr[data-trainee="Ana"]')  # noqa: E731
    WebDriverWait(page, 30).until(lambda d: len(rows(d)) == 3, "the three sessions of Ana listed")
    for sid in (first, second):
        clear_answers(page)
        click(page, f'#sessions tr[data-session="{sid}"] [data-action="session-void"]')
        WebDriverWait(page, 10).until(ec.alert_is_present()).accept()
        assert "voided" in answer(page, "accepted")
        gone = f'#sessions tr[data-session="{sid}"]'
        WebDriverWait(page, 10).until(lambda d, gone=gone: not d.find_elements(By.CSS_SELECTOR, gone),
                                      "the voided session out of the list")
    clear_answers(page)
    click(page, f'#sessions tr[data-session="{third}"] [data-action="session-rename"]')
    prompt = WebDriverWait(page, 10).until(ec.alert_is_present())
    prompt.send_keys("Ana Silva")
    prompt.accept()
    assert "renamed Ana Silva" in answer(page, "accepted")
    row = f'#sessions tr[data-session="{third}"]'
    WebDriverWait(page, 10).until(lambda d: d.find_element(By.CSS_SELECTOR, row).get_attribute("data-trainee")
                                  == "Ana Silva", "the session renamed")
    assert "began as Ana" in page.find_element(By.CSS_SELECTOR, row).text
    assert not rows(page)
    shown = page.find_element(By.ID, "sessions").text
    assert "show the 2 session(s) voided" in shown, shown
    save_shot(page, artefacts, "sessions-voided", doc=False)
    click(page, "#sessions-show-void")
    voided = "#sessions tr[data-void]"
    WebDriverWait(page, 10).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, voided)) == 2,
                                  "the voided sessions shown again on asking")
