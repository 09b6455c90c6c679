"""Trainee sessions from the console's page (SPEC §12c, issue 25): two trainees in a row.

A twin of the MAPP rover (without its drive) and a console; in a real browser at 1280x800, an
instructor runs a training day from the Session view:

- the twin's first session (no trainee named) runs to a later sim time at x50 and a snapshot
  "late" is saved there from the page;
- "New trainee" Ana (the rover file): a bad name is refused in the server's words and nothing
  is sent; the header names Ana and her session's id; a fault injected and cleared, and a mark
  from the page, show in her event log;
- "New trainee" Ben from the snapshot "late": the header names Ben; the event log holds
  nothing of Ana's session (every event is Ben's session's, none names her fault or her mark),
  and the plots nothing of her history (every point the page keeps and draws is at or after
  the sim time Ben's session began from, later than anything of Ana's); Ben's mark shows;
- the sessions list shows the three sessions: Ben's running, Ana's ended, the first; the view
  fits and speaks plainly (a session is named by when it began, never by a long number).
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.select import Select

from common import keys
from tests.console.conftest import Live, console_page, console_site, shoot
from tests.console.page_checks import LAYOUT, TEXT, field_names, vocabulary
from tests.console.pages import WebDriverWait, answer, clear_answers, click, view
from tests.harness import wait_for

pytestmark = pytest.mark.timeout(300)

R = "mapp-1"
LATE_S = 400.0  # the sim time the snapshot "late" is saved at: later than anything of Ana's


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Live]:
    with console_site(tmp_path_factory.mktemp("console-sessions")) as live:
        yield live


@pytest.fixture(scope="module")
def page(site) -> Iterator:
    with console_page(site) as driver:
        yield driver


def page_state(driver) -> dict:
    """What the page keeps and draws of the rover: its events, its plots' history, the sim
    times the plots draw, and the session the page says runs."""
    driver.set_script_timeout(10)
    got = driver.execute_async_script("""
        const rover = arguments[0], done = arguments[arguments.length - 1];
        Promise.all([import('/static/state.js'), import('/static/charts.js')]).then(([s, c]) => done({
          events: s.store.events[rover] ?? [], history: s.store.history[rover] ?? null,
          plotted: c.plotted(), session: s.store.sessions[rover] ?? null}),
        (e) => done({error: String(e)}));""", R)
    assert "error" not in got, got
    return got


def header(driver) -> tuple[str, str]:
    """(trainee, session id) as the top bar names them."""
    found = driver.find_elements(By.CSS_SELECTOR, "#trainee #trainee-now")
    return (found[0].text, found[0].get_attribute("data-session")) if found else ("", "")


def log_text(driver) -> str:
    return driver.find_element(By.ID, "events-list").text


def new_trainee(driver, name: str, snapshot: str = "") -> str:
    """Type the name, choose where to start from, click New trainee, accept; the answer's text."""
    clear_answers(driver)
    box = driver.find_element(By.ID, "trainee-name")
    box.clear()
    box.send_keys(name)
    if snapshot:
        WebDriverWait(driver, 10).until(lambda d: d.find_elements(
            By.CSS_SELECTOR, f'#trainee-from option[value="{snapshot}"]'))
    Select(driver.find_element(By.ID, "trainee-from")).select_by_value(snapshot)
    click(driver, f'[data-action="session-start"][data-rover="{R}"]')
    alert = WebDriverWait(driver, 10).until(ec.alert_is_present())
    assert name in alert.text and R in alert.text
    alert.accept()
    return answer(driver, "accepted", 15)


def mark(driver, text: str) -> None:
    clear_answers(driver)
    box = driver.find_element(By.ID, "mark-text")
    box.clear()
    box.send_keys(text)
    click(driver, f'[data-action="mark"][data-rover="{R}"]')
    assert text in answer(driver, "accepted")
    WebDriverWait(driver, 10).until(lambda d: text in log_text(d), f"the mark {text!r} in the event log")


def test_two_trainees_in_a_row_from_the_page(site, page, artefacts):
    p = site.probe
    view(page, "session")
    first = WebDriverWait(page, 10).until(lambda d: header(d)[1] or False, "the first session in the header")
    assert header(page)[0] == "no trainee named"
    # The twin's first session runs on to LATE_S; a snapshot is saved there from the page.
    p.put(keys.clock_control(R), {"time_scale": 50})
    p.wait_value(keys.clock(R), lambda c: c["t_s"] >= LATE_S, timeout_s=60)
    p.put(keys.clock_control(R), {"time_scale": 1})
    p.wait_value(keys.clock(R), lambda c: c["time_scale"] == 1)
    name = page.find_element(By.ID, "snap-name")
    name.clear()
    name.send_keys("late")
    # the sim time before the save: the snapshot's is at least this (read after it, on a busy
    # machine the clock had gone on more than a second past the snapshot)
    late_t = p.wait_value(keys.clock(R))["t_s"]
    click(page, f'[data-action="snapshot-save"][data-rover="{R}"]')
    WebDriverWait(page, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, '[data-snapshot="late"]')
                                  or d.find_element(By.ID, "snap-refresh").click())

    # A bad name: refused in the server's words, nothing sent, the session goes on.
    seen = len(p.events(R))
    clear_answers(page)
    box = page.find_element(By.ID, "trainee-name")
    box.send_keys("Ana <3;")
    click(page, f'[data-action="session-start"][data-rover="{R}"]')
    said = answer(page, "invalid")
    assert "trainee's name is letters, digits, spaces" in said and "'<', ';'" in said, said
    # refused before the page asks to end the running session for it (it asked first)
    assert not ec.alert_is_present()(page)
    assert header(page)[1] == first
    p.put(keys.under(R, "control/rewind"), b"")  # a probe's put, after: the first thing heard
    p.wait_event(R, lambda e: e["key"] == keys.under(R, "control/rewind"))
    assert not [e for e in p.events(R)[seen:] if e["key"].endswith("control/session")]

    # Ana, from the rover file.
    said = new_trainee(page, "Ana")
    assert re.search(r"session \d+ \w{3} [\d:]{8} of 'Ana' begins", said), said
    WebDriverWait(page, 10).until(lambda d: header(d)[0] == "Ana", "the header to name Ana")
    ana = header(page)[1]
    assert ana != first
    named = page.find_element(By.CSS_SELECTOR, "#trainee small")  # the session by when it began
    assert ana in named.get_attribute("title")
    assert re.fullmatch(r"session of \d+ \w{3} \d\d:\d\d:\d\d", named.text), named.text
    assert page.find_element(By.ID, "session-answer").get_attribute("data-verdict") == "accepted"
    p.put(keys.fault(R, "solar/left", "dust"), {"fraction": 0.4})
    WebDriverWait(page, 10).until(lambda d: "solar/left/dust" in log_text(d), "Ana's fault in the log")
    p.delete(keys.fault(R, "solar/left", "dust"))
    cleared = lambda d: any(e["kind"] == "fault_cleared" for e in page_state(d)["events"])  # noqa: E731
    WebDriverWait(page, 10).until(cleared, "Ana's fault cleared in the log")
    mark(page, "Ana cleaned the left panel")
    # who acted, in the log: the instructor's mark (the crew's calls read "by the crew")
    line = next(x for x in log_text(page).splitlines() if "Ana cleaned the left panel" in x)
    assert "by the instructor" in line, line
    view(page, "live")
    WebDriverWait(page, 20).until(lambda d: len((page_state(d)["plotted"] or [[]])[0]) >= 3, "Ana's plots")
    ana_t = max(page_state(page)["history"]["t"])
    assert ana_t < late_t
    view(page, "session")

    # Ben, from the snapshot "late".
    said = new_trainee(page, "Ben", "late")
    assert re.search(r"session \d+ \w{3} [\d:]{8} of 'Ben' begins: snapshot 'late' restored", said), said
    WebDriverWait(page, 10).until(lambda d: header(d)[0] == "Ben", "the header to name Ben")
    ben = header(page)[1]
    assert ben not in (first, ana)
    mark(page, "Ben starts late")
    view(page, "live")
    WebDriverWait(page, 20).until(lambda d: len((page_state(d)["plotted"] or [[]])[0]) >= 2, "Ben's plots")
    state = page_state(page)
    assert state["session"]["id"] == ben and state["session"]["trainee"] == "Ben"
    assert state["events"] and {e.get("session") for e in state["events"]} == {ben}, \
        [(e["kind"], e.get("session"), e["message"]) for e in state["events"] if e.get("session") != ben]
    text = log_text(page)
    assert "Ana" not in text and "solar/left/dust" not in text and "dust" not in text, text
    assert "Ben starts late" in text
    assert min(state["history"]["t"]) >= late_t - 1, state["history"]["t"][:10]
    for drawn in state["plotted"]:
        assert drawn and min(drawn) >= late_t - 1 > ana_t, drawn[:10]

    shoot(page, artefacts, "sessions-live", doc=False)

    # The sessions list: Ben's running, Ana's ended, the first.
    view(page, "session")
    def rows(d) -> dict[str, tuple[str, str]]:
        return {r.get_attribute("data-session"): (r.get_attribute("data-trainee"), r.text)
                for r in d.find_elements(By.CSS_SELECTOR, "#sessions tr[data-session]")}
    listed = lambda d: ben in rows(d) or d.find_element(By.ID, "sessions-refresh").click()  # noqa: E731
    WebDriverWait(page, 15).until(listed, "Ben's session in the list")
    got = rows(page)
    assert [got[s][0] for s in (first, ana, ben)] == ["", "Ana", "Ben"], got
    assert "running" in got[ben][1] and "running" not in got[ana][1] and "(no trainee named)" in got[first][1]
    assert "from snapshot late" in got[ben][1]
    shoot(page, artefacts, "sessions")
    problems = [f"session view: {x}" for x in page.execute_script(LAYOUT)]
    problems += [f"session view: {x}" for x in vocabulary(page.execute_script(TEXT), field_names())]
    assert not problems, "\n".join(problems)
    wait_for(lambda: site.console.get(f"/api/rovers/{R}/sessions")[0] == 200, 10, "the sessions API")
    _, infos = site.console.get(f"/api/rovers/{R}/sessions")
    assert [s["trainee"] for s in infos] == ["", "Ana", "Ben"], infos
    # The journal through the console: the running session's by default, another's by its id.
    _, hers = site.console.get(f"/api/rovers/{R}/journal?session={ana}")
    _, his = site.console.get(f"/api/rovers/{R}/journal")
    assert {e["session"] for e in hers} == {ana} and {e["session"] for e in his} == {ben}
    assert any(e["kind"] == "mark" and e["params"]["text"] == "Ana cleaned the left panel" for e in hers)
    assert not [e for e in his if e["kind"] in ("fault_injected", "fault_cleared")], his
    assert site.console.get(f"/api/rovers/{R}/journal?session=yesterday")[0] == 422


FOLD = """
const messages = arguments[0], done = arguments[arguments.length - 1];
Promise.all([import('/static/stream.js'), import('/static/state.js')]).then(([stream, state]) => {
  for (const m of messages) stream.receive(m);
  const rover = 'race-1';
  const events = (state.store.events[rover] ?? []).map((e) => e.message);
  done({t: state.store.history[rover]?.t ?? [], events});
}, (e) => done({error: String(e)}));
"""


def test_a_value_of_the_last_session_heard_late_is_not_plotted(page):
    """The race the console cannot see: the battery's last value of Ana's session (sim time
    13 s) is heard after the tick that begins Ben's (from a snapshot at 500 s), before the
    clock's event that says where it began. The page drops it, and Ana's event that comes
    late, so Ben's plots begin at 500 s. Fed to the page's own stream folding, for a rover of
    its own (the live rover's state is left alone)."""
    r, ana, ben = "race-1", "20000101-000000", "20000101-000100"

    def battery(t: float) -> dict:
        return {f"lunaris/{r}/battery/state": {"t_s": t, "soc": 0.9, "temperature_c": 20.0}}

    def event(session: str, kind: str, message: str, params: dict | None = None) -> dict:
        return {"t_s": 0, "severity": "info", "source": "clock" if kind == "session" else "faults",
                "kind": kind, "key": f"lunaris/{r}/control/x", "message": message, "params": params,
                "session": session}

    messages = [{"type": "batch", "sessions": {r: {"id": ana, "trainee": "Ana"}}, "values": battery(t)}
                for t in (10.0, 11.0, 12.0)]
    messages += [  # as the twin says it: the clock's first tick of Ben's session, then its event
        {"type": "batch", "sessions": {r: {"id": ben, "trainee": None}},
         "values": {f"lunaris/{r}/clock": {"t_s": 500.2, "session": ben}}},
        {"type": "batch", "values": battery(13.0), "events": [event(ana, "mark", "mark: Ana, late")]},
        {"type": "batch", "events": [
            event(ben, "session", "Ben begins", {"session": ben, "trainee": "Ben", "start_t_s": 500.0})]},
        {"type": "batch", "values": battery(500.1)},
        {"type": "batch", "values": battery(502.0)},
    ]
    page.set_script_timeout(10)
    got = page.execute_async_script(FOLD, messages)
    assert got == {"t": [500.1, 502.0], "events": ["Ben begins"]}, got


def test_a_long_mark_shows_its_start_in_the_log_and_the_whole_on_hover(site, page):
    """A mark of 500 characters (the most it holds) filled the event log: its line shows the
    first 240, the whole in its title."""
    text = " ".join(f"note {i:02} of the crew's long pause at the rim;" for i in range(11))
    assert 450 < len(text) <= 500, len(text)
    site.probe.put(keys.control_mark(R), {"text": text})
    view(page, "live")
    line = WebDriverWait(page, 10).until(lambda d: next(
        (e for e in d.find_elements(By.CSS_SELECTOR, '#events-list [data-kind="mark"]')
         if e.get_attribute("title") == text), None), "the long mark in the event log")
    shown = line.text
    assert "note 00 of" in shown and "note 10 of" not in shown and "…" in shown, shown
    assert len(shown) < 320, len(shown)
