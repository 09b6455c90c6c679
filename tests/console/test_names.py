"""Names the twin's keys hold reach the page as text, never as markup (issue 23.5).

Anyone who may publish on a twin (every client of a twin without access control, any service
identity of a deployment) can publish a key whose name chunk holds HTML: a load, rail, panel
or radio called ``a"><img src=nope onerror=...>``, a rover with such an id, an event or an
active fault that names one. The page must show those names as the text they are, and no
markup of theirs may reach the document, on every view.
"""

from __future__ import annotations

import pytest
from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait as _Wait

from common import keys
from tests.console.conftest import R, shoot

pytestmark = pytest.mark.timeout(120)


def hostile(where: str) -> list[str]:
    """Two names for ``where``: one that closes an attribute first, one plain tag."""
    return [f"a\"><img src=nope onerror=window.pwned='{where}-attr'>",
            f"<img src=nope onerror=window.pwned='{where}-tag'>"]


LOADS, RAILS, PANELS, RADIOS = hostile("load"), hostile("rail"), hostile("solar"), hostile("radio")
ROVER = "<img src=nope onerror=window.pwned='rover'>"
EVENT = "<img src=nope onerror=window.pwned='event'> and <b>bold</b>"
SERVICE = hostile("faults")[0]
FAULT = f"{keys.ROOT}/{R}/fault/load/{LOADS[1]}/short"


def forge(p) -> None:
    """What a client that may publish on the twin can put there."""
    for name in LOADS:
        p.put(keys.load_power(R, name), {"t_s": 1.0, "power_w": 1.5, "rail": "12V", "on": True, "faults": []})
    for name in RAILS:
        p.put(keys.rail_state(R, name), {"t_s": 1.0, "voltage_v": 12.0, "current_a": 0.1, "power_w": 1.2,
                                         "current_limit_a": 2.0, "state": "on"})
    for name in PANELS:
        p.put(keys.solar_power(R, name), {"t_s": 1.0, "power_w": 10.0, "sun_angle_deg": 60.0, "dust": 0.0})
    for name in RADIOS:
        p.put(keys.radio_link(R, name), {"t_s": 1.0, "in_range": True, "x_m": 5.0, "y_m": 0.0})
    p.put(keys.faults_active(R, SERVICE), {
        "t_s": 1.0, "service": SERVICE, "faults": [{"key": FAULT, "params": {LOADS[0]: 1}, "since_t_s": 1.0,
                                                    "origin": "injected", "severity": "critical"}]})
    p.put(keys.event(R), {"t_s": 1.0, "severity": "warning", "source": SERVICE, "kind": "fault_injected",
                          "key": FAULT, "message": EVENT})
    p.put(keys.battery_state(ROVER), {
        "t_s": 1.0, "energy_j": 1.0, "capacity_j": 2.0, "soc": 0.5, "ocv_v": 3.7, "voltage_v": 3.7,
        "current_a": 0.0, "power_w": 0.0, "temperature_c": 20.0, "operational": True, "fault_code": 0,
        "faults": [], "time_to_empty_s": None})


def WebDriverWait(driver, timeout_s: float) -> _Wait:  # noqa: N802 - selenium's own name
    """Selenium's wait, through the page re-drawing an element while it is looked at."""
    return _Wait(driver, timeout_s, poll_frequency=0.05, ignored_exceptions=(StaleElementReferenceException,))


def pick_rover(driver, starts: str) -> None:
    """Click the rover's button in the top bar (found again if the page re-draws it)."""
    xpath = f'//nav[@id="rovers"]//button[starts-with(normalize-space(.), "{starts}")]'
    WebDriverWait(driver, 10).until(lambda d: d.find_element(By.XPATH, xpath).click() or True)
    WebDriverWait(driver, 10).until(lambda d: "on" in d.find_element(By.XPATH, xpath).get_attribute("class"))


MARKUP = """return {
  pwned: window.pwned === undefined ? null : String(window.pwned),
  markup: [...document.querySelectorAll('img, svg, [onerror], [onload]')]
    .filter((e) => !e.closest('.uplot')).map((e) => e.outerHTML),
}"""


def no_script_ran(driver) -> None:
    """No element of a name's markup is in the document, and no handler of one ran: an image
    of our own that fails to load is waited for, so the hostile ones (requested before it) have
    had their turn too."""
    driver.set_script_timeout(10)
    driver.execute_async_script("""
        const done = arguments[0], img = new Image();
        img.onerror = img.onload = () => setTimeout(done, 0);
        img.src = '/static/no-such-image-' + Math.random();""")
    found = driver.execute_script(MARKUP)
    assert found == {"pwned": None, "markup": []}


def view(driver, name: str) -> None:
    driver.find_element(By.CSS_SELECTOR, f'#views [data-view="{name}"]').click()
    WebDriverWait(driver, 10).until(lambda d: d.find_element(
        By.CSS_SELECTOR, f'#views [data-view="{name}"]').get_attribute("class") == "on")


def shows(driver, names: list[str], where: str = "#main") -> None:
    """Every name appears as text in ``where`` (re-read until the page has drawn it)."""
    def check(d):
        text = d.execute_script("return document.querySelector(arguments[0]).textContent", where)
        missing = [n for n in names if n not in text]
        return not missing or False
    WebDriverWait(driver, 10).until(check, f"{names} shown as text in {where}")


def test_hostile_names_show_as_text_and_never_run(live, browser, artefacts):
    browser.get(live.console.url + "/")
    WebDriverWait(browser, 20).until(
        lambda d: d.find_elements(By.CSS_SELECTOR, '#main [data-key="battery/state"]'))
    forge(live.probe)
    shows(browser, [ROVER], "#rovers")
    # The twin's own rover, then each of its views with the forged names in them.
    pick_rover(browser, R)
    view(browser, "live")
    shows(browser, LOADS + RAILS + PANELS + RADIOS + [EVENT, f"Load {LOADS[1]}: Short circuit"])
    no_script_ran(browser)
    shoot(browser, artefacts, "hostile-names-live", doc=False)
    view(browser, "faults")
    comps = lambda d: d.execute_script(  # noqa: E731 - read inside the wait
        "return [...document.querySelectorAll('#f-comp option')].map((o) => o.textContent).join('\\n')")
    WebDriverWait(browser, 10).until(lambda d: all(n in comps(d) for n in LOADS + RAILS + PANELS + RADIOS))
    shows(browser, [EVENT, f"Load {LOADS[1]}: Short circuit"])
    no_script_ran(browser)
    view(browser, "inputs")
    shows(browser, PANELS + RADIOS)
    no_script_ran(browser)
    for other in ("session", "scenarios", "recordings"):
        view(browser, other)
        no_script_ran(browser)
    # The forged rover itself: its button, its views.
    pick_rover(browser, "<img")
    for other in ("live", "faults", "inputs", "session"):
        view(browser, other)
        no_script_ran(browser)
