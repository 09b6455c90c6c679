"""The bridge's look at what reaches the crew's dashboard (SPEC §13d): the shell around
:class:`services.bridge.delivery.Delivery`, which asks rclpy and Zenoh for the readers once
every :data:`DELIVERY_S` and publishes each rover's record on ``bridge/delivery``, and the news
of a dashboard lost or back in the log and in an event (kind ``delivery``)."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Any

import zenoh

from common import keys
from common.runtime import Runtime
from services.bridge.outlets import Shared

__all__ = ["DELIVERY_S", "DeliveryWatch"]

DELIVERY_S = 1.0  # how often each rover's delivery record is published


@dataclass
class DeliveryWatch:
    """The readers of every rover's topics, looked at once every :data:`DELIVERY_S`."""

    rt: Runtime
    shared: Shared
    # (rover, Zenoh flavour) -> a publisher that never puts, on the key of the rover's watched
    # topic: its matching status says whether some subscriber reads it
    watchers: dict[tuple[str, str], zenoh.Publisher] = field(default_factory=dict)

    def readers(self, rover: str) -> dict[str, list[int]]:
        """Per enabled flavour, the readers of each of the rover's topics watched. ``ros2``:
        the subscriptions each rclpy publisher has matched (every topic published so far).
        The Zenoh flavours tell only whether some subscriber matches a key, and a watcher
        costs a declaration: one topic per rover and flavour is watched, its
        ``/diagnostics`` (the one every dashboard shows), else its first topic."""
        outlets = self.shared.outlets_of[rover]
        out: dict[str, list[int]] = {}
        watched = next((o for o in outlets if o.binding.mapping.convert == "diagnostics"),
                       outlets[0])
        for flavour, key in (("ros2dds", watched.dds_key), ("rmw_zenoh", watched.rmw_key),
                             ("json", watched.json_key)):
            if key is None:
                continue
            pub = self.watchers.get((rover, flavour))
            if pub is None:
                pub = self.watchers[rover, flavour] = self.rt.zenoh_session.declare_publisher(key)
                self.rt.keep(pub)
            status: Any = pub.matching_status  # a MatchingStatus (the stub says a bool)
            out[flavour] = [int(status.matching)]
        if self.shared.graph is not None:
            out["ros2"] = [o.ros2_publisher.get_subscription_count() for o in outlets
                           if o.ros2_publisher is not None]
        return out

    def report(self) -> None:
        """Each rover's delivery record, and the news of a dashboard lost or back."""
        delivery, wall_s = self.shared.delivery, self.shared.wall()
        for rover in sorted(self.shared.outlets_of):
            self.rt.urgent_first()
            for flavour, per_topic in self.readers(rover).items():
                news = delivery.seen(rover, flavour, per_topic, wall_s)
                if news is not None:
                    lost = not delivery.tally(rover, flavour).receiving
                    print(f"bridge: {rover}: {news}", file=sys.stderr, flush=True)
                    self.rt.event(rover, "warning" if lost else "info", "delivery",
                                  keys.BRIDGE_DELIVERY.key(rover), news)
            self.rt.publish(keys.BRIDGE_DELIVERY.key(rover),
                            delivery.record(rover, self.rt.t_s.get(rover, 0.0), wall_s))
