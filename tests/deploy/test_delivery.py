"""The deployment as shipped delivers every change to every reader allowed to see it.

The real thing, outside Docker: ``lunaris deploy secrets`` and ``lunaris deploy acl
--secrets-dir`` into a folder of the test, the embedded router reading that file
(``lunaris router --config``: access control and TLS as zenohd applies them), all nine
services as subprocesses, each under its own identity with the publishers it really
declares, and readers of the ``debrief``, ``observer`` and ``dashboard`` identities holding
wildcard subscribers. An instructor writes through declared publishers too (what the
console does). Zenoh's clients send a declared publisher's samples only to a router that
told them of a matching subscriber: a rule that hides a wildcard subscriber from a service
lets its first sample through and drops the rest (issue 22), which plain ``put``\\ s never
show. Forged writes, on the contrary, are sent with plain ``put``\\ s: those always reach
the router, the worst case for its rules.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common import keys
from lunaris.processes import wait_for
from testbed.deployment import (
    REPO,
    SERVICES,
    Processes,
    Tap,
    changes,
    live_services,
    open_as,
    run_lunaris,
    start_router,
    start_service,
)
from tests import rosmsg
from tests.deploy.conftest import free_port

pytestmark = pytest.mark.timeout(240)

ROVER = "mapp-1"
MAPP = REPO / "config" / "rovers" / "mapp.yaml"
RAIL, LOAD = "5V_CH2", "nav_camera"  # a short on the camera trips its rail
STEP_S = 15.0  # the most one change may take to reach every reader (a busy 2-core machine)


class Deployment:
    def __init__(self, folder: Path, procs: Processes, endpoint: str):
        self.folder, self.procs, self.endpoint = folder, procs, endpoint
        self.secrets = folder / "secrets"
        self.sessions: list[zenoh.Session] = []

    def open(self, identity: str) -> zenoh.Session:
        session = open_as(self.secrets, identity)
        self.sessions.append(session)
        return session


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Deployment]:
    folder = tmp_path_factory.mktemp("deployment")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    secrets, router_file = folder / "secrets", folder / "zenohd.json5"
    made = run_lunaris("deploy", "secrets", str(secrets), "--host", "127.0.0.1",
                       "--connect", endpoint)
    assert made.returncode == 0, made.stderr
    acl = run_lunaris("deploy", "acl", "--rover", str(MAPP), "--secrets-dir", str(secrets),
                      "--output", str(router_file))
    assert acl.returncode == 0, acl.stderr
    procs = Processes(folder / "logs")
    dep = Deployment(folder, procs, endpoint)
    try:
        start_router(procs, "router", router_file, [endpoint])
        for service in SERVICES:
            start_service(procs, service, secrets, [MAPP], folder / "state")
        yield dep
    finally:
        for session in dep.sessions:
            session.close()
        procs.stop_all()
        print(procs.tails())


def _heat_w(active: bytes) -> float | None:
    """The heating fault's parameter in a ``faults/active/battery`` payload (None: none)."""
    for fault in json.loads(active)["faults"]:
        if fault["key"].endswith("/fault/battery/heating"):
            return _find(fault.get("params"), "heat_w")
    return None


def _find(tree: Any, name: str) -> Any:
    if isinstance(tree, dict):
        if name in tree:
            return tree[name]
        return next((v for v in (_find(x, name) for x in tree.values()) if v is not None), None)
    return None


def _rail_states(tap: Tap) -> list[str]:
    return [json.loads(p)["state"] for p in tap.payloads(keys.rail_state(ROVER, RAIL))]


def _rail_levels(tap: Tap) -> list[int]:
    """The level of the rail's DiagnosticStatus in every /diagnostics the dashboard got."""
    out = []
    for payload in tap.payloads("diagnostics"):
        msg = rosmsg.decode("diagnostic_msgs/msg/DiagnosticArray", payload)
        for status in msg.status:
            if status.name == f"{ROVER}/rail/{RAIL}":
                level = status.level
                out.append(level[0] if isinstance(level, bytes) else int(level))
    return out


def test_every_change_reaches_every_allowed_wildcard_subscriber(deployment: Deployment) -> None:
    dep = deployment
    debrief, observer, dashboard = (dep.open(i) for i in ("debrief", "observer", "dashboard"))
    instructor = dep.open("instructor")
    seen = {who: Tap() for who in ("debrief", "debrief-rails", "observer", "observer-faults",
                                    "observer-all", "dashboard")}
    subs = [
        debrief.declare_subscriber("lunaris/*/faults/active/*", seen["debrief"]),
        debrief.declare_subscriber("lunaris/*/rail/*/state", seen["debrief-rails"]),
        observer.declare_subscriber("lunaris/*/rail/*/state", seen["observer"]),
        observer.declare_subscriber("lunaris/*/faults/active/*", seen["observer-faults"]),
        observer.declare_subscriber(f"lunaris/{ROVER}/**", seen["observer-all"]),
        dashboard.declare_subscriber("**", seen["dashboard"]),
    ]
    wait_for(lambda: live_services(debrief, ROVER) >= set(SERVICES), 90,
               lambda: f"every service live (live: {sorted(live_services(debrief, ROVER))})"
               f"\n{dep.procs.tails()}")
    wait_for(lambda: _rail_levels(seen["dashboard"]), STEP_S, "the dashboard's /diagnostics")
    wait_for(lambda: _rail_states(seen["observer"]), STEP_S, "the observer's rail telemetry")

    heating = instructor.declare_publisher(keys.fault(ROVER, "battery", "heating"))
    short = instructor.declare_publisher(keys.fault(ROVER, f"load/{LOAD}", "short"))
    rail = instructor.declare_publisher(keys.cmd_rail(ROVER, RAIL))
    active = keys.faults_active(ROVER, "battery")

    # ten changes of a fault: the debrief's wildcard subscriber sees each one
    for heat_w in range(11, 21):
        heating.put(json.dumps({"heat_w": heat_w}))
        wait_for(lambda h=heat_w: [_heat_w(p) for p in seen["debrief"].payloads(active)][-1:] == [h],
                   STEP_S, lambda h=heat_w: f"heating {h} W in the debrief's faults/active/battery "
                   f"(seen {[_heat_w(p) for p in seen['debrief'].payloads(active)]})")
    heating.delete()

    # ten changes of a rail (five trips, five resets): the rail's state for the debrief and
    # the observer, the rail's status in the dashboard's /diagnostics
    for _ in range(5):
        short.put(json.dumps({"resistance_ohm": 0.05}))
        _wait_rail(seen, "tripped", 2)
        short.delete()
        rail.put(json.dumps({"reset": True}))
        _wait_rail(seen, "on", 0)

    assert changes([_heat_w(p) for p in seen["debrief"].payloads(active)
                    if _heat_w(p) is not None]) == list(range(11, 21))
    ten = ["on", "tripped"] * 5 + ["on"]
    assert changes(_rail_states(seen["debrief-rails"])) == ten
    assert changes(_rail_states(seen["observer"])) == ten
    assert changes([lv == 2 for lv in _rail_levels(seen["dashboard"])]) == [False, True] * 5 + [False]

    # what the crew must not read never reached it
    assert seen["observer-faults"].samples() == []
    hidden = [k for k, _, _ in seen["observer-all"].samples()
              if k.split("/")[2] in ("fault", "faults", "event", "control", "snapshots")]
    assert hidden == [], hidden
    assert [k for k, _, _ in seen["dashboard"].samples() if k.startswith("lunaris/")] == []
    del subs


def _wait_rail(seen: dict[str, Tap], state: str, level: int) -> None:
    for who in ("debrief-rails", "observer"):
        wait_for(lambda w=who: _rail_states(seen[w])[-1:] == [state], STEP_S,
                   lambda w=who: f"{RAIL} {state} for the {w} (seen {changes(_rail_states(seen[w]))})")
    wait_for(lambda: _rail_levels(seen["dashboard"])[-1:] == [level], STEP_S,
               lambda: f"{RAIL} at level {level} in the dashboard's /diagnostics "
               f"(seen {changes(_rail_levels(seen['dashboard']))})")


def test_forged_writes_are_refused(deployment: Deployment) -> None:
    """The dashboard writes only its inbound topics, a service only its own keys: a command
    and a fault of the dashboard's, telemetry forged by the bridge's identity, change
    nothing. The positive control goes the same way after them: the instructor's command on
    another rail arrives, and what was sent before it through the same router never did."""
    dep = deployment
    debrief, dashboard, bridge = (dep.open(i) for i in ("debrief", "dashboard", "lunaris-bridge"))
    instructor = dep.open("instructor")
    got = Tap()
    sub = debrief.declare_subscriber(f"lunaris/{ROVER}/**", got)
    wait_for(lambda: live_services(debrief, ROVER) >= set(SERVICES), 90, "every service live")
    wait_for(lambda: _rail_states(got), STEP_S, "the rail's telemetry")
    dashboard.put(keys.cmd_rail(ROVER, RAIL), json.dumps({"on": False}))
    dashboard.put(keys.fault(ROVER, "battery", "heating"), json.dumps({"heat_w": 99}))
    bridge.put(keys.rail_state(ROVER, RAIL), b'{"forged": "by lunaris-bridge"}')
    bridge.put(keys.faults_active(ROVER, "battery"), b'{"forged": "by lunaris-bridge"}')
    for session in (dashboard, bridge):  # a round trip: the router has dealt with the puts
        live_services(session, ROVER)
    control = keys.rail_state(ROVER, "3V3_CH2")
    instructor.put(keys.cmd_rail(ROVER, "3V3_CH2"), json.dumps({"on": False}))
    wait_for(lambda: [json.loads(p)["state"] for p in got.payloads(control)][-1:] == ["off"],
               STEP_S, "the instructor's command (the control)")
    after = len(_rail_states(got))
    wait_for(lambda: len(_rail_states(got)) >= after + 3, STEP_S, "three more ticks of the rail")
    instructor.put(keys.cmd_rail(ROVER, "3V3_CH2"), json.dumps({"on": True}))
    assert set(_rail_states(got)) == {"on"}, changes(_rail_states(got))
    assert [k for k, p, _ in got.samples() if b"forged" in p] == []
    assert 99 not in [_heat_w(p) for p in got.payloads(keys.faults_active(ROVER, "battery"))]
    del sub


@pytest.mark.skipif(not hasattr(keys, "event_of"),
                    reason="the services publish their events on event/<service> once the "
                           "harden-input branch (DECISIONS D1) is merged")
def test_events_travel_on_their_owners_keys_and_the_journal_relays_them(
        deployment: Deployment) -> None:
    """An instructor's fault: the battery's event on ``event/battery`` (the only key its
    identity may put events on), relayed unchanged by the journal on ``event``; the debrief
    reads both, the observer neither."""
    dep = deployment
    debrief, observer, instructor = (dep.open(i) for i in ("debrief", "observer", "instructor"))
    got, crew = Tap(), Tap()
    subs = [debrief.declare_subscriber(f"{keys.event(ROVER)}/**", got),
            observer.declare_subscriber(f"lunaris/{ROVER}/**", crew)]
    wait_for(lambda: live_services(debrief, ROVER) >= set(SERVICES), 90, "every service live")
    fault = instructor.declare_publisher(keys.fault(ROVER, "battery", "capacity_loss"))
    fault.put(json.dumps({"fraction": 0.1}))

    def about(key: str) -> list[dict]:
        return [e for e in (json.loads(p) for p in got.payloads(key))
                if e.get("key") == keys.fault(ROVER, "battery", "capacity_loss")]

    own = wait_for(lambda: about(keys.event_of(ROVER, "battery")), STEP_S,
                     "the battery's event on event/battery")
    relayed = wait_for(lambda: about(keys.event(ROVER)), STEP_S, "the journal's relay on event")
    assert own[0]["source"] == "battery" and relayed[0] == own[0]
    fault.delete()
    assert [k for k, _, _ in crew.samples() if "/event" in k] == []
    del subs


SET_BOOL = ("std_srvs::srv::dds_::SetBool_/"
            "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a")


def test_the_crews_calls_from_its_dashboard_reach_the_real_bridge(deployment: Deployment) -> None:
    """The crew switches a rail from its dashboard (SPEC §12a), under the generated rules: the
    ``dashboard`` identity calls ``set_enabled`` in the ros2dds and the rmw_zenoh flavours, the
    bridge (its own identity, the queryables it really declares) answers, the rail follows.
    Found: the bridge declared ``pdm/*/set_enabled``, which the rules (``pdm/rail_$*/...``)
    refused, and every rail call went unanswered; a stand-in queryable in
    test_crew_controls.py had not shown it."""
    dep = deployment
    debrief, dashboard = dep.open("debrief"), dep.open("dashboard")
    got = Tap()
    sub = debrief.declare_subscriber(keys.rail_state(ROVER, "3V3_CH2"), got)
    wait_for(lambda: live_services(debrief, ROVER) >= set(SERVICES), 90, "every service live")
    calls = (("pdm/rail_3V3_CH2/set_enabled", {}),
             (f"0/pdm/rail_3V3_CH2/set_enabled/{SET_BOOL}", {"target": zenoh.QueryTarget.ALL_COMPLETE}))
    for (key, kw), on in zip(calls, (False, True), strict=True):
        request = rosmsg.encode_service("std_srvs/srv/SetBool", "Request", {"data": on})
        replies = wait_for(lambda k=key, kw=kw, r=request: [
            x.ok.payload.to_bytes() for x in dashboard.get(k, payload=r, timeout=5.0, **kw)
            if x.ok is not None], STEP_S, f"the bridge's answer to {key}")
        answer = rosmsg.decode_service("std_srvs/srv/SetBool", "Response", replies[0])
        state = "on" if on else "off"
        assert answer.success and f"the rail is now {state}" in answer.message, answer
        wait_for(lambda s=state: [json.loads(p)["state"] for p in got.payloads(
            keys.rail_state(ROVER, "3V3_CH2"))][-1:] == [s], STEP_S, f"3V3_CH2 {state}")
    del sub
