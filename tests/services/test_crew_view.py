"""What the crew sees (SPEC §12b), rendered without ROS: :mod:`services.bridge.crew`.

The crew's ``/diagnostics`` is made of the twin's own alarms and of what the telemetry shows;
an injected fault in the same record is never named. Numbers and words written out here from
the SPEC, not taken from the code.
"""

from __future__ import annotations

import json

import pytest

from common import keys
from common.config import load_rover
from common.messages import ActiveFault, ActiveFaults, LoadPower, RadioLink, RailState
from services.bridge import crew_view
from services.bridge.convert import DIAG_ERROR, DIAG_OK, DIAG_STALE, DIAG_WARN
from services.bridge.crew import crew_statuses
from tests.harness import ROVERS

pytestmark = pytest.mark.timeout(30)

R = "mapp-1"
SHORT = ActiveFault(keys.fault(R, "load/nav_camera", "short"), {"resistance_ohm": 0.05}, 12.0,
                    "injected")
DUST = ActiveFault(keys.fault(R, "solar/left", "dust"), {"fraction": 0.4}, 3.0, "injected")
TRIPPED = ActiveFault(keys.fault(R, "rail/5V_CH2", "tripped"), {}, 12.1, "derived", "critical")


def _words(statuses: list[dict]) -> str:
    return json.dumps(statuses)


def test_a_short_is_an_over_current_trip_and_never_named():
    comps = ["battery", "rail/5V_CH2", "load/nav_camera", "solar/left"]
    tripped = RailState(12.1, 0.0, 0.0, 0.0, 3.0, "tripped",
                        "rail 5V_CH2 tripped: 9.80 A over its 3.0 A limit")
    st = {s["name"]: s for s in crew_statuses(R, comps, [DUST, SHORT, TRIPPED],
                                               {"rail/5V_CH2": tripped}, {}, 3.0)}
    rail = st[f"{R}/rail/5V_CH2"]
    assert rail["level"] == DIAG_ERROR
    assert rail["message"] == "over-current trip: off until reset"
    assert {"key": "reading", "value": tripped.reason} in rail["values"]
    # the injected faults leave no trace: the camera and the panel look well
    assert st[f"{R}/load/nav_camera"]["level"] == DIAG_OK
    assert st[f"{R}/solar/left"] == {"level": DIAG_OK, "name": f"{R}/solar/left", "message": "OK",
                                    "hardware_id": R, "values": []}
    text = _words(list(st.values()))
    for word in ("short", "dust", "injected", "0.05", "0.4", "resistance", "fraction"):
        assert word not in text, word


CAMERA_OVER = ActiveFault(keys.under(R, "load/nav_camera/over_current"), {}, 12.0, "derived", "critical")


@pytest.mark.parametrize("rail_state", ["on", "tripped"])
def test_a_loads_over_current_at_the_trip_is_never_the_crews(rail_state):
    """The instant of a short: the camera's own over-current alarm is up (the loads service
    raised it at its 500 W, before the power service tripped the rail, and resolves it once the
    rail is off), the rail still on or already tripped. A PDM measures its channels, not each
    load on one: the camera is OK, no status says over-current but the tripped rail's, and no
    status but the camera's own names it (issue 31: it read ERROR over-current for 13 ms)."""
    comps = ["rail/5V_CH2", "load/nav_camera", "load/hazard_cameras"]
    rail = (RailState(12.0, 5.0, 0.7, 3.5, 3.0, "on") if rail_state == "on"
            else RailState(12.0, 0.0, 0.0, 0.0, 3.0, "tripped", "over-current 100.00 A > 3.0 A"))
    active = [SHORT, CAMERA_OVER] + ([TRIPPED] if rail_state == "tripped" else [])
    st = {s["name"]: s for s in crew_statuses(R, comps, active, {"rail/5V_CH2": rail}, {}, 3.0)}
    assert st[f"{R}/load/nav_camera"] == {"level": DIAG_OK, "name": f"{R}/load/nav_camera",
                                          "message": "OK", "hardware_id": R, "values": []}
    others = json.dumps([s for name, s in st.items() if name != f"{R}/load/nav_camera"])
    assert "nav_camera" not in others
    want = (DIAG_OK, "OK") if rail_state == "on" else (DIAG_ERROR, "over-current trip: off until reset")
    assert (st[f"{R}/rail/5V_CH2"]["level"], st[f"{R}/rail/5V_CH2"]["message"]) == want
    # the console's "what the crew sees" says the same
    mapp = load_rover(ROVERS / "mapp.yaml")
    values = {keys.rail_state(R, "5V_CH2"): rail,
              keys.load_power(R, "nav_camera"): LoadPower(12.0, 500.0, "5V_CH2", True, ["over_current"]),
              keys.under(R, "faults/active/loads"): ActiveFaults(12.0, "loads", [SHORT, CAMERA_OVER])}
    view = crew_view(R, values, config=mapp)
    camera = next(d for d in view["diagnostics"] if d["component"] == "load/nav_camera")
    assert (camera["level_name"], camera["message"]) == ("OK", "OK")


def test_what_the_telemetry_shows_and_silence():
    comps = ["rail/12V", "radio/lander", "load/imu"]
    failed = RailState(5.0, 0.0, 0.0, 0.0, 4.0, "failed")
    lost = RadioLink(5.0, False, 900.0, 0.0)
    st = crew_statuses(R, comps, [], {"rail/12V": failed, "radio/lander": lost},
                       {"rail/12V": 0.1, "radio/lander": 0.1, "load/imu": 7.5}, 3.0)
    assert [(s["level"], s["message"]) for s in st] == [
        (DIAG_ERROR, "no output (0 V) while switched on"),
        (DIAG_WARN, "no link"),
        (DIAG_STALE, "no data for 7.5 s"),
    ]


def test_the_console_view_of_a_rover_lists_symptoms_topics_and_controls():
    mapp = load_rover(ROVERS / "mapp.yaml")
    rail = mapp.rails[0].name
    values = {
        keys.rail_state(R, rail): RailState(12.1, 0.0, 0.0, 0.0, 3.0, "tripped", "tripped"),
        keys.under(R, "faults/active/power"): ActiveFaults(12.1, "power", [
            ActiveFault(keys.fault(R, f"rail/{rail}", "tripped"), {}, 12.1, "derived", "critical")]),
        keys.under(R, "faults/active/loads"): ActiveFaults(12.1, "loads", [SHORT]),
    }
    view = crew_view(R, values, config=mapp)
    assert view["view"] == "symptoms"
    diag = {d["component"]: d for d in view["diagnostics"]}
    assert diag[f"rail/{rail}"]["level_name"] == "ERROR"
    assert diag[f"rail/{rail}"]["message"].startswith("over-current trip")
    assert "short" not in json.dumps(view["diagnostics"])
    services = {c["service"] for c in view["controls"]}
    assert {f"/pdm/rail_{r.name}/set_enabled" for r in mapp.rails} <= services
    assert {f"/pdm/rail_{r.name}/reset" for r in mapp.rails} <= services
    topics = {t["topic"]: t for t in view["topics"]}
    assert "/diagnostics" in topics and topics["/battery_state"]["message"] is None  # no value yet
