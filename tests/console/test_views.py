"""Every view of the console as an instructor without a technical background meets it (issue 26).

A twin of the shipped MAPP rover (with its drive) and a console serving the shipped drills
(``config/scenarios``: three for mapp-1, one for the LTV, which is not in this session). In a
real browser, at a laptop's 1280x800 and a tablet's 820x1180:

- every control of every view lies inside the viewport, or where the page scrolls to, and
  nothing sticks out of its card (element rectangles, ``page_checks.LAYOUT``); on the tablet
  every control is a touch target of at least 40 px;
- the page's visible text has no raw JSON, no ``$.field`` path, no Python repr or traceback,
  no raw command-line output and none of the twin's snake_case field names;
- a shipped drill is played from the page (Play asks first, as it resets the rover) and its
  steps' statuses are read from the page; a drill for a rover not in the session cannot be
  played;
- the plots' axes are in simulated time, their labels distinct and apart;
- the twin's answers never cover what the instructor reads;
- a snapshot name is checked on the page, in words, and nothing is sent.
"""

from __future__ import annotations

import re
import urllib.request
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec

from common import keys
from testbed.browser import size_viewport
from tests.console.conftest import Live, console_page, console_site, save_shot, settle, shoot
from tests.console.page_checks import COVERED, LAYOUT, TEXT, TOUCH, TOUCH_PX, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, fill, view
from tests.harness import (
    ALL_SERVICES,
    ROOT,
    ROVERS,
    wait_for,
)

pytestmark = pytest.mark.timeout(240)

R = "mapp-1"
VIEWS = ("live", "map", "faults", "crew", "inputs", "session", "scenarios", "recordings")
SIZES = ((1280, 800, ""), (820, 1180, "-tablet"))
SHIPPED = ROOT / "config" / "scenarios"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    """The shipped MAPP rover, its drive included, and a console with the shipped drills."""
    folder = tmp_path_factory.mktemp("console-views")
    with console_site(folder, "--scenarios", str(SHIPPED), "--rover", str(ROVERS / "mapp.yaml"),
                      rover=ROVERS / "mapp.yaml", services=(*ALL_SERVICES, "drive")) as live:
        yield live


@pytest.fixture(scope="module")
def page(site) -> Iterator:
    with console_page(site) as driver:
        yield driver


def steps(driver) -> list[tuple[str, str, str]]:
    """The step table of the drill playing (or played): (label, status, answer) a step."""
    return [(r.get_attribute("data-label"), r.get_attribute("data-status"), r.get_attribute("data-outcome"))
            for r in driver.find_elements(By.CSS_SELECTOR, "#sc-play tr[data-step]")]


def step_status(driver, index: int) -> str:
    rows = driver.find_elements(By.CSS_SELECTOR, f'#sc-play tr[data-step="{index}"]')
    return rows[0].get_attribute("data-status") if rows else ""


def test_a_shipped_drill_is_played_from_the_page(site, page, artefacts):
    """The shorted-camera drill, with the instructor standing in for the crew from the page."""
    p = site.probe
    view(page, "scenarios")
    ltv = WebDriverWait(page, 10).until(
        lambda d: d.find_element(By.CSS_SELECTOR, '[data-play="crater-rim-sortie.yaml"]'))
    assert not ltv.is_enabled()  # for ltv-1, which is not in this session
    row = page.find_element(By.CSS_SELECTOR, '[data-scenario="crater-rim-sortie.yaml"]').text
    assert "not in this session" in row
    click(page, '[data-play="shorted-camera.yaml"]')
    alert = WebDriverWait(page, 10).until(ec.alert_is_present())
    assert "reset" in alert.text.lower() and R in alert.text
    alert.dismiss()  # asked, and nothing played
    assert not page.find_elements(By.CSS_SELECTOR, "#sc-play tr[data-step]")
    seen = len(p.samples(keys.clock(R)))
    click(page, '[data-play="shorted-camera.yaml"]')
    WebDriverWait(page, 10).until(ec.alert_is_present()).accept()
    assert "playing" in answer(page, "accepted").lower()
    # The drill resets the rover first (clock at 0, x1); once it plays, the clock goes x10.
    # (its first step shown, in whatever state: at x1 it fires at 30 s, which a loaded machine
    # had reached before the page's first look)
    WebDriverWait(page, 30).until(lambda d: step_status(d, 1), "the drill to start")
    wait_for(lambda: any(c.get("cause") == "reset" for c in p.samples(keys.clock(R))[seen:]), 10, "the reset")
    view(page, "session")
    click(page, f'[data-action="clock-scale"][data-scale="10"][data-rover="{R}"]')
    p.wait_value(keys.clock(R), lambda c: c["time_scale"] == 10)
    view(page, "scenarios")
    WebDriverWait(page, 60).until(lambda d: step_status(d, 2) == "fired", "the 5V_CH2 trip to be seen")
    shoot(page, artefacts, "scenarios")
    # The crew's commands, from the page's rail buttons: off and reset (the channel safed), on.
    view(page, "live")
    click(page, f'[data-action="rail-off"][data-rover="{R}"][data-rail="5V_CH2"]')
    click(page, f'[data-action="rail-reset"][data-rover="{R}"][data-rail="5V_CH2"]')
    p.wait_value(keys.rail_state(R, "5V_CH2"), lambda r: r["state"] == "off")
    view(page, "scenarios")
    WebDriverWait(page, 30).until(lambda d: step_status(d, 6) == "fired", "the camera to be isolated")
    view(page, "live")
    click(page, f'[data-action="rail-on"][data-rover="{R}"][data-rail="5V_CH2"]')
    p.wait_value(keys.rail_state(R, "5V_CH2"), lambda r: r["state"] == "on")
    view(page, "scenarios")
    WebDriverWait(page, 90).until(lambda d: "finished" in d.find_element(By.ID, "sc-play").text.lower(),
                                  "the drill to finish")
    got = steps(page)
    assert [label for label, _, _ in got] == [
        "navigation camera shorts", "5V_CH2 tripped",
        "isolate the shorted camera - 5V_CH2 off and its trip reset", "channel safed by the crew",
        "short isolated", "camera lost", "restore 5V_CH2 for the hazard cameras", "channel back on",
        "hazard cameras powered again", "end of drill - camera repaired"]
    # the crew's two expectations (SPEC 12d), met from the page's rail buttons
    assert [status for _, status, _ in got] == ["fired"] * 2 + ["met"] + ["fired"] * 3 + ["met"] + [
        "fired"] * 3, got
    assert {outcome for _, _, outcome in got} <= {"accepted", "reached", "met"}, got
    text = page.find_element(By.ID, "sc-play").text
    assert "every step has played" in text
    # the crew's score in words, with when each was met (it read "met / met")
    assert "Expectations of the crew: 2 of 2 met" in text, text
    met = page.find_element(By.CSS_SELECTOR, '#sc-play tr[data-step="3"] td.status').text
    assert re.fullmatch(r"met at [\d:]+, .+ of its .+", met), met
    site.probe.put(keys.clock_control(R), {"time_scale": 1})


def test_every_view_fits_a_laptop_and_a_tablet_and_speaks_plainly(site, page, artefacts):
    p = site.probe
    fields = field_names()
    # Something on every card: faults with values, a refusal, a prediction, a snapshot.
    p.put(keys.fault(R, "battery", "heating"), {"heat_w": 40})
    p.put(keys.fault(R, "solar/left", "dust"), {"fraction": 0.3})
    p.put(keys.fault(R, "load/nav_camera", "short"), b"")
    p.wait_event(R, lambda e: e["kind"] == "fault_raised" and "5V_CH2" in e["message"])
    view(page, "faults")
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#f-params input[data-param]"))
    from selenium.webdriver.support.select import Select
    Select(page.find_element(By.ID, "f-comp")).select_by_value("battery")
    Select(page.find_element(By.ID, "f-kind")).select_by_value("heating")
    fill(page, '#f-params input[data-param="heat_w"]', "-5")
    click(page, '#f-buttons [data-action="fault-inject"]')
    answer(page, "invalid")
    view(page, "session")
    click(page, "#predict")
    WebDriverWait(page, 60).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#prediction table"))
    fill(page, "#snap-name", "views-1")
    click(page, f'[data-action="snapshot-save"][data-rover="{R}"]')
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, '[data-snapshot="views-1"]')
                                  or d.find_element(By.ID, "snap-refresh").click())
    view(page, "recordings")
    fill(page, "#rec-name", "views-1")
    click(page, "#rec-start")
    recording = lambda: site.console.get("/api/recordings")[1]["recording"]  # noqa: E731
    wait_for(lambda: "messages" in " ".join(recording()["lines"]), 30, "the recorder's progress")
    WebDriverWait(page, 20).until(lambda d: "so far" in d.find_element(By.ID, "rec-status").text,
                                  "the recording's progress on the page")
    problems = []
    for width, height, suffix in SIZES:
        size_viewport(page, width, height)
        for name in VIEWS:
            view(page, name)
            if name == "live":
                WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#charts .uplot"))
            if name == "crew":  # the crew's view and response, asked of the console
                WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#crew-alarms h2")
                                              and d.find_elements(By.CSS_SELECTOR, "#crew-response h2"))
            # drills: shot playing; the map: shot driving (test_map.py); recordings: shot saved, below
            save_shot(page, artefacts, f"{name}{suffix}", doc=name not in ("scenarios", "map", "recordings"))

            at = f"{name}{suffix} ({width}x{height})"
            problems += [f"{at}: {x}" for x in page.execute_script(LAYOUT)]
            if suffix:
                problems += [f"{at}: a small touch target: {x}" for x in page.execute_script(TOUCH, TOUCH_PX)]
            problems += [f"{at}: {x}" for x in vocabulary(page.execute_script(TEXT), fields)]
            if name == "recordings":
                progress = page.find_element(By.ID, "rec-status").text
                if not re.search(r"Recording to views-1\.mcap for .*: [\d,]+ values and events so far",
                                 progress):
                    problems.append(f"{at}: the recording's progress is not said plainly: {progress!r}")
    size_viewport(page, 1280, 800)
    click(page, "#rec-stop")
    wait_for(lambda: not recording()["running"], 30, "the recording to stop")
    said = lambda d: d.find_element(By.ID, "rec-status").text  # noqa: E731
    WebDriverWait(page, 10).until(lambda d: not said(d).startswith("Recording"))
    problems += [f"recordings, stopped: {x}" for x in vocabulary(page.execute_script(TEXT), fields)]
    status = page.find_element(By.ID, "rec-status").text
    if not re.search(r"Saved views-1\.mcap.*\d MB", status):
        problems.append(f"recordings, stopped: the status does not say what was saved: {status!r}")
    # The recording saved is offered for download (Foxglove, PlotJuggler): an MCAP file.
    click(page, "#rec-refresh")
    link = WebDriverWait(page, 10).until(lambda d: d.find_element(
        By.CSS_SELECTOR, '[data-recording="views-1.mcap"] a[data-link="download"]'))
    assert "Foxglove" in link.get_attribute("title") and "Download" in link.text
    with urllib.request.urlopen(link.get_attribute("href"), timeout=10) as r:
        assert r.headers["Content-Type"] == "application/vnd.mcap" and r.read(8) == b"\x89MCAP0\r\n"
    shoot(page, artefacts, "recordings")
    for kind in ("battery/heating", "solar/left/dust", "load/nav_camera/short"):
        p.delete(keys.fault(R, *kind.rsplit("/", 1)))
    assert not problems, "\n".join(problems)


def _ticks(driver) -> list[dict]:
    driver.set_script_timeout(10)
    return driver.execute_async_script(
        "const done = arguments[0]; import('/static/charts.js').then((m) => done(m.axisTicks()));")


def test_the_plots_read_in_simulated_time(site, page):
    """At x100 the time axis runs in sim time (hh:mm:ss) over the span it says; no two labels
    of an axis are the same, and none overlaps the next."""
    p = site.probe
    view(page, "live")
    p.put(keys.clock_control(R), {"time_scale": 100})
    p.wait_value(keys.clock(R), lambda c: c["time_scale"] == 100)
    start = p.wait_value(keys.clock(R))["t_s"]
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > start + 600, timeout_s=30)
    WebDriverWait(page, 20).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#charts .uplot"))
    WebDriverWait(page, 10).until(lambda d: len(_ticks(d)) >= 3)
    now = p.wait_value(keys.clock(R))["t_s"]
    problems = []
    for axis in _ticks(page):
        labels, px, widths = axis["labels"], axis["px"], axis["widths"]
        where = f"{axis['plot']} axis {axis['axis']} {labels}"
        shown = [x for x in labels if x]
        if len(set(shown)) != len(shown):
            problems.append(f"{where}: a label repeated")
        if len(shown) < 2:
            problems.append(f"{where}: fewer than two labels")
        for i in range(1, len(labels)):
            if not labels[i] or not labels[i - 1]:
                continue
            gap = abs(px[i] - px[i - 1])
            need = (widths[i] + widths[i - 1]) / 2 if axis["axis"] == 0 else 10
            if gap < need:
                problems.append(f"{where}: {labels[i - 1]!r} and {labels[i]!r} overlap ({gap:.0f} px apart)")
        if axis["axis"] == 0:
            for label in shown:
                m = re.fullmatch(r"(\d+):(\d\d):(\d\d)", label)
                if not m:
                    problems.append(f"{where}: {label!r} is not sim time hh:mm:ss")
                    continue
                t = int(m[1]) * 3600 + int(m[2]) * 60 + int(m[3])
                if not now - axis["span_s"] - 60 <= t <= now + 60:
                    problems.append(f"{where}: {label} is outside the last {axis['span_s']} s of sim time "
                                    f"(now {now:.0f} s)")
    p.put(keys.clock_control(R), {"time_scale": 1})
    assert not problems, "\n".join(problems)


def test_answers_cover_nothing_the_instructor_reads(site, page):
    """An answer lies on nothing of the view that shows, wherever the view is scrolled."""
    for width, height, _ in SIZES:
        size_viewport(page, width, height)
        view(page, "live")
        clear_answers(page)
        for _ in range(3):
            click(page, f'[data-action="rail-on"][data-rover="{R}"][data-rail="12V"]')
            answer(page, "accepted")
        for where in ("start", "end"):
            page.execute_script("document.getElementById('events-list')"
                                ".scrollIntoView({block: arguments[0]})", where)
            settle(page)
            covered = page.execute_script(COVERED)
            assert not covered, f"{width}x{height}, event log at the {where}: {covered[:5]}"
    size_viewport(page, 1280, 800)


def test_a_snapshot_name_is_checked_on_the_page(site, page):
    p = site.probe
    view(page, "session")
    seen = len(p.samples(keys.event(R)))
    clear_answers(page)
    name = page.find_element(By.ID, "snap-name")
    name.clear()
    name.send_keys("before storm")
    click(page, f'[data-action="snapshot-save"][data-rover="{R}"]')
    said = answer(page, "invalid")
    assert "space" in said and "before storm" in said and "no such control" not in said
    assert not re.search(r"control/snapshot", said)
    p.put(keys.under(R, "control/rewind"), b"")  # a probe's put, made after: the first thing heard
    p.wait_event(R, lambda e: e["key"] == keys.under(R, "control/rewind"))
    assert not [e for e in p.samples(keys.event(R))[seen:] if "snapshot" in e["key"]]


def test_off_on_an_essential_rail_is_asked_first(site, page):
    """The flight computer's rail (essential: never shed, in the rover file the console was
    given) is switched off only once the instructor says yes; another rail at once."""
    p = site.probe
    view(page, "live")
    seen = len(p.events(R))
    cmd = keys.under(R, "cmd/rail/5V_CH1")
    click(page, f'[data-action="rail-off"][data-rover="{R}"][data-rail="5V_CH1"]')
    alert = WebDriverWait(page, 10).until(ec.alert_is_present())
    asked = alert.text
    assert "5V_CH1" in asked and "essential" in asked and "flight_computer" in asked, asked
    alert.dismiss()  # asked, and nothing sent: the next command is answered with none before it
    click(page, f'[data-action="rail-off"][data-rover="{R}"][data-rail="3V3_CH2"]')  # not asked
    p.wait_event(R, lambda e: e["kind"] == "command" and e["key"].endswith("cmd/rail/3V3_CH2"))
    assert not [e for e in p.events(R)[seen:] if e["key"] == cmd]
    click(page, f'[data-action="rail-off"][data-rover="{R}"][data-rail="5V_CH1"]')
    WebDriverWait(page, 10).until(ec.alert_is_present()).accept()
    p.wait_value(keys.rail_state(R, "5V_CH1"), lambda r: r["state"] == "off")
    for rail in ("5V_CH1", "3V3_CH2"):
        p.put(keys.under(R, f"cmd/rail/{rail}"), {"on": True})
        p.wait_value(keys.rail_state(R, rail), lambda r: r["state"] == "on")
