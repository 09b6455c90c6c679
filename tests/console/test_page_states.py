"""The page says where the console is with the twin, and with each rover, in the server's own
words (issue 26.7, SPEC 12f), in a real browser:

- the console started before the twin: "waiting for the twin at <endpoint>" on the page;
- the twin comes (a router and a rover whose clock ticks but whose services never answer):
  "twin connected", the rover's views;
- the rover's clock stops ticking: its link is lost, with the console's reason, within 3 s of the
  console saying so; a write then is "Not applied" with the reason, never "refused";
- the clock ticks again: the banner goes; a write nobody answers is "Not applied: no answer
  within 3 s";
- the router goes: "connection to the twin lost".
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from selenium.webdriver.common.by import By

from testbed.browser import open_browser
from testbed.twin import free_port
from tests.console.conftest import save_shot
from tests.console.page_checks import TEXT, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, text
from tests.console.test_server import FakeRover
from tests.harness import (
    ROOT,
    env_without_zenoh_config,
    free_endpoint,
    lunaris_cmd,
    open_router,
    stop_process,
)

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"


def _console(endpoint: str, port: int, folder: Path) -> subprocess.Popen:
    with open(folder / "console.log", "ab") as out:
        return subprocess.Popen(lunaris_cmd("console", "--http", f"127.0.0.1:{port}", "--connect", endpoint,
                                            "--recordings", str(folder / "recordings")),
                                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=ROOT,
                                env=env_without_zenoh_config())


@pytest.fixture
def browser() -> Iterator:
    with open_browser(1280, 800) as driver:
        yield driver


def plain(driver) -> list[str]:
    return vocabulary(driver.execute_script(TEXT), field_names())


def test_the_page_says_where_it_is_with_the_twin_and_with_each_rover(tmp_path, browser, artefacts):
    endpoint, port = free_endpoint(), free_port()  # nothing there yet
    console = _console(endpoint, port, tmp_path)
    router = rover = None
    problems: list[str] = []
    try:
        def loaded(d):
            assert console.poll() is None, (tmp_path / "console.log").read_text()
            try:
                d.get(f"http://127.0.0.1:{port}/")
                return True
            except Exception:  # noqa: BLE001 - not listening yet
                return False
        WebDriverWait(browser, 30).until(loaded, "the console's page")
        link = lambda d: text(d, "#link")  # noqa: E731
        WebDriverWait(browser, 10).until(lambda d: link(d) == f"waiting for the twin at {endpoint}")
        assert text(browser, "#waiting").startswith(
            f"Waiting for the twin at {endpoint}: nothing answers there yet")
        problems += plain(browser)
        save_shot(browser, artefacts, "waiting-for-the-twin", doc=False)

        router = open_router(endpoint)  # the twin comes
        rover = FakeRover(endpoint)
        WebDriverWait(browser, 20).until(lambda d: link(d) == "twin connected")
        tab = f'#rovers [data-rover-pick="{R}"]'
        WebDriverWait(browser, 20).until(lambda d: d.find_elements(By.CSS_SELECTOR, tab))
        first = WebDriverWait(browser, 10).until(lambda d: text(d, "#clock-t"), "the rover's clock")
        WebDriverWait(browser, 10).until(lambda d: text(d, "#clock-t") not in ("", first), "ticks")

        rover.ticking.clear()  # the rover's link is cut
        lost = '#main [data-link="lost"]'
        banner = WebDriverWait(browser, 10).until(lambda d: text(d, lost), "the link lost")
        assert banner.startswith(f"Link to {R} lost: no clock tick since "), banner
        assert "link lost" in text(browser, tab).lower()
        problems += plain(browser)
        save_shot(browser, artefacts, "rover-link-lost", doc=False)
        clear_answers(browser)
        click(browser, f'#clock [data-action="clock-pause"][data-rover="{R}"]')
        said = answer(browser, "not applied")
        assert said.startswith("Not applied:") and f"the link to {R} is lost" in said, said
        assert not browser.find_elements(By.CSS_SELECTOR, '#answers .answer[data-verdict="rejected"]')

        rover.ticking.set()  # back: nobody answers a write, though
        WebDriverWait(browser, 10).until(lambda d: not d.find_elements(By.CSS_SELECTOR, lost))
        clear_answers(browser)
        click(browser, f'#clock [data-action="clock-pause"][data-rover="{R}"]')
        said = answer(browser, "not applied", timeout_s=15)
        assert said.startswith("Not applied: no answer within 3 s"), said

        rover.close()
        rover = None
        router.close()  # the twin goes
        router = None
        WebDriverWait(browser, 20).until(lambda d: link(d) == "connection to the twin lost")
        assert text(browser, '#main [data-router="lost"]').startswith("Connection to the twin lost: ")
        problems += plain(browser)
        save_shot(browser, artefacts, "twin-lost", doc=False)
    finally:
        stop_process(console, 10)
        if rover is not None:
            rover.close()
        if router is not None:
            router.close()
    assert not problems, "\n".join(problems)
