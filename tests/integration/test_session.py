"""Session control over real processes: reset to the rover file, snapshots saved and restored.

SPEC §5: ``control/reset`` puts every service back to the rover file's initial conditions
(stored energy, temperature, rails, inputs, injected faults cleared, the clock at 0);
``control/snapshot/<name>`` saves every service's state, ``control/restore/<name>`` puts it
back, ``get snapshots`` lists them.
"""

from __future__ import annotations

import pytest

from common import keys
from tests.harness import ALL_SERVICES, static_rover, wait_for

pytestmark = pytest.mark.timeout(90)

R = "mapp-1"
CAPACITY_J = 5.3e5


@pytest.fixture
def twin(twin_factory, probe_solo):
    probe_solo.watch("lunaris/**")
    twin_factory([static_rover("mapp.yaml")])  # the drive's reset: test_drive.py
    probe_solo.wait_services(R, ALL_SERVICES)
    probe_solo.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
    return probe_solo


def disturb(p) -> None:
    """Leave marks everywhere: heat, a tripped rail, a switched-off rail, the sun, the clock."""
    p.put(keys.clock_control(R), {"time_scale": 200})
    p.put(keys.fault(R, "battery", "heating"), 500)
    p.put(keys.fault(R, "load/nav_camera", "short"), b"")
    p.put(keys.cmd_rail(R, "3V3_CH2"), {"on": False})
    p.put(keys.input_sun_angle(R), 80)
    p.put(keys.input_radio_position(R, "lander"), {"distance_m": 900, "angle_deg": 0})
    p.wait_value(keys.rail_state(R, "5V_CH2"), lambda r: r["state"] == "tripped")
    p.wait_value(keys.rail_state(R, "3V3_CH2"), lambda r: r["state"] == "off")
    p.wait_value(keys.battery_state(R), lambda b: b["temperature_c"] > 25 and b["soc"] < 0.99)


def test_reset_puts_every_service_back_to_the_rover_file(twin):
    p = twin
    disturb(p)
    p.put(keys.control_reset(R), b"")
    p.wait_event(R, lambda e: e["kind"] == "session" and "reset" in e["message"])
    b = p.wait_value(keys.battery_state(R), lambda b: b["soc"] > 0.9999 and b["t_s"] < 5)
    assert b["temperature_c"] < 21  # 500 W of heating no more
    clock = p.wait_value(keys.clock(R), lambda c: c["t_s"] < 5)
    assert clock["time_scale"] == 1.0 and not clock["paused"] and clock["epoch"] >= 1
    p.wait_value(keys.rail_state(R, "5V_CH2"), lambda r: r["state"] == "on")
    p.wait_value(keys.rail_state(R, "3V3_CH2"), lambda r: r["state"] == "on")
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["sun_angle_deg"] == 60)
    p.wait_value(keys.radio_link(R, "lander"), lambda r: r["in_range"] and r["x_m"] == 0)
    wait_for(lambda: p.get_json(keys.faults(R)) == [[]], 5, "no fault in effect")
    cleared = {e["key"] for e in p.events(R) if e["kind"] == "fault_cleared"}
    assert {keys.fault(R, "battery", "heating"), keys.fault(R, "load/nav_camera", "short")} <= cleared


def test_a_snapshot_restores_the_stored_energy_and_the_faults(twin):
    p = twin
    p.put(keys.clock_control(R), {"time_scale": 200})
    p.put(keys.fault(R, "solar/left", "dust"), 0.4)
    p.wait_value(keys.battery_state(R), lambda b: b["soc"] < 0.995)
    p.put(keys.clock_control(R), {"paused": True})
    paused = p.wait_value(keys.clock(R), lambda c: c["paused"])
    saved = p.wait_value(keys.battery_state(R), lambda b: b["t_s"] == paused["t_s"])
    p.put(keys.control_snapshot(R, "before-storm"), b"")
    p.wait_event(R, lambda e: e["kind"] == "session" and "before-storm" in e["message"])
    wait_for(lambda: any(s["name"] == "before-storm" and "battery" in s["services"]
                         for (got,) in [p.get_json(keys.snapshots(R))] for s in got),
             5, "the snapshot in the list")
    # Change everything, then go back.
    p.put(keys.clock_control(R), {"paused": False})
    p.delete(keys.fault(R, "solar/left", "dust"))
    p.put(keys.fault(R, "battery", "capacity_loss"), 0.5)
    p.wait_value(keys.battery_state(R), lambda b: b["energy_j"] < saved["energy_j"] - 2000
                 and b["t_s"] > saved["t_s"] + 10)
    p.put(keys.control_restore(R, "before-storm"), b"")
    # The clock was saved paused: the energy comes back to the saved energy, to the joule.
    b = p.wait_value(keys.battery_state(R), lambda b: b["capacity_j"] == CAPACITY_J
                     and abs(b["energy_j"] - saved["energy_j"]) < 1.0)
    assert b["capacity_j"] == CAPACITY_J and b["t_s"] == saved["t_s"]
    assert p.wait_value(keys.clock(R), lambda c: c["cause"] == "restore:before-storm")["paused"]
    right = p.wait_value(keys.solar_power(R, "right"))["power_w"]  # clean: 0.6 of it on the left
    p.wait_value(keys.solar_power(R, "left"), lambda s: s["power_w"] == pytest.approx(0.6 * right))
    (faults,) = p.get_json(keys.faults(R))
    assert {f["key"] for f in faults} == {keys.fault(R, "solar/left", "dust")}


def test_session_controls_refused_when_they_cannot_be(twin):
    p = twin
    for key, reason in ((keys.control_restore(R, "never-saved"), "no snapshot"),
                        (keys.under(R, "control/rewind"), "no such control"),
                        (keys.control_snapshot(R, "bad name!"), "no such control")):
        p.put(key, b"")
        p.wait_event(R, lambda e, key=key, reason=reason: e["kind"] == "rejected"
                     and e["key"] == key and reason in e["message"])
