"""What the bridge delivers to the crew's dashboard (SPEC §13d), on numbers: the counts, the
readers, the silence and the news of a dashboard lost and back (services/bridge/delivery.py)."""

from __future__ import annotations

import msgspec
import pytest

from common import keys
from common.messages import BridgeDelivery, decode, encode
from services.bridge.delivery import Delivery

R = "mapp-1"


def test_sends_and_failures_are_counted_per_flavour():
    d = Delivery()
    d.sent(R, "ros2", 1.0, 100.0)
    d.sent(R, "ros2", 2.0, 101.0)
    d.sent(R, "json", 2.0, 101.5)
    d.failed(R, "ros2", "/battery_state: context invalid")
    rec = d.record(R, 3.0, 102.0)
    by = {f.flavour: f for f in rec.flavours}
    assert (by["ros2"].sent, by["ros2"].last_send_t_s, by["ros2"].last_send_wall_s) == (2, 2.0, 101.0)
    assert (by["ros2"].errors, by["ros2"].last_error) == (1, "/battery_state: context invalid")
    assert (by["json"].sent, by["json"].errors) == (1, 0)
    assert d.record("ltv-1", 0.0, 102.0).flavours == []  # another rover's counts are its own


def test_a_dashboard_never_seen_is_not_silent_and_says_nothing():
    d = Delivery(lost_after_s=3.0)
    for wall in range(10):
        assert d.seen(R, "ros2", [0, 0], float(wall)) is None
    rec = d.record(R, 0.0, 10.0)
    assert (rec.receiving, rec.ever_received, rec.silent_since_wall_s) == (False, False, None)


def test_a_dashboard_that_goes_away_is_silent_at_once_and_not_discovered_after_a_while():
    d = Delivery(lost_after_s=3.0)
    assert d.seen(R, "ros2", [1, 2, 0], 100.0) is None
    rec = d.record(R, 5.0, 100.0)
    assert rec.receiving and rec.silent_since_wall_s is None
    assert (rec.flavours[0].readers, rec.flavours[0].topics, rec.flavours[0].topics_read) == (2, 3, 2)
    assert d.seen(R, "ros2", [0, 0, 0], 101.0) is None
    rec = d.record(R, 6.0, 101.0)
    assert not rec.receiving and rec.silent_since_wall_s == 101.0 and rec.ever_received
    assert d.seen(R, "ros2", [0, 0, 0], 103.9) is None  # not yet lost_after_s
    news = d.seen(R, "ros2", [0, 0, 0], 104.0)
    assert news is not None and "not discovered" in news and news.startswith("ros2")
    assert d.seen(R, "ros2", [0, 0, 0], 105.0) is None  # said once per silence
    back = d.seen(R, "ros2", [1, 0, 0], 106.0)
    assert back is not None and "again" in back
    rec = d.record(R, 7.0, 106.0)
    assert rec.receiving and rec.silent_since_wall_s is None


def test_a_short_gap_is_silent_but_not_news():
    d = Delivery(lost_after_s=3.0)
    d.seen(R, "json", [1], 0.0)
    assert d.seen(R, "json", [0], 1.0) is None
    assert d.seen(R, "json", [1], 2.0) is None


def test_the_rover_receives_while_any_flavour_has_a_reader():
    d = Delivery()
    d.seen(R, "ros2", [1], 0.0)
    d.seen(R, "json", [1], 0.0)
    d.seen(R, "ros2", [0], 1.0)
    assert d.record(R, 0.0, 1.0).receiving
    d.seen(R, "json", [0], 2.0)
    rec = d.record(R, 0.0, 2.0)
    assert not rec.receiving and rec.silent_since_wall_s == 2.0  # the last reader gone


def test_the_record_is_the_key_family_payload():
    d = Delivery()
    d.seen(R, "ros2", [1], 0.0)
    d.sent(R, "ros2", 0.5, 0.0)
    rec = d.record(R, 1.0, 2.0)
    assert keys.family_of(keys.split(keys.BRIDGE_DELIVERY.key(R))[1]) is keys.BRIDGE_DELIVERY
    assert keys.BRIDGE_DELIVERY.direction == "out" and keys.BRIDGE_DELIVERY.owner == "bridge"
    assert decode(encode(rec), BridgeDelivery) == rec
    with pytest.raises(msgspec.ValidationError, match="receiving"):
        decode(b'{"t_s": 0, "wall_s": 0, "receiving": "yes", "silent_since_wall_s": null, '
               b'"ever_received": false, "flavours": []}', BridgeDelivery)


def test_lost_after_must_be_positive():
    with pytest.raises(ValueError, match="lost_after_s must be > 0"):
        Delivery(lost_after_s=0.0)
