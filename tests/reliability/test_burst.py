"""Nothing lost in a burst: 5,000 injections sent as fast as possible all arrive.

Found with plain puts: Zenoh's default congestion control drops under pressure, and
500-600 of 5,000 never reached the loads service, with no event. Lunaris tools write with
blocking congestion control (common.connection.write) and the services publish their
events reliably, so every write is answered.
"""

from __future__ import annotations

import subprocess

import pytest
import zenoh

from common import keys
from common.connection import write
from tests.harness import ROOT, lunaris_cmd, wait_for
from tests.reliability.conftest import R, events, wait_events

pytestmark = pytest.mark.timeout(180)

BURST = 5000


def test_a_burst_of_5000_injections_is_answered_5000_times(whole_twin):
    p, _ = whole_twin
    key = keys.fault(R, "load/imu", "stuck")
    for i in range(BURST):
        write(p.session, key, f"{1.0 + i * 1e-4:.4f}")
    wait_events(p, BURST, "fault_injected", key, timeout_s=150)
    answered = events(p, "fault_injected", key)
    assert len(answered) == BURST
    assert not events(p, "rejected", key) and not events(p, "internal_error")
    # The last value is in effect.
    p.wait_value(keys.load_power(R, "imu"), lambda v: v["power_w"] == pytest.approx(1.4999))


def test_every_write_of_the_tools_and_every_event_blocks_rather_than_drops(whole_twin):
    """The mechanism: a put sent with CongestionControl.DROP may be dropped by any queue on its
    way when the network is congested; BLOCK waits instead. The instructor's tools, the
    bridge's inbound inputs and the services' events must all block."""
    p, _ = whole_twin
    seen: list = []
    subs = [p.session.declare_subscriber(k, seen.append)
            for k in (keys.under(R, "fault/**"), keys.event(R), keys.event_of(R, "*"),
                      keys.under(R, "input/**"))]
    try:
        out = subprocess.run(lunaris_cmd("fault", "inject", R, "battery", "heating", "3",
                                         "--connect", p.endpoint),
                             cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        # The dashboard's inbound topic (json flavour), forwarded by the bridge as an input.
        p.put("json/curr_to_receiving_radio_m",
              {"layout": {"dim": [], "data_offset": 0}, "data": [120.0, 10.0]})
        wait_for(lambda: {"fault", "event", "input"} <= {str(s.key_expr).split("/")[2] for s in seen},
                 10, "the tool's put, an event and the bridge's input")
        for s in seen:
            assert s.congestion_control == zenoh.CongestionControl.BLOCK, str(s.key_expr)
    finally:
        for sub in subs:
            sub.undeclare()
