"""What the crew sees and how it responds, on the console's page (SPEC §12b, §12d, issue 25).

A twin of the MAPP rover (without its drive) and a console given its rover file; in a real
browser at 1280x800 the instructor opens the "Crew" view: with nothing wrong every part reads
OK; after a short is injected on the navigation camera, the crew's alarms show rail 5V_CH2's
over-current trip and its readings the rail's 0 mA, while nothing the crew sees names the
short, its resistance or an injection; beside it the instructor's own active faults name the
short. The crew's controls are listed with what they do. The crew's response (SPEC 12d) shows
the fault with the crew not acted yet, then the crew's own command as its action. The view fits
and speaks plainly.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec

from common import keys
from tests.console.conftest import MAPP, Live, console_page, console_site, shoot
from tests.console.page_checks import LAYOUT, TEXT, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, fill, view
from tests.harness import (
    ROOT,
    env_without_zenoh_config,
    lunaris_cmd,
)
from tests.lunaris.conftest import run_tool

pytestmark = pytest.mark.timeout(180)

R = "mapp-1"
DRILL = ROOT / "config" / "scenarios" / "shorted-camera.yaml"
CREW = ("#crew-alarms table", "#crew-ok", "#crew-readings table", "#crew-controls table")  # what it reads


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    with console_site(tmp_path_factory.mktemp("console-crew"), "--rover", str(MAPP),
                      "--scenarios", str(DRILL.parent)) as live:
        yield live


@pytest.fixture(scope="module")
def page(site) -> Iterator:
    with console_page(site) as driver:
        yield driver


def crew_text(driver) -> str:
    """What the crew's cards show of the rover (not their help, nor the instructor's own faults)."""
    return "\n".join(e.text for sel in CREW for e in driver.find_elements(By.CSS_SELECTOR, sel))


def test_the_instructor_sees_what_the_crew_sees(site, page, artefacts):
    p = site.probe
    view(page, "crew")
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.ID, "crew-all-ok"), "every part OK")
    short, rail = keys.fault(R, "load/nav_camera", "short"), keys.rail_state(R, "5V_CH2")
    p.put(short, {"resistance_ohm": 0.05})
    try:
        p.wait_value(rail, lambda v: v["state"] == "tripped")
        tripped = '#crew-alarms tr[data-component="rail/5V_CH2"][data-level="ERROR"]'
        row = WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, tripped),
                                            "the crew's alarm of rail 5V_CH2")[0]
        assert "over-current trip" in row.text, row.text
        current = '#crew-readings tr[data-topic="/pdm/rail_5V_CH2_current_ma"]'
        reads = lambda d: d.find_element(By.CSS_SELECTOR, current).text  # noqa: E731
        WebDriverWait(page, 10).until(lambda d: reads(d).endswith(" 0 mA"), "the rail at 0 mA")
        WebDriverWait(page, 10).until(lambda d: "Short circuit" in d.find_element(By.ID, "faults-list").text,
                                      "the instructor's own fault beside it")
        said = crew_text(page)
        for word in ("short", "Short", "injected", "0.05", "resistance", "Ω"):
            assert word not in said, f"the crew's view says {word!r}:\n{said}"
        services = {e.get_attribute("data-service") for e in page.find_elements(
            By.CSS_SELECTOR, "#crew-controls tr[data-service]")}
        assert {"/pdm/rail_5V_CH2/set_enabled", "/pdm/rail_5V_CH2/reset"} <= services, services
        reset = page.find_element(By.CSS_SELECTOR, '#crew-controls tr[data-service="/pdm/rail_5V_CH2/reset"]')
        assert "resets rail 5V_CH2" in reset.text
        # The crew's response, live: the fault seen, the crew not acted yet; then the crew's
        # own command (actor crew, as its dashboard sends it) shows as its action.
        fault_row = '#crew-response tr[data-fault="load/nav_camera/short"]'
        row = WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, fault_row),
                                            "the fault in the crew's response")[0]
        assert row.get_attribute("data-acted") == "false" and "not yet" in row.text, row.text
        p.session.put(keys.cmd_rail(R, "5V_CH2"), b'{"on": false}', attachment=b"actor=crew")
        acted = f'{fault_row}[data-acted="true"]'
        row = WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, acted),
                                            "the crew's action in its response")[0]
        assert "acted" in row.text and "5V_CH2" in row.text, row.text
        shoot(page, artefacts, "crew-short", doc=False)  # the docs take test_views.py's
        problems = [f"crew view: {x}" for x in page.execute_script(LAYOUT)]
        problems += [f"crew view: {x}" for x in vocabulary(page.execute_script(TEXT), field_names())]
        assert not problems, "\n".join(problems)
    finally:
        p.delete(short)
        p.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})
        p.put(keys.cmd_rail(R, "5V_CH2"), {"on": True})  # the crew switched it off
        p.wait_value(rail, lambda v: v["state"] == "on")
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.ID, "crew-all-ok"), "every part OK again")


def test_a_drill_and_a_crew_that_responds_turn_the_expectations_met_on_the_page(site, page):
    """The training loop in the browser (issue 25): a trainee's session, the shipped
    shorted-camera drill played at x20, a crew process that reads the rail as its dashboard
    does and acts as the bridge writes its calls (actor crew); the Crew view shows the drill's
    two expectations pending, then met."""
    p, ep = site.probe, site.endpoint
    done = run_tool("session", "start", R, "--trainee", "crew 2", "--connect", ep)
    assert done.returncode == 0, done.stdout + done.stderr
    view(page, "crew")
    env = env_without_zenoh_config()
    # the crew acts once the test has seen the expectations pending (at x20 the crew had
    # acted before the page had shown them)
    crew = subprocess.Popen([sys.executable, "-m", "tests.lunaris.crew", ep, R, "5V_CH2", "15",
                             "--after-go"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=env)
    drill = None
    try:
        assert crew.stdout is not None and crew.stdout.readline().startswith("crew: watching")
        drill = subprocess.Popen(lunaris_cmd("scenario", "run", str(DRILL), "--time-scale", "20",
                                             "--connect", ep, "--clear-at-end"),
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
                                 env=env)
        rows = "#crew-response tr[data-expectation]"

        def expectations(d) -> dict[str, str]:
            return {e.get_attribute("data-expectation"): e.get_attribute("data-met")
                    for e in d.find_elements(By.CSS_SELECTOR, rows)}
        pending = WebDriverWait(page, 30).until(lambda d: len(expectations(d)) == 2 and expectations(d),
                                                "the drill's two expectations on the page")
        assert "true" not in pending.values(), pending  # before the crew acted: not met yet
        assert crew.stdin is not None
        crew.stdin.write("go\n")
        crew.stdin.flush()
        met = WebDriverWait(page, 60).until(
            lambda d: set(expectations(d).values()) == {"true"} and expectations(d),
            "both expectations met on the page")
        assert {"isolate the shorted camera - 5V_CH2 off and its trip reset",
                "restore 5V_CH2 for the hazard cameras"} == set(met)
        out, _ = drill.communicate(timeout=60)
        assert drill.returncode == 0 and "expectations of the crew: 2 of 2 met" in out, out
    finally:
        for proc in (drill, crew):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.wait(20)
        p.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})
        p.put(keys.cmd_rail(R, "5V_CH2"), {"on": True})


def test_the_crew_view_follows_an_event_at_once(site, page):
    """An event of the rover asks the crew's view again at once, not at the next poll: with the
    page's clock held (Date.now frozen) the poll every 2 s never comes, and only the fault's
    own events can bring it to the crew's response."""
    p = site.probe
    dust = keys.fault(R, "solar/right", "dust")
    row = '#crew-response tr[data-fault="solar/right/dust"]'
    view(page, "crew")
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#crew-response"),
                                  "the crew's response")
    assert not page.find_elements(By.CSS_SELECTOR, row)
    page.execute_script("window.__now = Date.now; const held = Date.now(); Date.now = () => held;")
    try:
        p.put(dust, {"fraction": 0.4})
        WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, row),
                                      "the injected dust in the crew's response, with the clock held")
    finally:
        page.execute_script("if (window.__now) Date.now = window.__now;")
        p.delete(dust)


def test_the_instructor_standing_in_for_the_crew_is_counted_as_the_crew(site, page):
    """A drill run without the crew's dashboard: with "Standing in for the crew" ticked, the
    PDM's buttons are the crew's actions (the Crew view's response said "not yet" beside a drill
    whose expectations were met from those buttons)."""
    p = site.probe
    fault = keys.fault(R, "load/imu", "open")  # the imu is on 3V3_CH1: the crew acts on its rail
    row = '#crew-response tr[data-fault="load/imu/open"]'
    p.put(fault, b"")
    try:
        view(page, "crew")
        WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, row), "the fault's row")
        assert page.find_element(By.CSS_SELECTOR, row).get_attribute("data-acted") == "false"
        view(page, "live")
        box = WebDriverWait(page, 10).until(lambda d: d.find_element(By.ID, "as-crew"))
        box.click()
        WebDriverWait(page, 10).until(lambda d: d.find_element(By.ID, "as-crew").is_selected(), "ticked")
        click(page, f'[data-action="rail-off"][data-rover="{R}"][data-rail="3V3_CH1"]')
        WebDriverWait(page, 10).until(ec.alert_is_present()).accept()  # an essential rail: asked first
        p.wait_event(R, lambda e: e["kind"] == "command" and e["key"].endswith("cmd/rail/3V3_CH1")
                     and e["actor"] == "crew")
        click(page, f'[data-action="rail-on"][data-rover="{R}"][data-rail="3V3_CH1"]')
        p.wait_value(keys.rail_state(R, "3V3_CH1"), lambda r: r["state"] == "on")
        view(page, "crew")
        WebDriverWait(page, 10).until(lambda d: d.find_element(
            By.CSS_SELECTOR, row).get_attribute("data-acted") == "true", "the crew's action counted")
    finally:
        page.execute_script("const b = document.getElementById('as-crew'); if (b && b.checked) b.click();")
        p.delete(fault)
        p.put(keys.cmd_rail(R, "3V3_CH1"), {"on": True})


def test_the_instructor_marks_the_timeline_from_the_crew_view(site, page, artefacts):
    """Found by an instructor: watching the crew, there was no Mark field (only on the Session
    view): a note from the Crew view is a mark on the session's timeline, for its debrief."""
    view(page, "crew")
    clear_answers(page)
    note = "crew found the tripped rail from its alarms"
    fill(page, "#crew-mark #mark-text", note)
    click(page, f'#crew-mark [data-action="mark"][data-rover="{R}"]')
    assert note in answer(page, "accepted")
    got = site.probe.wait_event(R, lambda e: e.get("kind") == "mark" and note in e.get("message", ""))
    assert got["actor"] == "instructor", got
    WebDriverWait(page, 10).until(lambda d: d.find_element(By.CSS_SELECTOR, "#crew-mark #mark-text")
                                  .get_attribute("value") == "", "the field emptied once the mark is made")
    shoot(page, artefacts, "crew-mark", doc=False)


def test_a_new_trainee_stops_the_drill_of_the_session_before(site, page):
    """SPEC 13a: a drill belongs to its session. Found by an instructor: New trainee pressed
    40 s into the shipped drill (the question did not mention it), and the drill played on and
    scored the next trainee ("isolate the shorted camera ... waiting: 55 s left")."""
    view(page, "scenarios")
    click(page, '[data-play="shorted-camera.yaml"]')
    WebDriverWait(page, 10).until(ec.alert_is_present()).accept()  # it starts from a reset
    playing = lambda d: d.find_element(By.ID, "sc-play").text  # noqa: E731
    WebDriverWait(page, 30).until(lambda d: playing(d).startswith("Playing"), "the drill playing")
    view(page, "crew")
    rows = "#crew-response tr[data-expectation]"
    WebDriverWait(page, 30).until(lambda d: d.find_elements(By.CSS_SELECTOR, rows), "its expectations")
    view(page, "session")
    box = page.find_element(By.ID, "trainee-name")
    box.clear()
    box.send_keys("Cleo")
    click(page, f'[data-action="session-start"][data-rover="{R}"]')
    alert = WebDriverWait(page, 10).until(ec.alert_is_present())
    drill = "Shorted camera - isolate and recover the 5V rail"
    assert alert.text.startswith(f'The drill "{drill}" stops first'), alert.text
    alert.accept()
    view(page, "scenarios")
    WebDriverWait(page, 30).until(lambda d: playing(d).startswith("Stopped") and "a new session began"
                                  in playing(d), lambda: f"the drill stopped (the page: {playing(page)!r})")
    view(page, "crew")
    WebDriverWait(page, 10).until(lambda d: not d.find_elements(By.CSS_SELECTOR, rows),
                                  "none of the drill's expectations in Cleo's session")
