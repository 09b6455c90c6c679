"""The console says whether the crew's dashboard is receiving, and alarms the instructor when
it has been silent for 3 s during a session (SPEC 13d), from the bridge's ``bridge/delivery``.

The crew's dashboard here is a Zenoh subscriber on the bridge's JSON ``diagnostics`` topic (the
topic the bridge watches per Zenoh flavour): the bridge sees it through its publisher's
matching status. Undeclared, the page says "silent since ..." and raises the alarm; declared
again, "receiving" and the alarm gone.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import zenoh
from selenium.webdriver.common.by import By

from common import keys
from common.connection import make_config
from tests.console.conftest import Live, console_page, console_site
from tests.console.pages import WebDriverWait
from tests.harness import ALL_SERVICES, json_bridge_extra

pytestmark = pytest.mark.timeout(180)

R = "mapp-1"
SERVICES = (*ALL_SERVICES, "bridge")
WATCHED = "json/diagnostics"  # the rover's /diagnostics in the json flavour (a fleet of one)
STATUS = '#main [data-key="bridge/delivery"][data-field="receiving"]'
ALARM = f'[data-dashboard-alarm="{R}"]'


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    folder = tmp_path_factory.mktemp("console-dashboard")
    with console_site(folder, services=SERVICES, extra=json_bridge_extra(folder),
                      ready=lambda p: p.wait_value(keys.BRIDGE_DELIVERY.key(R))) as live:
        yield live


def status(driver) -> tuple[str, str]:
    found = driver.find_elements(By.CSS_SELECTOR, STATUS)
    return (found[0].get_attribute("data-dashboard"), found[0].text) if found else ("", "")


def test_the_page_says_when_the_crews_dashboard_goes_silent_and_alarms(site):
    probe = site.probe
    probe.put(keys.control_session(R), {"trainee": "Ada"})
    probe.wait_value(keys.clock(R), lambda c: bool(c["session"]))
    crew = zenoh.open(make_config("client", connect=[site.endpoint]))
    try:
        dashboard = crew.declare_subscriber(WATCHED, lambda _s: None)
        probe.wait_value(keys.BRIDGE_DELIVERY.key(R), lambda v: v["receiving"], timeout_s=15)
        with console_page(site) as driver:
            wait = WebDriverWait(driver, 15)
            wait.until(lambda d: status(d)[0] == "receiving", "the page says receiving")
            assert status(driver)[1] == "crew's dashboard: receiving"
            assert not driver.find_elements(By.CSS_SELECTOR, ALARM)

            dashboard.undeclare()  # the crew's dashboard hears nothing any more
            wait.until(lambda d: status(d)[0] == "silent", "the page says silent")
            assert status(driver)[1].startswith("crew's dashboard: silent since "), status(driver)
            banner = wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, ALARM), "the alarm")[0]
            assert banner.get_attribute("role") == "alert" and "The crew's dashboard on mapp-1" in banner.text
            probe.wait_event(R, lambda e: e["kind"] == "delivery" and e["severity"] == "warning")

            dashboard = crew.declare_subscriber(WATCHED, lambda _s: None)
            wait.until(lambda d: status(d)[0] == "receiving", "the page says receiving again")
            wait.until(lambda d: not d.find_elements(By.CSS_SELECTOR, ALARM), "the alarm gone")
    finally:
        crew.close()
