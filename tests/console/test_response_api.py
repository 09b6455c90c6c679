"""The console's live view of the crew's response (SPEC 12d): ``GET /api/rovers/<rover>/response``
against a router and samples of the test's own (a clock naming its session, the services'
events on their own keys): the fault with the time since its injection, the crew's action once
it came, the scenario's expectation as it is met, nothing of the session before."""

from __future__ import annotations

import itertools

import msgspec
import pytest
import zenoh
from starlette.testclient import TestClient

from common import keys
from common.connection import make_config
from common.messages import Clock, Event, LoadPower, RailState
from lunaris.console.server import make_app
from tests.harness import wait_for

pytestmark = pytest.mark.timeout(90)
R = "mapp-1"
ONE, TWO = "20261125-090000", "20261125-100000"  # the clock's session ids


class Twin:
    """What the console hears of a rover: its ticks and its services' events."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.seq = itertools.count(1)

    def tick(self, t: float, sid: str, epoch: int = 0, rail: str = "on") -> None:
        self.session.put(keys.clock(R), msgspec.json.encode(
            Clock(t_s=t, dt_s=0.1, seq=int(t * 10), time_scale=1.0, paused=False, epoch=epoch, session=sid)))
        self.session.put(keys.rail_state(R, "5V_CH2"), msgspec.json.encode(
            RailState(t, 5.0, 0.5, 2.5, 5.0, rail)))  # type: ignore[arg-type]
        self.session.put(keys.load_power(R, "nav_camera"), msgspec.json.encode(
            LoadPower(t, 2.5 if rail == "on" else 0.0, "5V_CH2", rail == "on", [])))

    def event(self, t: float, sid: str, source: str, kind: str, key: str, actor: str, params=None) -> None:
        ev = Event(t_s=t, severity="info", source=source, kind=kind, key=f"lunaris/{R}/{key}",
                   message=kind, params=params, source_id=f"test-{source}", seq=next(self.seq),
                   actor=actor, session=sid)
        self.session.put(keys.event_of(R, source), msgspec.json.encode(ev))


def _live(c: TestClient) -> dict:
    r = c.get(f"/api/rovers/{R}/response")
    return r.json() if r.status_code == 200 else {}


def test_the_console_shows_the_crews_response_live_in_the_running_session(session, router):
    app = make_app(session, None)
    feed = zenoh.open(make_config("client", connect=[router]))
    twin = Twin(feed)
    try:
        with TestClient(app, base_url="http://127.0.0.1:8080") as c:
            assert c.get("/api/rovers/nobody/response").status_code == 404
            wait_for(lambda: app.app.state.hub.started, 10, "the console to subscribe")
            twin.tick(1.0, ONE)
            twin.event(1.5, ONE, "battery", "fault_injected", "fault/battery/heating", "instructor",
                       {"heat_w": 30})  # the first trainee's: not the second's
            for i in range(5):
                twin.tick(i / 10, TWO, epoch=1)
            # the twin runs a while (each key is a stream of its own: the console knows the
            # camera's rail once its power has come)
            wait_for(lambda: _live(c).get("session") == TWO and _live(c)["t_s"] == 0.4, 10,
                     lambda: f"the console in the second session: {_live(c)}")
            twin.event(0.4, TWO, "loads", "fault_injected", "fault/load/nav_camera/short", "scenario",
                       {"resistance_ohm": 0.1})
            twin.tick(0.5, TWO, epoch=1, rail="tripped")
            twin.event(0.5, TWO, "power", "fault_raised", "rail/5V_CH2/tripped", "twin")
            twin.tick(3.0, TWO, epoch=1, rail="tripped")
            wait_for(lambda: _live(c).get("faults") and _live(c)["t_s"] == 3.0, 10,
                     lambda: f"the console to measure the short: {_live(c)}")
            live = _live(c)
            assert (live["rover"], live["session"]) == (R, TWO)
            (f,) = live["faults"]  # nothing of the first session
            assert f["fault"] == "load/nav_camera/short" and f["injected_by"] == "scenario"
            assert (f["since_injection_s"], f["first_symptom_t_s"], f["crew_acted"]) == (
                pytest.approx(2.6), 0.5, False)
            version = live["version"]

            twin.event(3.5, TWO, "power", "command", "cmd/rail/5V_CH2", "crew", {"on": False, "reset": False})
            twin.event(4.0, TWO, "faults", "scenario", "control/scenario", "scenario", {
                "scenario": "drill", "what": "expect", "step": 2, "expectation": {
                    "index": 1, "label": "isolate the shorted camera",
                    "condition": "rail.5V_CH2.state == off", "within_s": 60.0, "met": True,
                    "at_t_s": 3.6, "armed_t_s": 0.4, "start_t_s": 0.0}})
            twin.tick(4.0, TWO, epoch=1, rail="off")
            wait_for(lambda: _live(c).get("expectations"), 10, "the expectation to be scored")
            live = _live(c)
            (f,) = live["faults"]
            assert f["crew_acted"] and f["first_crew_action_t_s"] == 3.5 and live["version"] > version
            assert [(a["action"], a["target"], a["accepted"]) for a in f["crew_actions"]] == [
                ("rail off", "5V_CH2", True)]
            (e,) = live["expectations"]
            assert (e["label"], e["met"], e["at_t_s"], e["within_s"]) == (
                "isolate the shorted camera", True, 3.6, 60.0)
    finally:
        feed.close()
