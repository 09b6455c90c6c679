"""Energy and time continue across restarts and router outages; every sample has its tick's time.

Found: a battery restart raised the stored energy 5-6 J, lost about 41 J of drain and
published an older t_s; a clock restart rewound up to 1 s; a router outage advanced sim
time with no drain (843 J over 19 s); battery/state carried the previous tick's time about
1 tick in 11. Now the clock is saved every tick, the battery integrates the time since it
last stepped at the demand it held, and sim time moves with the tick a service handles.
"""

from __future__ import annotations

import time

import pytest

from common import keys
from tests.harness import ALL_SERVICES, Probe, Twin, free_endpoint, open_router, wait_for
from tests.reliability.conftest import MAPP, R, kill9, restart

pytestmark = pytest.mark.timeout(120)

SCALE = 20.0  # sim seconds per wall second: a tick is 2 s of sim time
LOADS = {"drive_motors": 40.0, "survival_heater": 12.0, "flight_computer": 6.0, "uhf_radio": 4.0,
         "nav_camera": 3.5, "hazard_cameras": 2.5, "imu": 1.0, "sun_sensor": 0.5,
         "nir_spectrometer": 4.0, "thermal_imager": 2.5}


def steady(p: Probe) -> None:
    """A constant demand: every load stuck at its nominal power, no sun, time x20."""
    for load, power in LOADS.items():
        p.put(keys.fault(R, f"load/{load}", "stuck"), power)
    p.put(keys.input_sun_angle(R), 90)
    p.put(keys.clock_control(R), {"time_scale": SCALE})
    p.wait_value(keys.clock(R), lambda c: c["time_scale"] == SCALE)
    p.wait_value(keys.power_summary(R), lambda s: s["generation_w"] < 1e-9
                 and s["load_power_w"] == pytest.approx(sum(LOADS.values())))


def drain_rate(p: Probe, since_t_s: float) -> tuple[float, float, float]:
    """(t_s, energy_j, W) from the battery samples after ``since_t_s``: a straight fit."""
    samples = [b for b in p.samples(keys.battery_state(R)) if b["t_s"] > since_t_s]
    (t0, e0), (t1, e1) = (samples[0]["t_s"], samples[0]["energy_j"]), (samples[-1]["t_s"],
                                                                          samples[-1]["energy_j"])
    return t1, e1, (e0 - e1) / (t1 - t0)


def test_energy_continues_across_a_battery_restart(twin_factory, probe_solo):
    p = probe_solo
    p.watch("lunaris/**")
    twin = twin_factory([MAPP])
    p.wait_services(R, ALL_SERVICES)
    steady(p)
    start = p.wait_value(keys.battery_state(R))["t_s"]
    p.wait_value(keys.battery_state(R), lambda b: b["t_s"] > start + 40)
    t_before, e_before, rate = drain_rate(p, start + 4)
    restart(twin, p, "battery")
    after = p.wait_value(keys.battery_state(R), lambda b: b["t_s"] > t_before + 20)
    expected = e_before - rate * (after["t_s"] - t_before)
    one_tick_j = rate * SCALE / 10
    assert after["energy_j"] == pytest.approx(expected, abs=one_tick_j), (after, expected, rate)
    times = [b["t_s"] for b in p.samples(keys.battery_state(R))]
    assert times == sorted(times), "battery/state went back in time"


def test_time_never_goes_back_across_a_clock_restart(twin_factory, probe_solo):
    p = probe_solo
    p.watch(keys.clock(R))
    twin = twin_factory([MAPP], services=("clock",))
    p.wait_services(R, ("clock",))
    p.put(keys.clock_control(R), {"time_scale": SCALE})
    p.wait_value(keys.clock(R), lambda c: c["t_s"] > 30)
    for _ in range(3):
        restart(twin, p, "clock")
        p.wait_value(keys.clock(R), lambda c: c["seq"] > 0)
    times = [c["t_s"] for c in p.samples(keys.clock(R))]
    assert times == sorted(times), f"the clock went back: {times}"


def test_energy_continues_across_a_router_outage(tmp_path):
    endpoint = free_endpoint()
    router = open_router(endpoint)
    with Twin(endpoint, [MAPP], tmp_path / "state") as twin, Probe(endpoint) as p:
        p.watch("lunaris/**")
        p.wait_services(R, ALL_SERVICES)
        steady(p)
        start = p.wait_value(keys.battery_state(R))["t_s"]
        p.wait_value(keys.battery_state(R), lambda b: b["t_s"] > start + 40)
        t_before, e_before, rate = drain_rate(p, start + 4)
        router.close()
        time.sleep(3.0)  # the outage itself: 60 s of sim time pass without the router
        router = open_router(endpoint)
        after = wait_for(lambda: next((b for b in reversed(p.samples(keys.battery_state(R)))
                                       if b["t_s"] > t_before + 60), None), 30,
                         "the battery back after the outage")
        expected = e_before - rate * (after["t_s"] - t_before)
        assert after["energy_j"] == pytest.approx(expected, abs=rate * SCALE / 10), (after, expected)
        del twin
    router.close()


def test_every_tick_is_in_the_battery_state_with_its_own_time(twin_factory, probe_solo):
    p = probe_solo
    p.watch(keys.clock(R))
    p.watch(keys.battery_state(R))
    twin_factory([MAPP])
    p.wait_services(R, ALL_SERVICES)
    first = p.wait_value(keys.clock(R))["seq"]
    p.wait_value(keys.clock(R), lambda c: c["seq"] > first + 60)
    ticks = {c["t_s"] for c in p.samples(keys.clock(R)) if first + 5 < c["seq"] < first + 55}
    stepped = {b["t_s"] for b in p.samples(keys.battery_state(R))}
    missing = sorted(ticks - stepped)
    assert not missing, f"{len(missing)} of {len(ticks)} ticks never carried by battery/state"


def test_a_killed_service_keeps_its_time_and_the_others_theirs(twin_factory, probe_solo):
    p = probe_solo
    p.watch("lunaris/**")
    twin = twin_factory([MAPP])
    p.wait_services(R, ALL_SERVICES)
    for service in ("loads", "power", "solar"):
        kill9(twin, service)
        twin.start(service)
        p.wait_services(R, (service,))
    for key in (keys.battery_state(R), keys.power_summary(R), keys.load_power(R, "imu")):
        times = [v["t_s"] for v in p.samples(key)]
        assert times == sorted(times), f"{key} went back in time"
