"""Every fault of SPEC §6 over real processes: its effect on the keys, and `delete` restoring it.

Most faults share one twin (each test clears what it injected); the faults that
leave a lasting mark on the pack (heat, depletion) get a twin of their own.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from common import keys
from common.config import load_rover
from tests.harness import Probe, static_rover, wait_for

pytestmark = pytest.mark.timeout(90)

R = "mapp-1"
MAPP = static_rover("mapp.yaml")  # no drive: its pack drains and its radio takes the position
PANEL_W = 1361 * 0.12 * 0.29 * 0.5  # 23.68 W at the 60 deg sun of mapp.yaml


@pytest.fixture
def probe(mapp_twin):
    p, _ = mapp_twin
    p.clear_history()
    yield p


def fault_key(component: str, kind: str) -> str:
    return keys.fault(R, component, kind)


def inject(p: Probe, component: str, kind: str, payload=b"") -> dict:
    """Put the fault and return the event that answers this very put."""
    key = fault_key(component, kind)
    seen = len(p.events(R))
    p.put(key, payload)
    return p.wait_event(R, lambda e: e["key"] == key and e["kind"] in ("fault_injected", "rejected")
                        and p.events(R).index(e) >= seen)


def clear(p: Probe, component: str, kind: str) -> None:
    key = fault_key(component, kind)
    p.delete(key)
    p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "fault_cleared")


def active_faults(p: Probe, expected_keys: set[str]) -> list[dict]:
    """The journal's answer once it lists exactly ``expected_keys`` (it trails events briefly)."""
    last: list = []
    def answer():
        replies = p.get_json(keys.faults(R))  # none while a restarted journal comes up
        if len(replies) != 1:
            return None
        (faults,) = replies
        last[:] = faults
        return (faults,) if {f["key"] for f in faults} == expected_keys else None
    try:
        return wait_for(answer, timeout_s=5)[0]
    except AssertionError:
        raise AssertionError(f"get faults: expected exactly {expected_keys}, got {last}") from None


# -- battery ---------------------------------------------------------------------------------

def test_capacity_loss_shrinks_capacity_and_the_lost_energy_stays_lost(probe):
    before = probe.value(keys.battery_state(R))
    assert inject(probe, "battery", "capacity_loss", 0.5)["kind"] == "fault_injected"
    b = probe.wait_value(keys.battery_state(R), lambda b: b["capacity_j"] == pytest.approx(0.5 * 5.3e5))
    # the crew sees a smaller pack, never the fault's name (SPEC §12b)
    assert b["energy_j"] <= b["capacity_j"] and (b["faults"], b["fault_code"]) == ([], 0)
    clear(probe, "battery", "capacity_loss")
    b = probe.wait_value(keys.battery_state(R), lambda b: b["capacity_j"] == 5.3e5)
    assert b["fault_code"] == 0
    assert b["soc"] < before["soc"] - 0.4  # the energy above the reduced capacity is gone


def test_resistance_multiplies_the_internal_resistance(probe):
    # V = V_oc - sum(v_j) - R0(soc) I: the series resistance is what the terminals lose beyond
    # the branches' polarisation, and MAPP's R0 is its resistance_curve at the pack's charge.
    curve = load_rover(MAPP).battery.resistance_curve
    assert curve is not None

    def r_ohm(b):
        return (b["ocv_v"] - sum(b["polarisation_v"]) - b["voltage_v"]) / b["current_a"]

    def r0(b):
        return float(np.interp(b["soc"], curve.soc, curve.ohm))
    try:
        inject(probe, "battery", "resistance", {"factor": 3})
        b = probe.wait_value(keys.battery_state(R), lambda b: r_ohm(b) == pytest.approx(3 * r0(b), rel=1e-6))
        assert (b["faults"], b["fault_code"]) == ([], 0)  # a deeper sag: the symptom, no name
    finally:
        clear(probe, "battery", "resistance")
    probe.wait_value(keys.battery_state(R), lambda b: r_ohm(b) == pytest.approx(r0(b), rel=1e-6))


def test_disconnect_takes_the_pack_off_the_bus_and_every_rail_off(probe):
    inject(probe, "battery", "disconnect")
    b = probe.wait_value(keys.battery_state(R), lambda b: not b["operational"])
    assert (b["voltage_v"], b["current_a"], b["fault_code"], b["faults"]) == (0.0, 0.0, 7, ["no_output"])
    for rail in ("12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2"):
        probe.wait_value(keys.rail_state(rail=rail, rover=R), lambda v: v["state"] == "off")
    probe.wait_value(keys.load_power(R, "flight_computer"), lambda v: not v["on"])
    clear(probe, "battery", "disconnect")
    probe.wait_value(keys.battery_state(R), lambda b: b["operational"] and b["voltage_v"] > 14)
    probe.wait_value(keys.rail_state(R, "12V"), lambda v: v["state"] == "on")


# -- loads and rails ----------------------------------------------------------------------------

def test_a_shorted_load_trips_its_rail_and_reset_restores_it_after_clearing(probe):
    inject(probe, "load/nav_camera", "short")  # 5 V^2 / 0.05 ohm = 500 W = 100 A >> 5 A
    rs = probe.wait_value(keys.rail_state(R, "5V_CH2"), lambda v: v["state"] == "tripped")
    assert rs["voltage_v"] == 0.0 and rs["current_a"] == 0.0
    for load in ("nav_camera", "hazard_cameras"):  # the siblings go dark too
        probe.wait_value(keys.load_power(R, load), lambda v: not v["on"] and v["power_w"] == 0.0)
    probe.wait_event(R, lambda e: e["kind"] == "fault_raised" and e["key"].endswith("rail/5V_CH2/tripped")
                     and e["severity"] == "critical")
    # the cause before its effects in the loads' events (and so in the journal): the short, then
    # the load's over-current it raised (it read over-current raised, then the short)
    wait_for(lambda: any(e["kind"] == "fault_raised" for e in probe.samples(keys.event_of(R, "loads"))),
             10, "the load's over-current")
    said = [(e["kind"], e["key"].rsplit("/", 1)[-1]) for e in probe.samples(keys.event_of(R, "loads"))]
    assert said.index(("fault_injected", "short")) < said.index(("fault_raised", "over_current")), said
    probe.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})  # still shorted: trips again
    probe.wait_event(R, lambda e: e["kind"] == "command" and e["key"].endswith("5V_CH2"))
    probe.wait_value(keys.rail_state(R, "5V_CH2"), lambda v: v["state"] == "tripped")
    clear(probe, "load/nav_camera", "short")
    assert probe.value(keys.rail_state(R, "5V_CH2"))["state"] == "tripped"  # latched
    probe.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})
    probe.wait_value(keys.rail_state(R, "5V_CH2"), lambda v: v["state"] == "on")
    probe.wait_value(keys.load_power(R, "nav_camera"), lambda v: v["on"] and 0 < v["power_w"] <= 5)
    probe.wait_event(R, lambda e: e["kind"] == "fault_resolved" and e["key"].endswith("5V_CH2/tripped"))


def test_open_load_draws_nothing(probe):
    inject(probe, "load/imu", "open")
    lp = probe.wait_value(keys.load_power(R, "imu"), lambda v: v["power_w"] == 0.0)
    assert lp["on"] and lp["faults"] == []  # no current on a live rail: the symptom, no name
    clear(probe, "load/imu", "open")
    probe.wait_value(keys.load_power(R, "imu"), lambda v: v["power_w"] > 0 and not v["faults"])


def test_stuck_load_draws_a_constant_power(probe):
    inject(probe, "load/drive_motors", "stuck", 77.5)
    wait_for(lambda: [s["power_w"] for s in probe.samples(keys.load_power(R, "drive_motors"))
                      [-5:]].count(77.5) == 5, what="five samples stuck at 77.5 W")
    clear(probe, "load/drive_motors", "stuck")
    probe.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] != 77.5)


def test_a_failed_rail_is_at_zero_volts_with_its_loads_off(probe):
    inject(probe, "rail/3V3_CH2", "fail")
    rs = probe.wait_value(keys.rail_state(R, "3V3_CH2"), lambda v: v["state"] == "failed")
    assert rs["voltage_v"] == 0.0
    probe.wait_value(keys.load_power(R, "nir_spectrometer"), lambda v: not v["on"])
    clear(probe, "rail/3V3_CH2", "fail")
    probe.wait_value(keys.rail_state(R, "3V3_CH2"), lambda v: v["state"] == "on" and v["voltage_v"] == 3.3)
    probe.wait_value(keys.load_power(R, "nir_spectrometer"), lambda v: v["on"] and v["power_w"] > 0)


# -- solar, umbilical, radio -----------------------------------------------------------------

def test_dust_cuts_one_panel_by_its_fraction(probe):
    inject(probe, "solar/left", "dust", 0.3)
    left = probe.wait_value(keys.solar_power(R, "left"),
                            lambda v: v["power_w"] == pytest.approx(0.7 * PANEL_W))
    assert (left["dust"], left["faults"]) == (0.0, [])  # dust reports the environment's only
    assert probe.value(keys.solar_power(R, "right"))["power_w"] == pytest.approx(PANEL_W)
    probe.wait_value(keys.power_summary(R),
                     lambda s: s["generation_w"] == pytest.approx(1.7 * PANEL_W * 0.95))
    clear(probe, "solar/left", "dust")
    probe.wait_value(keys.solar_power(R, "left"), lambda v: v["power_w"] == pytest.approx(PANEL_W))


def test_disconnected_panel_gives_nothing(probe):
    inject(probe, "solar/right", "disconnect")
    probe.wait_value(keys.solar_power(R, "right"), lambda v: v["power_w"] == 0.0)
    clear(probe, "solar/right", "disconnect")
    probe.wait_value(keys.solar_power(R, "right"), lambda v: v["power_w"] == pytest.approx(PANEL_W))


def test_umbilical_disconnect(probe):
    probe.put(keys.input_umbilical(R), "true")
    probe.wait_value(keys.umbilical_state(R), lambda v: v["connected"] and v["power_w"] == 120)
    try:
        inject(probe, "umbilical", "disconnect")
        probe.wait_value(keys.umbilical_state(R), lambda v: not v["connected"] and v["power_w"] == 0)
        clear(probe, "umbilical", "disconnect")
        probe.wait_value(keys.umbilical_state(R), lambda v: v["connected"] and v["power_w"] == 120)
    finally:
        probe.put(keys.input_umbilical(R), "false")
        probe.wait_value(keys.umbilical_state(R), lambda v: not v["connected"])


def test_radio_failure_and_degraded_range(probe):
    link = keys.radio_link(R, "lander")
    probe.put(keys.input_radio_position(R, "lander"), {"distance_m": 300, "angle_deg": 0})
    probe.wait_value(link, lambda v: v["in_range"] and v["x_m"] == pytest.approx(300))
    inject(probe, "radio/lander", "failure")
    probe.wait_value(link, lambda v: not v["in_range"] and v["faults"] == [])  # a lost link
    clear(probe, "radio/lander", "failure")
    probe.wait_value(link, lambda v: v["in_range"])
    inject(probe, "radio/lander", "degraded", 0.5)  # a = 200 m now: 300 m is out
    probe.wait_value(link, lambda v: not v["in_range"] and v["faults"] == [])
    clear(probe, "radio/lander", "degraded")
    probe.wait_value(link, lambda v: v["in_range"])


# -- the journal --------------------------------------------------------------------------------

def test_get_faults_lists_exactly_the_active_faults(probe):
    active_faults(probe, set())
    dust, heating = fault_key("solar/left", "dust"), fault_key("battery", "heating")
    inject(probe, "solar/left", "dust", 0.1)
    first = inject(probe, "battery", "heating", 1.0)
    again = inject(probe, "battery", "heating", 2.0)  # injecting again replaces the parameters
    assert again["message"].startswith("replaced") and again["params"] == {"heat_w": 2.0}
    wait_for(lambda: {f["key"]: f for f in active_faults(probe, {dust, heating})}[heating]
             ["params"] == {"heat_w": 2.0}, what="the replaced parameters in get faults")
    faults = {f["key"]: f for f in active_faults(probe, {dust, heating})}
    assert faults[heating]["since_t_s"] == first["t_s"]  # active since the first injection
    assert all(f["origin"] == "injected" and f["since_t_s"] > 0 for f in faults.values())
    clear(probe, "battery", "heating")
    active_faults(probe, {dust})
    clear(probe, "solar/left", "dust")
    active_faults(probe, set())


# -- faults that leave a lasting mark: a twin each ------------------------------------------------

def rover_variant(tmp: Path, **edits: str) -> Path:
    text = MAPP.read_text()
    for old, new in edits.values():
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp / "variant.yaml"
    path.write_text(text)
    return path


def test_heating_raises_the_alarm_then_the_pack_cuts_itself_off(twin_factory, probe_solo, tmp_path):
    # C = 50 J/K, G = 0.8 W/K, 100 W: T_inf = 145 C, tau = 62.5 s; x20 sim time.
    rover = rover_variant(tmp_path, c=("heat_capacity_j_per_k: 1500", "heat_capacity_j_per_k: 50"))
    p = probe_solo
    p.watch(f"lunaris/{R}/**")
    services = ("clock", "battery", "loads", "power", "solar", "faults")
    twin_factory([rover], services=services)
    p.wait_services(R, services)
    p.wait_value(keys.battery_state(R), lambda b: b["current_a"] > 0)
    p.put(keys.clock_control(R), {"time_scale": 20})
    p.put(fault_key("battery", "heating"), 100)
    alarm = p.wait_event(R, lambda e: e["kind"] == "fault_raised" and e["key"].endswith("over_temperature"))
    assert alarm["severity"] == "warning"
    cut = p.wait_event(R, lambda e: e["kind"] == "fault_raised" and e["key"].endswith("thermal_cutoff"))
    assert cut["severity"] == "critical"
    b = p.wait_value(keys.battery_state(R), lambda b: not b["operational"])
    assert b["temperature_c"] > 75 and b["fault_code"] == 6
    for rail in ("12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2"):
        p.wait_value(keys.rail_state(R, rail), lambda v: v["state"] == "off")
    p.delete(fault_key("battery", "heating"))  # cooling brings it back below max_c
    p.wait_value(keys.battery_state(R), lambda b: b["operational"] and b["temperature_c"] < 60,
                 timeout_s=30)
    p.wait_value(keys.rail_state(R, "12V"), lambda v: v["state"] == "on")


def test_draining_to_empty_gives_fault_code_5_and_every_rail_off(twin_factory, probe_solo, tmp_path):
    rover = rover_variant(tmp_path, c=("capacity_j: 5.3e5", "capacity_j: 2000"),
                          s=("initial_soc: 1.0", "initial_soc: 0.5"))
    p = probe_solo
    p.watch(f"lunaris/{R}/**")
    services = ("clock", "battery", "loads", "power", "solar", "faults")
    twin_factory([rover], services=services)
    p.wait_services(R, services)
    p.put(keys.clock_control(R), {"time_scale": 10})
    b = p.wait_value(keys.battery_state(R), lambda b: b["fault_code"] == 5, timeout_s=30)
    assert not b["operational"] and b["soc"] == 0.0 and "depleted" in b["faults"]
    for rail in ("12V", "5V_CH1", "5V_CH2", "3V3_CH1", "3V3_CH2"):
        p.wait_value(keys.rail_state(R, rail), lambda v: v["state"] == "off")
    (faults,) = p.get_json(keys.faults(R))
    assert any(f["key"].endswith("battery/depleted") and f["origin"] == "derived" for f in faults)


def test_a_restarted_service_keeps_its_injected_faults(twin_factory, probe_solo, mapp_file):
    p = probe_solo
    p.watch(f"lunaris/{R}/**")
    services = ("clock", "loads", "faults")
    twin = twin_factory([mapp_file], services=services)
    p.wait_services(R, services)
    p.put(fault_key("load/drive_motors", "stuck"), 77.5)
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] == 77.5)
    twin.procs["loads"].kill()
    twin.procs["loads"].wait()
    p.clear_history()
    twin.start("loads")  # same state folder, as lunaris up restarts it
    p.wait_services(R, ("loads",))  # a process's start (imports, coverage) is slow on a busy machine
    def drawn() -> list[float]:
        return [s["power_w"] for s in p.samples(keys.load_power(R, "drive_motors"))]
    wait_for(lambda: drawn()[-3:] == [77.5] * 3, timeout_s=30,
             what=lambda: f"the restarted loads service to keep drive_motors stuck (last: {drawn()[-5:]})")
    (faults,) = p.get_json(keys.faults(R))
    assert [f["key"] for f in faults] == [fault_key("load/drive_motors", "stuck")]
    p.delete(fault_key("load/drive_motors", "stuck"))  # and it can still be cleared
    p.wait_event(R, lambda e: e["kind"] == "fault_cleared")
    p.wait_value(keys.load_power(R, "drive_motors"), lambda v: v["power_w"] != 77.5)


def test_a_restarted_journal_rebuilds_the_active_faults(twin_factory, probe_solo, mapp_file):
    p = probe_solo
    p.watch(f"lunaris/{R}/**")
    services = ("clock", "battery", "loads", "power", "solar", "faults")
    twin = twin_factory([mapp_file], services=services)
    p.wait_services(R, services)
    p.put(fault_key("load/nav_camera", "short"), b"")
    p.put(fault_key("battery", "heating"), 3)
    p.put(fault_key("solar/left", "dust"), 0.2)
    p.wait_event(R, lambda e: e["key"].endswith("solar/left/dust"))
    p.delete(fault_key("solar/left", "dust"))  # cleared before the restart: must stay cleared
    p.wait_event(R, lambda e: e["kind"] == "fault_cleared")
    expected = {fault_key("load/nav_camera", "short"), fault_key("battery", "heating"),
                f"lunaris/{R}/rail/5V_CH2/tripped"}
    active_faults(p, expected)
    twin.procs["faults"].kill()
    twin.procs["faults"].wait()
    twin.start("faults")
    p.wait_services(R, ("faults",))
    faults = {f["key"]: f for f in active_faults(p, expected)}  # replayed from the event caches
    assert faults[fault_key("battery", "heating")]["params"] == {"heat_w": 3.0}


# -- the faults in effect, as soon as their effect shows --------------------------------------

EFFECTS = [  # (component, kind, payload, telemetry key, effect seen)
    # (an injected heating shows only as a slow rise of temperature: SPEC 12b)
    ("battery", "capacity_loss", b"0.5", keys.battery_state(R), lambda v: v["capacity_j"] < 0.6 * 5.3e5),
    ("load/imu", "stuck", b"1.5", keys.load_power(R, "imu"), lambda v: v["power_w"] == 1.5),
    ("solar/left", "dust", b"0.3", keys.solar_power(R, "left"),
     lambda v: v["power_w"] == pytest.approx(0.7 * PANEL_W)),
    ("radio/lander", "failure", b"", keys.radio_link(R, "lander"), lambda v: not v["in_range"]),
    ("rail/3V3_CH2", "fail", b"", keys.rail_state(R, "3V3_CH2"), lambda v: v["state"] == "failed"),
]


def listed(p: Probe) -> set[str]:
    (faults,) = p.get_json(keys.faults(R))
    return {f["key"] for f in faults}


class _Effect:
    """Wakes the test the moment a sample on ``key`` satisfies ``holds`` (no polling delay)."""

    def __init__(self, p: Probe, key: str):
        self.holds = lambda v: False
        self.seen = threading.Event()
        self._sub = p.session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, s) -> None:
        if self.holds(json.loads(s.payload.to_bytes())):
            self.seen.set()

    def expect(self, holds) -> None:
        self.seen.clear()
        self.holds = holds

    def wait(self, what: str) -> None:
        assert self.seen.wait(5.0), f"no sample showed {what}"


@pytest.mark.timeout(120)
def test_get_faults_lists_a_fault_as_soon_as_its_effect_shows(probe):
    """SPEC §5: an instructor who sees the effect and then asks for the active faults sees the
    fault; and once the effect is gone, the fault is gone from the list. 10 rounds of 5, each
    query made the moment the effect's sample arrives."""
    watchers = {key: _Effect(probe, key) for _, _, _, key, _ in EFFECTS}
    for _ in range(10):
        for component, kind, payload, key, effect in EFFECTS:
            fkey = fault_key(component, kind)
            watchers[key].expect(effect)
            probe.put(fkey, payload)
            watchers[key].wait(f"the effect of {fkey}")
            assert fkey in listed(probe), f"{fkey} has its effect on {key} but is not listed"
            watchers[key].expect(lambda v, effect=effect: not effect(v))
            probe.delete(fkey)
            watchers[key].wait(f"the clearing of {fkey}")
            assert fkey not in listed(probe), f"{fkey} was cleared but is still listed"


@pytest.mark.timeout(120)
def test_the_faults_in_effect_go_out_before_the_effect(probe):
    """A dashboard hears of a fault before it sees what the fault does: the owner publishes
    its faults in effect, then the effect (for each of the 5 owners, 5 rounds). Samples of
    one publisher session reach a subscriber in the order they were put; one subscription
    (one dispatch thread) sees both."""
    order: list[str] = []
    lock = threading.Lock()
    watch: dict = {}  # key -> (tag, holds), the round's

    def on_sample(s) -> None:
        k = str(s.key_expr)
        for prefix, (tag, holds) in list(watch.items()):
            if k.startswith(prefix) and holds(json.loads(s.payload.to_bytes())):
                with lock:
                    order.append(tag)

    sub = probe.session.declare_subscriber(f"lunaris/{R}/**", on_sample)
    try:
        for component, kind, payload, key, effect in EFFECTS:
            fkey = fault_key(component, kind)
            watch.clear()
            watch[key] = ("effect", effect)
            watch[keys.faults_active(R, "")] = ("listed", lambda v, k=fkey: any(
                f["key"] == k for f in v["faults"]))
            for _ in range(5):
                with lock:
                    order.clear()
                probe.put(fkey, payload)
                wait_for(lambda: "effect" in order and "listed" in order, 5,
                         f"the effect and the listing of {fkey}")
                with lock:
                    assert order.index("listed") < order.index("effect"), (fkey, order)
                probe.delete(fkey)
                probe.wait_value(key, lambda v, effect=effect: not effect(v))
    finally:
        sub.undeclare()
