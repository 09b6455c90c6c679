"""The bridge's outbound topics: one :class:`Outlet` per topic of a binding, in every enabled
flavour, fed by a :class:`Feed` per twin key; what every outlet of a bridge process shares
(:class:`Shared`: the runtime, the options, the rate timer's heap).

A sample is decoded once per twin key and its discrete fields compared once, whatever the
number of outlets; an outlet with a rate sends the newest sample of its feed on a grid of its
period (:meth:`Outlet.schedule`), going idle when no sample came, so the first one after a
silence goes at once; a change of a discrete field goes at once.
"""

from __future__ import annotations

import heapq
import sys
import time
from collections.abc import Callable
from operator import attrgetter
from typing import Any

import msgspec
import zenoh

from common.runtime import Runtime
from services.bridge.bindings import Binding, domain_of, zenoh_key
from services.bridge.cdr import encode_cdr
from services.bridge.delivery import Delivery
from services.bridge.mapping import BridgeOptions
from services.bridge.rmw_zenoh import HEARTBEAT_S, attachment, entity_token, gid_of, qos_keyexpr
from services.bridge.ros2_node import Ros2Graph, env_domain

__all__ = ["Feed", "Outlet", "Shared"]

PUBLISHER_DEPTH = 1  # the last-value cache: TRANSIENT_LOCAL, KEEP_LAST 1
CDR = zenoh.Encoding.APPLICATION_CDR
JSON = zenoh.Encoding.APPLICATION_JSON


class Shared:
    """What every outlet of one bridge process shares; ``clock`` (monotonic seconds) times the
    rates, ``wall`` (seconds since 1970) stamps the delivery record."""

    def __init__(self, rt: Runtime, opts: BridgeOptions, zid: str, graph: Ros2Graph | None,
                 clock: Callable[[], float] = time.monotonic,
                 wall: Callable[[], float] = time.time):
        self.rt, self.opts, self.zid, self.graph, self.clock = rt, opts, zid, graph, clock
        self.wall = wall
        self.ros2_base = (opts.outputs.ros2.domain_id if opts.outputs.ros2.domain_id is not None
                          else env_domain())
        self.due: list[tuple[float, int, Outlet]] = []  # outlets waiting for their rate
        self.seq = 0
        self.delivery = Delivery()  # what each rover's flavours sent (SPEC §13d)
        self.outlets_of: dict[str, list[Outlet]] = {}  # rover -> its outbound topics

    def rmw_domain(self, b: Binding) -> int:
        return domain_of(self.opts, self.opts.outputs.rmw_zenoh.domain_id, b.rover, b.place)

    def ros2_domain(self, b: Binding) -> int:
        return domain_of(self.opts, self.ros2_base, b.rover, b.place)


class Feed:
    """One twin key the bridge publishes from: its newest sample, counted, and its outlets.
    A sample is decoded once and its discrete fields compared once, whatever the number of
    outlets; a sample that changes nothing discrete, for outlets whose rate holds them, costs
    nothing more (the rate timer takes the newest sample when an outlet is due)."""

    def __init__(self, payload_type: type[msgspec.Struct], discrete: tuple[str, ...]):
        self.type = payload_type
        self.discrete_of: Callable[[Any], Any] = (attrgetter(*discrete) if discrete
                                                  else lambda _: None)
        self.outlets: list[Outlet] = []
        self.payload: Any = None  # the newest sample
        self.seq = 0  # samples so far
        self.discrete: Any = None  # the discrete fields when last flushed (a change goes at once)
        self.unrated = False  # some outlet follows every sample
        self.idle = False  # some outlet with a rate is off its timer: the next sample goes at once


class Outlet:
    """One outbound topic of one binding in every enabled flavour: the message is built and
    CDR-encoded once per published sample, whatever the number of flavours; a flavour that is
    not enabled costs nothing. The rmw_zenoh publisher (its liveliness token included) and the
    ROS 2 publisher are declared with the first sample, so a topic that never publishes (a
    null value without a default) is not advertised.

    With a rate, the outlet is on a grid of its period: when due it sends its feed's newest
    sample if one came since it last sent, else it goes idle until the next sample, which is
    sent at once. A sample whose discrete fields changed goes at once and leaves the grid as
    it is; a late timer does not push the grid later (after a pause it starts again)."""

    def __init__(self, shared: Shared, b: Binding, entity_id: int, feed: Feed | None):
        out = shared.opts.outputs
        self.shared, self.binding, self.entity_id, self.feed = shared, b, entity_id, feed
        self.type = b.mapping.type
        self.dds_key = zenoh_key(b, shared.opts, "ros2dds") if out.ros2dds.enabled else None
        self.json_key = zenoh_key(b, shared.opts, "json") if out.json.enabled else None
        self.rmw_key = zenoh_key(b, shared.opts, "rmw_zenoh") if out.rmw_zenoh.enabled else None
        self.ros2 = out.ros2.enabled
        self.encodes = bool(self.dds_key or self.rmw_key or self.ros2)  # some flavour wants CDR
        # /diagnostics carries the faults: never dropped, ahead of a fleet's telemetry
        self.urgent = b.mapping.convert == "diagnostics"
        self.gid = b""
        self.sequence = 0
        self.ros2_publisher: Any = None  # the rclpy Publisher, with the first sample
        rate = b.mapping.rate_hz
        self.period_s = 1.0 / rate if rate else 0.0
        self.next_s = 0.0  # monotonic time of its next slot on the grid
        self.idle = bool(rate)  # off the rate timer (no sample since it last sent)
        self.sent_seq = 0  # its feed's sample it last sent
        self.last: tuple[Any, bytes] | None = None  # what a restamped message repeats
        shared.outlets_of.setdefault(b.rover, []).append(self)

    def _declare_rmw(self) -> None:
        sh, b = self.shared, self.binding
        r = sh.opts.outputs.rmw_zenoh
        token = entity_token(sh.rmw_domain(b), sh.zid, 0, self.entity_id, "MP", r.namespace,
                             r.node, b.topic, self.type, qos_keyexpr(True, PUBLISHER_DEPTH),
                             sh.opts.ros_distro)
        sh.rt.keep(sh.rt.zenoh_session.liveliness().declare_token(token))
        self.gid = gid_of(token)

    def publish(self, msg: dict, cdr: bytes | None = None) -> None:
        """Publish a message (``cdr``: already encoded) in every enabled flavour, each send
        counted in :attr:`Shared.delivery` (a failed one too, and the other flavours still
        get the message)."""
        rt, distro = self.shared.rt, self.shared.opts.ros_distro
        if self.encodes:
            if cdr is None:
                cdr = encode_cdr(self.type, msg, distro)
            if self.dds_key:
                self._send("ros2dds", rt.publish_bytes, self.dds_key, cdr, CDR,
                           reliable=self.urgent)
            if self.rmw_key:
                if not self.gid:
                    self._declare_rmw()
                self.sequence += 1
                self._send("rmw_zenoh", rt.publish_bytes, self.rmw_key, cdr, CDR,
                           attachment(self.sequence, time.time_ns(), self.gid),
                           reliable=self.urgent, heartbeat_s=HEARTBEAT_S)
            if self.ros2:
                if self.ros2_publisher is None:
                    graph = self.shared.graph
                    assert graph is not None, "the ros2 flavour has its graph"
                    self.ros2_publisher = graph.publisher(self.shared.ros2_domain(self.binding),
                                                          self.binding.topic, self.type)
                self._send("ros2", self.ros2_publisher.publish, cdr)
        if self.json_key:
            self._send("json", rt.publish_bytes, self.json_key, msgspec.json.encode(msg), JSON,
                       reliable=self.urgent)

    def _send(self, flavour: str, publish: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        sh, rover = self.shared, self.binding.rover
        try:
            publish(*args, **kwargs)
        except Exception as exc:  # counted and said: the delivery record carries it
            sh.delivery.failed(rover, flavour, f"{self.binding.topic}: {exc}")
            if sh.delivery.tally(rover, flavour).errors == 1:
                print(f"bridge: {rover} {flavour} {self.binding.topic}: send failed: {exc}",
                      file=sys.stderr, flush=True)
            return
        sh.delivery.sent(rover, flavour, sh.rt.t_s.get(rover, 0.0), sh.wall())

    def send(self, build: Callable[[Outlet, Any], dict | None]) -> None:
        """Publish the feed's newest sample."""
        feed = self.feed
        assert feed is not None, "an outlet of a twin key"
        self.sent_seq = feed.seq
        msg = build(self, feed.payload)
        if msg is not None:
            self.publish(msg)

    def schedule(self, now: float) -> None:
        """Put the outlet on the rate timer at its next slot."""
        grid = self.next_s + self.period_s
        self.next_s = grid if now < grid else now + self.period_s
        sh = self.shared
        sh.seq += 1
        heapq.heappush(sh.due, (self.next_s, sh.seq, self))
