"""A twin, the console serving it, and a headless Chromium: what the console's tests share.

The console runs as ``lunaris console`` in its own process, as an instructor runs it; the
browser is Debian's Chromium driven by Selenium (``make test`` installs both as root, see the
Makefile's ``system-deps``). Screenshots of each view are saved under the session's artefact
folder (printed at the end), and into ``docs/images`` with ``LUNARIS_DOC_IMAGES=1``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh
from selenium.common.exceptions import TimeoutException

from common import keys
from common.connection import make_config
from testbed.browser import available, open_browser, size_viewport
from testbed.console import Console, start_console
from tests.harness import (
    ALL_SERVICES,
    ROOT,
    Probe,
    Twin,
    free_endpoint,
    open_router,
    static_rover,
    stop_process,
)

R = "mapp-1"
MAPP = static_rover("mapp.yaml")
DOC_IMAGES = ROOT / "docs" / "images"

if not available():
    pytest.skip("Debian's chromium and chromium-driver are not installed (make system-deps as root)",
                allow_module_level=True)


# the page shows the twin: the battery's charge, as "97.3 %"
SOC_SHOWN = (r"""const e = document.querySelector('#main [data-key="battery/state"][data-field="soc"]');"""
             r"""return e && /\d+\.\d %/.test(e.textContent);""")


@dataclass
class Live:
    endpoint: str
    twin: Twin
    probe: Probe
    console: Console
    folder: Path


@contextmanager
def console_site(folder: Path, *console_args: str, rover: Path = MAPP,
                 services: tuple[str, ...] = ALL_SERVICES,
                 ready: Callable[[Probe], object] | None = None,
                 extra: dict[str, list[str]] | None = None) -> Iterator[Live]:
    """A router on a free port, a twin of ``rover`` with ``services`` (``extra``: more
    arguments per service), a probe watching the rover, and a console started with
    ``console_args`` once the twin is ``ready`` (default: the battery publishes); everything
    stopped, and the console's log printed, at the end."""
    endpoint = free_endpoint()
    router = open_router(endpoint)
    try:
        with Twin(endpoint, [rover], folder / "state", services=services, extra=extra) as twin, \
                Probe(endpoint) as p:
            p.watch(f"{keys.ROOT}/{R}/**")
            p.wait_services(R, services)
            if ready is None:
                p.wait_value(keys.battery_state(R))
            else:
                ready(p)
            console = start_console(endpoint, folder, *console_args)
            try:
                yield Live(endpoint, twin, p, console, folder)
            finally:
                stop_process(console.proc, 10)
                print(f"--- console log ---\n{console.log.read_text()[-3000:]}")
    finally:
        router.close()


@contextmanager
def console_page(site: Live, ready: str = SOC_SHOWN) -> Iterator:
    """Chromium at 1280x800 on the console's page, once ``ready`` (a script returning
    something truthy) says the page shows the twin."""
    with open_browser(1280, 800) as driver:
        driver.get(site.console.url + "/")
        from tests.console.pages import WebDriverWait as SayingWait  # (pages imports this module)
        try:  # (the wait of tests.console.pages says what the page showed)
            SayingWait(driver, 30).until(lambda d: d.execute_script(ready), "the page showing the twin")
        except TimeoutException as exc:  # and the console: running or not, its log (a full run
            # failed here twice in a row, for a reason its log would have said)
            raise TimeoutException(f"{exc.msg}\n{site.console.why_down()}") from None
        yield driver


@pytest.fixture
def session(router) -> Iterator[zenoh.Session]:
    """A Zenoh client of the test's router (a module may give its own)."""
    s = zenoh.open(make_config("client", connect=[router]))
    try:
        yield s
    finally:
        s.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory) -> Iterator[Live]:
    folder = tmp_path_factory.mktemp("console")
    scenarios = folder / "scenarios"
    scenarios.mkdir()
    (scenarios / "short-drill.yaml").write_text(SCENARIO)
    def drawing(p: Probe) -> None:
        p.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
    with console_site(folder, "--scenarios", str(scenarios), ready=drawing) as site:
        yield site


SCENARIO = """\
scenario: {name: Short drill, description: dust on the left panel for a moment}
rover: mapp-1
start: reset
time_scale: 5
steps:
  - name: dust settles
    at_s: 2
    inject: {component: solar/left, kind: dust, value: 0.25}
  - name: dust blown off
    after_s: 3
    clear: {component: solar/left, kind: dust}
"""


@pytest.fixture(scope="session")
def artefacts(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("screenshots")
    yield folder
    print(f"\nconsole screenshots: {folder}")


@pytest.fixture(scope="module")
def browser(live) -> Iterator:
    with open_browser(1280, 800) as driver:
        yield driver


def settle(driver) -> None:
    """Two animation frames: the page has laid itself out again (after a resize, a click)."""
    driver.set_script_timeout(10)
    driver.execute_async_script(
        "const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(() => done()));")


TABLET = (820, 1180)


def save_shot(driver, artefacts: Path, name: str, doc: bool = True) -> Path:
    """What the page shows now, kept as a test artefact (and as ``docs/images/console-<name>.png``
    with ``LUNARIS_DOC_IMAGES=1``, unless ``doc`` is false)."""
    settle(driver)
    path = artefacts / f"{name}.png"
    driver.save_screenshot(str(path))
    if doc and os.environ.get("LUNARIS_DOC_IMAGES"):
        DOC_IMAGES.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(DOC_IMAGES / f"console-{name}.png"))
    return path


def shoot(driver, artefacts: Path, name: str, doc: bool = True) -> Path:
    """Screenshots of what the page shows on a 1280x800 laptop (``<name>``) and an 820x1180
    tablet (``<name>-tablet``); the page is left at the laptop's size."""
    try:
        size_viewport(driver, *TABLET)
        save_shot(driver, artefacts, f"{name}-tablet", doc)
    finally:
        size_viewport(driver, 1280, 800)
    return save_shot(driver, artefacts, name, doc)
