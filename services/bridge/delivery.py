"""What the bridge delivers to the crew's dashboard, per rover and output flavour (SPEC §13d).

:class:`Delivery` is pure bookkeeping, no I/O: the bridge counts each message sent and each failed send
(:meth:`Delivery.sent`, :meth:`Delivery.failed`), and about once a second tells what it sees
of the readers (:meth:`Delivery.seen`: the ROS 2 subscriptions matched by the rclpy
publishers, the Zenoh subscribers matching a key) and publishes the rover's
:class:`~common.messages.BridgeDelivery` (:meth:`Delivery.record`).

A flavour *had* readers once one was seen; when it has none after that it is *silent since*
the first look that found none, and after ``lost_after_s`` of that the bridge says so once
("not discovered", :meth:`Delivery.seen` returns the news); a reader back is news too. Times
are given, never read: the tests run it on numbers. Its shell in the bridge, which asks rclpy
and Zenoh for the readers and publishes, is :mod:`services.bridge.watch`.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.messages import BridgeDelivery, FlavourDelivery

__all__ = ["LOST_AFTER_S", "Delivery", "Tally"]

LOST_AFTER_S = 3.0  # readers gone this long: "not discovered" (log and event)


@dataclass
class Tally:
    """One rover's flavour: its sends, failures and readers."""

    sent: int = 0
    last_t_s: float | None = None
    last_wall_s: float | None = None
    errors: int = 0
    last_error: str = ""
    readers: int | None = None  # None: nothing watched yet
    topics: int = 0
    topics_read: int = 0
    had_readers: bool = False
    silent_since_wall_s: float | None = None  # readers gone (after having some)
    said_lost: bool = False  # "not discovered" said for this silence

    @property
    def receiving(self) -> bool:
        return bool(self.readers)


class Delivery:
    """Every tally of one bridge process, by (rover, flavour)."""

    def __init__(self, lost_after_s: float = LOST_AFTER_S):
        if not lost_after_s > 0:
            raise ValueError(f"lost_after_s must be > 0, not {lost_after_s!r}")
        self.lost_after_s = lost_after_s
        self.tallies: dict[tuple[str, str], Tally] = {}

    def tally(self, rover: str, flavour: str) -> Tally:
        found = self.tallies.get((rover, flavour))
        if found is None:
            found = self.tallies[rover, flavour] = Tally()
        return found

    def sent(self, rover: str, flavour: str, t_s: float, wall_s: float) -> None:
        """A message of the rover went out in the flavour (sim time ``t_s``, wall ``wall_s``)."""
        t = self.tally(rover, flavour)
        t.sent += 1
        t.last_t_s, t.last_wall_s = t_s, wall_s

    def failed(self, rover: str, flavour: str, error: str) -> None:
        """A send of the rover in the flavour failed (``error`` in words)."""
        t = self.tally(rover, flavour)
        t.errors += 1
        t.last_error = error

    def seen(self, rover: str, flavour: str, per_topic: list[int], wall_s: float) -> str | None:
        """What one look found: the readers of each watched topic of the rover in the flavour.
        Returns the news in words when the flavour has had no reader for ``lost_after_s``
        after having some ("not discovered", once per silence) or has one again after that;
        else None."""
        t = self.tally(rover, flavour)
        t.topics = len(per_topic)
        t.topics_read = sum(1 for n in per_topic if n > 0)
        t.readers = max(per_topic) if per_topic else None
        if t.readers:
            news = None
            if t.said_lost:
                news = (f"{flavour}: the crew's dashboard reads the topics again "
                        f"({t.topics_read} of {t.topics} topics with a reader)")
            t.had_readers, t.silent_since_wall_s, t.said_lost = True, None, False
            return news
        if not t.had_readers:
            return None
        if t.silent_since_wall_s is None:
            t.silent_since_wall_s = wall_s
        if not t.said_lost and wall_s - t.silent_since_wall_s >= self.lost_after_s:
            t.said_lost = True
            return (f"{flavour}: not discovered: no reader of the rover's topics for "
                    f"{wall_s - t.silent_since_wall_s:.0f} s (the crew's dashboard had one); "
                    f"{t.sent} messages sent so far")
        return None

    def record(self, rover: str, t_s: float, wall_s: float) -> BridgeDelivery:
        """The rover's delivery record now (``t_s``: its sim time)."""
        flavours = sorted((f, t) for (r, f), t in self.tallies.items() if r == rover)
        receiving = any(t.receiving for _, t in flavours)
        ever = any(t.had_readers for _, t in flavours)
        silences = [t.silent_since_wall_s for _, t in flavours
                    if t.silent_since_wall_s is not None]
        return BridgeDelivery(
            t_s=t_s, wall_s=wall_s, receiving=receiving,
            silent_since_wall_s=None if receiving or not silences else max(silences),
            ever_received=ever,
            flavours=[FlavourDelivery(
                flavour=f, readers=t.readers, topics=t.topics, topics_read=t.topics_read,
                sent=t.sent, last_send_t_s=t.last_t_s, last_send_wall_s=t.last_wall_s,
                errors=t.errors, last_error=t.last_error, receiving=t.receiving,
                silent_since_wall_s=t.silent_since_wall_s) for f, t in flavours])
