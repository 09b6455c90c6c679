"""What the console's browser tests do on the page: wait, open a view, click, type, read an
answer."""

from __future__ import annotations

from selenium.common.exceptions import StaleElementReferenceException, TimeoutException, WebDriverException
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.ui import WebDriverWait as _Wait

from tests.console.conftest import settle


class _SayingWait(_Wait):
    """A wait whose timeout says what the page showed then: a wait that failed in a full run
    is understood from the log alone."""

    def until(self, method, message: str = ""):
        try:
            return super().until(method, message)
        except TimeoutException as exc:
            try:
                shown = self._driver.execute_script(
                    "const m = document.querySelector('main') || document.body; return m.innerText")
            except WebDriverException:
                shown = "(the page could not be read)"
            shown = " | ".join(line.strip() for line in str(shown).splitlines() if line.strip())
            raise TimeoutException(f"{message or 'the condition'}; the page showed: {shown[:1500]}",
                                   exc.screen, exc.stacktrace) from None


def WebDriverWait(driver, timeout_s: float) -> _Wait:  # noqa: N802 - selenium's own name
    """Selenium's wait, through the page re-drawing an element while it is looked at."""
    return _SayingWait(driver, timeout_s, poll_frequency=0.05,
                       ignored_exceptions=(StaleElementReferenceException,))


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


def fill(driver, selector: str, value: str) -> None:
    """Type ``value`` into the input found by ``selector``, again until the input holds it:
    a field the page re-draws as it is typed into (a form re-made once a select changed, a
    table once a value was read) lost what was typed, or kept half of it ("5" of "-5")."""
    def filled(d):
        box = d.find_element(By.CSS_SELECTOR, selector)
        if box.get_attribute("value") != value:
            box.clear()
            box.send_keys(value)
        return d.find_element(By.CSS_SELECTOR, selector).get_attribute("value") == value
    WebDriverWait(driver, 10).until(filled, f"{selector} to hold {value!r}")


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
