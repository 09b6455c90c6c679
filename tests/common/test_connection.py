"""The Zenoh configuration every Lunaris process opens with (``common.connection``)."""

from __future__ import annotations

import json

import pytest
import zenoh

from common.connection import TX_QUEUE_SIZE, make_config
from tests.harness import free_endpoint, wait_for

pytestmark = pytest.mark.timeout(60)

# The kernel's buffers of the loopback link kept small (Linux doubles the value), so what a
# link queues while its reader is held up is Zenoh's queue, not megabytes of socket buffer.
SOCKET_BUFFER = "65536"


def _config(mode: str, **kw) -> zenoh.Config:
    conf = make_config(mode, **kw)
    conf.insert_json5("transport/link/tcp/so_sndbuf", SOCKET_BUFFER)
    conf.insert_json5("transport/link/tcp/so_rcvbuf", SOCKET_BUFFER)
    return conf


def test_every_mode_queues_a_fleets_tick_on_each_link():
    for mode in ("client", "router"):
        sizes = json.loads(make_config(mode).get_json("transport/link/tx/queue/size"))
        assert {p: sizes[p] for p in TX_QUEUE_SIZE} == TX_QUEUE_SIZE == {"data_high": 16, "data": 16}


def test_a_burst_of_telemetry_reaches_a_subscriber_that_was_held_up_whole():
    """A tick's burst of droppable telemetry (600 kB: a fleet's PDM publishes ~175 kB a tick,
    a bridge shard receives more) sent while the subscriber does not read: the router queues
    it for the subscriber's link instead of dropping it (Zenoh's default queue, 2 batches,
    lost about 60 % of it here)."""
    endpoint = free_endpoint()
    n, size = 600, 1000
    with zenoh.open(_config("router", listen=[endpoint])), \
            zenoh.open(_config("client", connect=[endpoint])) as pub_session, \
            zenoh.open(_config("client", connect=[endpoint])) as sub_session:
        # a channel of one sample, not drained: the subscriber's link stops reading at once
        sub = sub_session.declare_subscriber("burst/**", zenoh.handlers.FifoChannel(1))
        pub = pub_session.declare_publisher("burst/telemetry",
                                            congestion_control=zenoh.CongestionControl.DROP)
        wait_for(lambda: pub.matching_status.matching, 10, "the publisher to match the subscriber")
        for i in range(n):
            pub.put(i.to_bytes(4, "little") + bytes(size - 4))
        got: list[int] = []

        def drained() -> bool:
            while (s := sub.try_recv()) is not None:
                got.append(int.from_bytes(s.payload.to_bytes()[:4], "little"))
            return len(got) >= n

        wait_for(drained, 10, f"all {n} samples (a dropped one never comes)")
        assert got == list(range(n))
