"""The shipped site on three machines (network namespaces made by the test), as generated.

ground (router, the faults service, an instructor, a debrief), mapp-1 (router, the rover's
models) and crew (router, the bridge, the crew's dashboard): TLS everywhere, mutual TLS
between the routers, each router's access control, all from ``lunaris deploy secrets --site``.
An instructor's fault on the ground reaches the rover's services (their faults in effect, read
back at the ground) and the crew host's ``/diagnostics`` (the ros2dds flavour read through
Zenoh as the ``dashboard`` identity); clearing it brings both back.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from common import keys
from tests import netns
from tests.deploy.deployment import Remote, wait_until
from tests.deploy.machines import SiteOnMachines

pytestmark = [pytest.mark.timeout(300),
              pytest.mark.skipif(netns.unavailable() is not None, reason=str(netns.unavailable()))]

ROVER, RAIL, LOAD = "mapp-1", "5V_CH2", "nav_camera"
MODELS = ("clock", "battery", "loads", "power", "solar", "radio", "drive")
STEP_S = 20.0


@pytest.fixture(scope="module")
def machines(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SiteOnMachines]:
    with SiteOnMachines(tmp_path_factory.mktemp("machines")) as m:
        try:
            yield m
        finally:
            print(m.tails())


def _rail_level(dashboard: Remote) -> list[int]:
    """The rail's level in each /diagnostics the dashboard got, in order."""
    return [s["level"] for m in dashboard.samples("diag") for s in m["payload"]
            if s["name"] == f"{ROVER}/rail/{RAIL}"]


def test_a_fault_from_the_ground_reaches_the_rovers_services_and_the_crews_diagnostics(
        machines: SiteOnMachines) -> None:
    debrief = machines.remote("ground", "debrief")
    instructor = machines.remote("ground", "instructor")
    dashboard = machines.remote("crew", "dashboard")
    debrief.subscribe("active", "lunaris/*/faults/active/*")
    dashboard.subscribe("diag", "diagnostics", decode="diagnostics")

    def live() -> list[str]:
        return debrief.call("alive", key=f"lunaris/{ROVER}/service/*")["keys"]
    every = {keys.service(ROVER, s) for s in (*MODELS, "faults", "bridge")}
    wait_until(lambda: every <= set(live()), 120,
               lambda: f"every service of the three machines (live: {live()})\n{machines.tails()}")
    wait_until(lambda: _rail_level(dashboard)[-1:] == [0], STEP_S, "the crew's /diagnostics, rail OK")

    short = keys.fault(ROVER, f"load/{LOAD}", "short")
    instructor.call("pub", key=short)
    wait_until(lambda: instructor.call("matching", key=short)["matching"], STEP_S,
               "the instructor's publisher to learn of the loads service on the rover")
    instructor.call("put", key=short, payload=json.dumps({"resistance_ohm": 0.05}))

    def in_effect(service: str) -> list[str]:
        got = debrief.samples("active", keys.faults_active(ROVER, service))
        return [f["key"] for f in got[-1]["payload"]["faults"]] if got else []
    wait_until(lambda: short in in_effect("loads"), STEP_S,
               lambda: f"the short in effect on the rover (loads: {in_effect('loads')})")
    wait_until(lambda: any(k.endswith(f"rail/{RAIL}/tripped") for k in in_effect("power")),
               STEP_S, lambda: f"the rail tripped on the rover (power: {in_effect('power')})")
    wait_until(lambda: _rail_level(dashboard)[-1:] == [2], STEP_S,
               lambda: f"the tripped rail as ERROR in the crew's /diagnostics ({_rail_level(dashboard)})")

    instructor.call("delete", key=short)
    instructor.call("put", key=keys.cmd_rail(ROVER, RAIL), payload=json.dumps({"reset": True}))
    wait_until(lambda: _rail_level(dashboard)[-1:] == [0], STEP_S,
               lambda: f"the rail back to OK in the crew's /diagnostics ({_rail_level(dashboard)})")
    assert short not in in_effect("loads")
    # the faults service on the ground lists what the rover's services hold, none of it now
    listed = instructor.call("get", selector=keys.faults(ROVER))
    assert listed["ok"] and listed["ok"][0]["payload"] == [], listed


def test_the_crew_reads_only_what_its_identities_may_across_the_routers(
        machines: SiteOnMachines) -> None:
    """The crew's router enforces its own clients' rules on what comes from the others: the
    observer on the crew host reads the rover's telemetry, never the faults in effect or the
    instructor's puts of the ground; the dashboard writes nothing but its inbound topics."""
    observer = machines.remote("crew", "observer")
    dashboard = machines.remote("crew", "dashboard")
    debrief = machines.remote("ground", "debrief")
    observer.subscribe("all", "lunaris/**")
    debrief.subscribe("rails", f"lunaris/{ROVER}/rail/*/state")
    wait_until(lambda: observer.samples("all", keys.rail_state(ROVER, RAIL)), 60,
               "the rover's rails at the crew's observer")
    dashboard.call("put", key=keys.cmd_rail(ROVER, "3V3_CH2"), payload=json.dumps({"on": False}))
    instructor = machines.remote("ground", "instructor")
    instructor.call("put", key=keys.fault(ROVER, "battery", "heating"), payload="5")
    instructor.call("put", key=keys.cmd_rail(ROVER, "3V3_CH1"), payload=json.dumps({"on": False}))

    def state(rail: str) -> list[str]:
        return [m["payload"]["state"] for m in debrief.samples("rails", keys.rail_state(ROVER, rail))]
    wait_until(lambda: state("3V3_CH1")[-1:] == ["off"], STEP_S, "the instructor's command (control)")
    instructor.call("put", key=keys.cmd_rail(ROVER, "3V3_CH1"), payload=json.dumps({"on": True}))
    instructor.call("delete", key=keys.fault(ROVER, "battery", "heating"))
    assert "off" not in state("3V3_CH2")
    hidden = {m["key"] for m in observer.samples("all")
              if m["key"].split("/")[2] in ("fault", "faults", "event", "control")}
    assert hidden == set(), hidden
