"""Keys the twin does not know are refused, and a key is never read as another.

Found: puts on input/sun_angle/x, input/umbilical/x or clock/control/x got no event, and
any input/radio/lander/<anything> was taken as a position (a put on .../velocity took the
radio out of range). Now every put on a key an instructor, scenario or dashboard writes
(fault/, input/, cmd/, clock/control, control/, and one chunk after the rover) that no
family of the twin matches gets a rejection event, and each service reads only its own
exact keys.
"""

from __future__ import annotations

import pytest

from common import keys
from tests.reliability.conftest import R, events, wait_events

pytestmark = pytest.mark.timeout(60)

UNOWNED = ["input/sun_angle/x", "input/umbilical/x", "clock/control/x", "input/radio/lander/velocity",
           "input/radio/lander/position/x", "cmd/rail/12V/extra", "cmd/rail", "input", "fault",
           "control", "self_destruct", "control/snapshot"]


def test_a_put_nobody_owns_is_rejected_once_and_changes_nothing(whole_twin):
    p, _ = whole_twin
    link = p.wait_value(keys.radio_link(R, "lander"))
    for angle, tail in enumerate(UNOWNED, start=10):
        key = keys.under(R, tail)
        p.put(key, {"distance_m": 5000, "angle_deg": 0})
        wait_events(p, 1, "rejected", key, timeout_s=10)
        p.put(keys.input_sun_angle(R), angle)  # a valid input behind it: the rejection is final
        p.wait_value(keys.solar_power(R, "left"), lambda v, a=angle: v["sun_angle_deg"] == a)
        assert len(events(p, "rejected", key)) == 1, key
        assert p.value(keys.radio_link(R, "lander"))["x_m"] == link["x_m"], key
