"""The map and driving from the console (issue 26.2, 26.3), and the faults list with an owner
missing (SPEC 12f), in a real browser against the shipped MAPP rover (its drive, its lander
radio at a site) and a console given its rover file.

- a shipped traverse is chosen on the map's drive panel: its plan in words (the console's own
  numbers), previewed on the map; sent; the rover's marker then follows ``drive/state``: drawn
  at the twin's position, at the map's scale, from the lander's site, and the route's driven
  part ends at it;
- waypoints typed and clicked on the map are previewed (one outside the lander's range said
  so), one removed, sent, and the drive follows exactly those; Stop parks the rover;
- the lander radio follows the drive: the Inputs view offers no position form for it and says
  why;
- the map and its drive panel fit a laptop and a tablet and speak plainly;
- the battery service stopped: the faults view names it as not answering.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support.select import Select

from common import keys
from testbed.browser import size_viewport
from tests.console.conftest import Live, console_page, console_site, save_shot, shoot
from tests.console.page_checks import LAYOUT, TEXT, TOUCH, TOUCH_PX, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, fill, text, view
from tests.harness import (
    ALL_SERVICES,
    ROVERS,
    Probe,
    stop_process,
    wait_for,
)

pytestmark = pytest.mark.timeout(240)

R = "mapp-1"
SERVICES = (*ALL_SERVICES, "drive")
SIZES = ((1280, 800, ""), (820, 1180, "-tablet"))

# Everything the map says about the rover, read in one go (the page redraws between two reads):
# the twin's position it was drawn from, where the marker and the lander's site are in the
# drawing, the map's scale, its scale bar, and the driven part's last point.
READ = """
const svg = document.getElementById('map-svg'), rover = document.getElementById('map-rover');
const lander = svg && svg.querySelector('g.radio[data-radio="lander"]');
if (!svg || !rover || !lander) return null;
const at = (g) => { const m = g.transform.baseVal.consolidate().matrix; return [m.e, m.f]; };
const bar = document.querySelector('#map-scale path').getAttribute('d').match(/h([\\d.]+)/)[1];
const driven = document.getElementById('map-driven');
const last = driven ? driven.getAttribute('points').trim().split(' ').pop().split(',').map(Number) : null;
return {x_m: Number(rover.dataset.xM), y_m: Number(rover.dataset.yM),
        heading: Number(rover.dataset.headingDeg), rover: at(rover), lander: at(lander),
        scale: Number(svg.dataset.scale), bar_px: Number(bar),
        bar_m: Number(document.getElementById('map-scale').dataset.metres), driven_end: last};
"""


# the page shows the twin: the battery's values are there
MAP_SHOWN = "return document.querySelector('#main [data-key=\"battery/state\"]') !== null;"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    def ready(p: Probe) -> None:
        p.wait_value(keys.drive_state(R))
        p.wait_value(keys.radio_link(R, "lander"))
    with console_site(tmp_path_factory.mktemp("console-map"), "--rover", str(ROVERS / "mapp.yaml"),
                      rover=ROVERS / "mapp.yaml", services=SERVICES, ready=ready) as live:
        yield live


@pytest.fixture(scope="module")
def page(site) -> Iterator:
    with console_page(site, MAP_SHOWN) as driver:
        yield driver


def read_map(driver) -> dict:
    return WebDriverWait(driver, 10).until(lambda d: d.execute_script(READ), "the map, the rover, the lander")


def check_drawn(m: dict) -> list[str]:
    """Where the marker is against the twin's numbers it shows: its offset from the lander's
    site (the site frame's origin for MAPP) is (x east, y north) at the map's scale, the scale
    bar is as long as the scale says, and the route driven ends at the marker."""
    problems = []
    dx, dy = m["rover"][0] - m["lander"][0], m["rover"][1] - m["lander"][1]
    want = (m["x_m"] * m["scale"], -m["y_m"] * m["scale"])  # east is right, north is up
    if math.dist((dx, dy), want) > 1.0:
        problems.append(f"the marker is {dx:.1f}, {dy:.1f} px from the lander, not "
                        f"{want[0]:.1f}, {want[1]:.1f}")
    if abs(m["bar_px"] - m["bar_m"] * m["scale"]) > 0.5:
        problems.append(f"the scale bar says {m['bar_m']} m over {m['bar_px']} px at {m['scale']} px/m")
    if m["driven_end"] is not None and math.dist(m["driven_end"], m["rover"]) > 1.0:
        problems.append(f"the route driven ends at {m['driven_end']}, the marker is at {m['rover']}")
    return problems


def test_a_shipped_traverse_sent_from_the_page_moves_the_rover_on_the_map(site, page, artefacts):
    p = site.probe
    view(page, "map")
    Select(WebDriverWait(page, 10).until(lambda d: d.find_element(By.ID, "tr-file"))).select_by_value(
        "mapp-crater-rim.yaml")
    # The plan in words, from where the rover is: the console's numbers.
    status, listed = site.console.get(f"/api/traverses?rover={R}")
    (entry,) = [t for t in listed["traverses"] if t["file"] == "mapp-crater-rim.yaml"]
    plan = entry["plan"]
    assert status == 200 and not plan["problems"], plan
    said = WebDriverWait(page, 10).until(lambda d: text(d, "#tr-plan"))
    minutes = round(plan["duration_s"] / 60)
    assert f"{round(plan['length_m'])} m there and back" in said, said
    assert f"about {minutes // 60} h {minutes % 60:02d} min at 0.10 m/s" in said, said
    # Previewed: the four waypoints, out and back from the rover.
    preview = page.find_element(By.ID, "map-preview")
    assert preview.get_attribute("data-waypoints") == "4"
    points = preview.find_element(By.TAG_NAME, "polyline").get_attribute("points").split()
    assert len(points) == 1 + 4 + 3 + 1
    assert not page.find_elements(By.ID, "map-driven")
    before = p.wait_value(keys.drive_state(R))
    clear_answers(page)
    click(page, f'[data-action="traverse-send"][data-rover="{R}"]')
    assert "traverse" in answer(page, "accepted")
    route = p.wait_value(keys.drive_route(R), lambda r: len(r["waypoints"]) == 4)
    assert [(w["x_m"], w["y_m"]) for w in route["waypoints"]] == [(80, 60), (170, 140), (190, 160),
                                                                    (200, 170)]
    WebDriverWait(page, 10).until(lambda d: not d.find_elements(By.ID, "map-preview"),
                                  "the preview to give way")
    p.put(keys.clock_control(R), {"time_scale": 50})
    # The marker follows drive/state: each time the rover has moved on, the page shows one of
    # the twin's positions, drawn where it is.
    seen, problems = [], []
    for _ in range(4):
        last = seen[-1]["x_m"] if seen else before["x_m"]
        p.wait_value(keys.drive_state(R), lambda d, last=last: d["x_m"] > last + 3, timeout_s=30)
        m = WebDriverWait(page, 10).until(
            lambda d, last=last: (x := d.execute_script(READ)) and x["x_m"] > last + 3 and x)
        published = [(s["x_m"], s["y_m"]) for s in p.samples(keys.drive_state(R))]
        if not any(math.isclose(m["x_m"], x, abs_tol=1e-9) and math.isclose(m["y_m"], y, abs_tol=1e-9)
                   for x, y in published):
            problems.append(f"the page shows the rover at {m['x_m']}, {m['y_m']}: no drive/state said so")
        problems += check_drawn(m)
        seen.append(m)
    assert not problems, "\n".join(problems)
    assert seen[-1]["x_m"] > seen[0]["x_m"] and seen[-1]["y_m"] > seen[0]["y_m"]  # north-east, up the route
    assert 0 < seen[-1]["heading"] < 90
    # Past the first waypoint (a picture with some route driven), still drawn where it is.
    p.put(keys.clock_control(R), {"time_scale": 100})
    p.wait_value(keys.drive_state(R), lambda d: d["x_m"] > 110, timeout_s=60)
    p.put(keys.clock_control(R), {"paused": True})
    p.wait_value(keys.clock(R), lambda c: c["paused"])
    m = WebDriverWait(page, 10).until(lambda d: (x := d.execute_script(READ)) and x["x_m"] > 110 and x)
    assert not check_drawn(m), check_drawn(m)
    clear_answers(page)
    shoot(page, artefacts, "map")
    p.put(keys.clock_control(R), {"paused": False, "time_scale": 1})


def test_waypoints_typed_and_clicked_are_previewed_sent_and_stopped(site, page):
    p = site.probe
    view(page, "map")
    click(page, '[data-map-fit="site"]')
    click(page, '[data-drive-mode="hand"]')
    click(page, "#wp-add")
    click(page, "#wp-add")
    for i, (x, y) in enumerate(((20, 10), (35, -5)), start=1):
        for k, v in (("east", x), ("north", y), ("up", 0)):
            fill(page, f'#wp-table input[aria-label="waypoint {i} {k}"]', str(v))
    # A third waypoint clicked near the map's east edge: past the lander's range (400 m east).
    svg = page.find_element(By.ID, "map-svg")
    width = svg.size["width"]
    page.execute_script("""
        const svg = arguments[0], r = svg.getBoundingClientRect();
        svg.dispatchEvent(new MouseEvent('click', {
            clientX: r.left + r.width - 8, clientY: r.top + r.height / 2, bubbles: true}));""", svg)
    rows = "#wp-table tr[data-waypoint]"
    WebDriverWait(page, 10).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, rows)) == 3)
    east = float(page.find_element(By.CSS_SELECTOR, '#wp-table input[aria-label="waypoint 3 east"]')
                 .get_attribute("value"))
    assert east > 400, (east, width)
    note = WebDriverWait(page, 10).until(lambda d: text(d, "#map-preview-note"))
    assert "waypoint 3 outside lander's range" in note, note
    assert page.find_element(By.ID, "map-preview").get_attribute("data-waypoints") == "3"
    click(page, '#wp-table [data-remove="3"]')
    WebDriverWait(page, 10).until(
        lambda d: d.find_element(By.ID, "map-preview").get_attribute("data-waypoints") == "2")
    assert "outside" not in text(page, "#map-preview-note")
    assert re.search(r"If sent now, from where the rover is: [\d.,]+ m, at the rover's top speed",
                     text(page, "#wp-plan"))
    fill(page, "#wp-speed", "0.05")
    WebDriverWait(page, 10).until(lambda d: "at 0.05 m/s" in text(d, "#wp-plan"))
    clear_answers(page)
    click(page, f'[data-action="traverse-go"][data-rover="{R}"]')
    assert "traverse" in answer(page, "accepted")
    route = p.wait_value(keys.drive_route(R), lambda r: [(w["x_m"], w["y_m"]) for w in r["waypoints"]]
                         == [(20, 10), (35, -5)])
    assert all(w["speed_m_per_s"] == 0.05 for w in route["waypoints"]) and not route["return_to_start"]
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#map-to-go"),
                                  "the route to go drawn")
    clear_answers(page)
    click(page, f'[data-action="traverse-stop"][data-rover="{R}"]')
    answer(page, "accepted")
    p.wait_value(keys.drive_state(R), lambda d: d.get("status") == "parked")
    WebDriverWait(page, 10).until(lambda d: not d.find_elements(By.CSS_SELECTOR, "#map-to-go, #map-driven"),
                                  "the route gone once the rover is parked")
    WebDriverWait(page, 10).until(lambda d: "parked" in text(d, "#drive-now"), "the rover said parked")


def test_a_radio_that_follows_the_drive_has_no_position_form(site, page):
    view(page, "inputs")
    box = WebDriverWait(page, 10).until(
        lambda d: d.find_element(By.CSS_SELECTOR, '[data-radio="lander"][data-follows-drive]'))
    assert "The drive sets where the rover is: move the rover on the map's drive panel instead" in box.text
    assert not page.find_elements(By.CSS_SELECTOR, '[data-action="input-position"]')
    click(page, '[data-to-map="lander"]')
    WebDriverWait(page, 10).until(lambda d: d.find_element(By.CSS_SELECTOR, '#views [data-view="map"]')
                                  .get_attribute("class") == "on")


def test_the_map_and_its_drive_panel_fit_a_laptop_and_a_tablet_and_speak_plainly(site, page, artefacts):
    fields = field_names()
    view(page, "map")
    problems = []
    for mode in ("file", "hand"):
        click(page, f'[data-drive-mode="{mode}"]')
        if mode == "hand" and not page.find_elements(By.CSS_SELECTOR, "#wp-table tr[data-waypoint]"):
            click(page, "#wp-add")
        for fit in ("site", "rover"):
            click(page, f'[data-map-fit="{fit}"]')
            for width, height, suffix in SIZES:
                size_viewport(page, width, height)
                view(page, "map")
                at = f"map, {mode}, {fit}, {width}x{height}"
                svg = page.find_element(By.ID, "map-svg").rect
                if svg["width"] < 0.55 * width or svg["height"] < 320:
                    problems.append(f"{at}: the map is only {svg['width']:.0f} x {svg['height']:.0f} px")
                problems += [f"{at}: {x}" for x in page.execute_script(LAYOUT)]
                if suffix:
                    problems += [f"{at}: a small touch target: {x}"
                                 for x in page.execute_script(TOUCH, TOUCH_PX)]
                problems += [f"{at}: {x}" for x in vocabulary(page.execute_script(TEXT), fields)]
                problems += [f"{at}: {x}" for x in check_drawn(read_map(page))]
                save_shot(page, artefacts, f"map-{mode}-{fit}{suffix}", doc=False)
    size_viewport(page, 1280, 800)
    click(page, '[data-map-fit="site"]')
    click(page, '[data-drive-mode="file"]')
    assert not problems, "\n".join(problems)


def test_the_faults_view_names_an_owner_that_does_not_answer(site, page, artefacts):
    """The battery service stopped: its fault is marked as the last known (its liveliness is
    gone), and the faults service's answer names it as not answering (a 502 from the console:
    D3); the page says so, and never "no active fault"."""
    p, twin = site.probe, site.twin
    p.put(keys.fault(R, "battery", "heating"), {"heat_w": 5})
    p.put(keys.fault(R, "solar/left", "dust"), {"fraction": 0.3})
    p.wait_event(R, lambda e: e["kind"] == "fault_injected" and "dust" in e["key"])
    view(page, "faults")
    dust = '#faults-list [data-fault="solar/left/dust"]'
    heating = '#faults-list [data-fault="battery/heating"]'
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, dust)
                                  and d.find_elements(By.CSS_SELECTOR, heating))
    assert not page.find_elements(By.ID, "faults-missing")
    stop_process(twin.procs["battery"], 10)
    try:
        row = WebDriverWait(page, 10).until(
            lambda d: d.find_element(By.CSS_SELECTOR, f"{heating}[data-stale]"), "the battery's fault marked")
        assert "last known: its battery service does not answer" in row.text
        said = WebDriverWait(page, 30).until(lambda d: text(d, "#faults-missing"), "the owner missing said")
        assert "Not every part of the rover answered" in said, said
        assert "the battery service of mapp-1 did not answer" in said, said
        assert page.find_elements(By.CSS_SELECTOR, dust)
        assert "No active fault." not in text(page, "#faults-list")
        problems = vocabulary(page.execute_script(TEXT), field_names())
        save_shot(page, artefacts, "faults-missing-owner", doc=False)
        assert not problems, "\n".join(problems)
    finally:
        twin.start("battery")
        p.wait_services(R, ("battery",))
    WebDriverWait(page, 30).until(lambda d: not d.find_elements(By.ID, "faults-missing"),
                                  "the battery to answer again")
    for component, kind in (("battery", "heating"), ("solar/left", "dust")):
        p.delete(keys.fault(R, component, kind))
    wait_for(lambda: not page.find_elements(By.CSS_SELECTOR, "#faults-list [data-fault]"), 10,
             "the faults cleared")
