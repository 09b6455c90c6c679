"""What the console's browser tests do on the page: wait, open a view, click, read an answer."""

from __future__ import annotations

from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.ui import WebDriverWait as _Wait

from tests.console.conftest import settle


def WebDriverWait(driver, timeout_s: float) -> _Wait:  # noqa: N802 - selenium's own name
    """Selenium's wait, through the page re-drawing an element while it is looked at."""
    return _Wait(driver, timeout_s, poll_frequency=0.05, ignored_exceptions=(StaleElementReferenceException,))


def view(driver, name: str) -> None:
    tab = f'#views [data-view="{name}"]'
    WebDriverWait(driver, 10).until(lambda d: d.find_element(By.CSS_SELECTOR, tab).click() or True)
    WebDriverWait(driver, 10).until(lambda d: d.find_element(
        By.CSS_SELECTOR, f'#views [data-view="{name}"]').get_attribute("class") == "on")
    settle(driver)


def click(driver, selector: str) -> None:
    """Click the element once it is clickable (scrolled into view first); the click is inside
    the wait, so an element the page re-draws between being found and being clicked is found
    again."""
    clickable = ec.element_to_be_clickable((By.CSS_SELECTOR, selector))

    def clicked(d):
        element = clickable(d)
        if not element:
            return False
        d.execute_script("arguments[0].scrollIntoView({block: 'center'})", element)
        element.click()
        return True
    WebDriverWait(driver, 10).until(clicked, f"{selector} to be clicked")


def answer(driver, verdict: str, timeout_s: float = 10.0) -> str:
    """The text of the newest answer with this verdict, once there is one."""
    def check(d):
        got = d.find_elements(By.CSS_SELECTOR, f'#answers .answer[data-verdict="{verdict}"]')
        return got[0].get_attribute("textContent") if got else False
    return WebDriverWait(driver, timeout_s).until(check, f"an answer {verdict!r}")


def clear_answers(driver) -> None:
    driver.execute_script("document.querySelectorAll('#answers .answer').forEach((e) => e.remove())")


def text(driver, selector: str) -> str:
    found = driver.find_elements(By.CSS_SELECTOR, selector)
    return found[0].text if found else ""
