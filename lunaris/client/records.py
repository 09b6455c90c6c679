"""What the client's mirror holds (:mod:`lunaris.client.mirror`): a key's value, a service's
liveliness token, a rover's trainee session, a change told to the listeners, and one rover's
record."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

from common.messages import Event
from lunaris.client.link import LinkTracker

__all__ = ["Change", "Session", "Token", "Value"]


@dataclass(frozen=True)
class Value:
    """A key's sample: its payload as received, decoded, and the wall time it came."""

    raw: bytes
    value: Any
    at: float


class Token(NamedTuple):
    """A service's liveliness token as last seen: alive or gone, since when (wall time)."""

    alive: bool
    since: float


class Session(NamedTuple):
    """A rover's trainee session as the mirror knows it: its id (from the clock's ticks) and
    its trainee ("" for none named; None while the event that opened it has not been heard)."""

    id: str
    trainee: str | None


class Change(NamedTuple):
    """What a listener is told: a value, an event, the services of a rover, a rover forgotten,
    or its session changed (``value``: the :class:`Session`; the previous session's history and
    events are gone from the mirror by then); ``key`` the Zenoh key (the rover's for
    ``services``, ``forget`` and ``session``)."""

    kind: Literal["value", "event", "services", "forget", "session"]
    rover: str
    key: str
    raw: bytes
    value: Any


@dataclass
class _Rover:
    latest: dict[str, Value] = field(default_factory=dict)
    names: dict[str, set[str]] = field(default_factory=dict)  # family -> component names
    history: dict[str, deque[Value]] = field(default_factory=dict)
    events: deque[tuple[Event, bytes]] = field(default_factory=deque)
    tokens: dict[str, Token] = field(default_factory=dict)
    link: LinkTracker = field(default_factory=LinkTracker)
    seen: float = 0.0  # wall time of the last sample or token
    ever_live: bool = False
    session: str = ""  # the session running, as the clock's ticks say ("" before the first)
    trainees: dict[str, str] = field(default_factory=dict)  # session -> its trainee (a few)

    def live(self) -> set[str]:
        return {s for s, t in self.tokens.items() if t.alive}
