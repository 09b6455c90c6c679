"""The crew's controls in the router's rules (SPEC §12a), on deploy/zenohd.json5 over TLS.

The dashboard may call exactly the services of the mapping (the ros2dds keys a
zenoh-bridge-ros2dds queries for a DDS client, the rmw_zenoh keys an rmw_zenoh client queries),
and only the bridge may answer them and write the commands they carry; the dashboard may not
put a command itself. Each refusal has a positive control sent after it, as in
test_access_control.py.
"""

from __future__ import annotations

import pytest
import zenoh

from common import keys
from services.bridge import open_keyexpr
from tests.deploy.conftest import Collector, Router, wait_for

ROVER = "mapp-1"
SET_ENABLED_DDS = "mapp_1/pdm/rail_5V_CH2/set_enabled"
SET_ENABLED_RMW = ("0/pdm/rail_5V_CH2/set_enabled/std_srvs::srv::dds_::SetBool_/"
                   "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a")
SET_ENABLED_REQUEST = b"\x00\x01\x00\x00\x00"  # SetBool, data false: CDR with its header


def _answers(session: zenoh.Session, key: str, **kw) -> list[bytes]:
    return [r.ok.payload.to_bytes() for r in session.get(key, payload=SET_ENABLED_REQUEST,
                                                          timeout=3.0, **kw) if r.ok is not None]


@pytest.mark.timeout(90)
def test_the_dashboard_calls_set_enabled_and_cannot_put_a_rail_command(router: Router) -> None:
    bridge, power = router.open("lunaris-bridge"), router.open("lunaris-power")
    dashboard = router.open("dashboard")
    commands = Collector()
    power.declare_subscriber(keys.cmd_rail(ROVER, "*"), commands)
    calls = Collector()

    def serve(q: zenoh.Query) -> None:  # as the bridge answers: writes the command, replies
        calls(str(q.key_expr))
        bridge.put(keys.cmd_rail(ROVER, "5V_CH2"), b'{"on": false}', attachment=b"actor=crew")
        q.reply(q.key_expr, b"\x00\x01\x00\x00\x01")
        q.drop()
    # a bridge serving the fleet: one queryable per service of every rail and rover, as it
    # opens them (the real bridge's, under the generated rules: test_delivery.py)
    bridge.declare_queryable(open_keyexpr([SET_ENABLED_DDS, "ltv_1/pdm/rail_12V/set_enabled"]), serve)
    bridge.declare_queryable(open_keyexpr([SET_ENABLED_RMW, SET_ENABLED_RMW.replace(
        "0/pdm/rail_5V_CH2", "1/pdm/rail_12V", 1)]), serve, complete=True)
    # the dashboard cannot serve a service itself: its answer never reaches a caller
    dashboard.declare_queryable("mapp_1/pdm/rail_5V_CH2/reset", lambda q: q.reply(q.key_expr, b"forged"))
    caller = router.open("dashboard")

    # a plain put of a rail command by the dashboard is refused at the router ...
    dashboard.put(keys.cmd_rail(ROVER, "5V_CH2"), b'{"on": true}')
    dashboard.delete(keys.input_drive_traverse(ROVER))
    # ... while its calls are answered by the bridge, which writes the command
    wait_for(lambda: _answers(dashboard, SET_ENABLED_DDS), "the bridge's answer to the ros2dds call")
    assert _answers(dashboard, SET_ENABLED_RMW, target=zenoh.QueryTarget.ALL_COMPLETE) == [
        b"\x00\x01\x00\x00\x01"]
    wait_for(lambda: len(commands.items) >= 2, "the bridge's rail commands")
    assert [s.payload.to_bytes() for s in commands.items] == [b'{"on": false}'] * len(commands.items)
    assert {s.attachment.to_bytes() for s in commands.items} == {b"actor=crew"}
    assert SET_ENABLED_DDS in calls.items and SET_ENABLED_RMW in calls.items
    assert _answers(caller, "mapp_1/pdm/rail_5V_CH2/reset") == []


@pytest.mark.timeout(60)
def test_the_dashboard_calls_only_the_mappings_services(router: Router) -> None:
    """A key that is no service of the mapping is not asked of the bridge, nor is another
    rover's namespace refused: the fleet's rovers are the deployment's (mapp-1, ltv-1)."""
    bridge, dashboard = router.open("lunaris-bridge"), router.open("dashboard")
    asked = Collector()
    for key in ("$*_1/pdm/rail_5V_CH2/set_enabled", "$*_1/pdm/rail_5V_CH2/set_state"):
        bridge.declare_queryable(key, lambda q: (asked(str(q.key_expr)),
                                                 q.reply(q.key_expr, b"\x00\x01\x00\x00\x01")))
    assert _answers(dashboard, "mapp_1/pdm/rail_5V_CH2/set_state") == []
    assert _answers(dashboard, "crew/pdm/rail_5V_CH2/set_enabled") == []
    wait_for(lambda: _answers(dashboard, SET_ENABLED_DDS), "the allowed call's answer")
    assert set(asked.items) == {SET_ENABLED_DDS}
