"""The one client of the twin that every Lunaris tool uses (STYLE habit 11).

- :class:`Mirror` (:mod:`~lunaris.client.mirror`): a live, bounded mirror of one rover or of
  every rover: the latest value (and a bounded history) per key, the events taken once by
  ``(source_id, seq)``, the live services, each rover's link (:class:`Link`) and its trainee
  session (:class:`Session`: history and events start empty with each session).
- :class:`Writer` (:mod:`~lunaris.client.writer`): one write and its answer,
  :class:`Accepted`, :class:`Rejected` or :class:`NotApplied`; the write itself is planned,
  checked, by :func:`common.writes.plan_write`.
- :func:`open_session` and friends (:mod:`~lunaris.client.session`): a session on the twin's
  router, and the words when there is none.
- :func:`event_identity` (:mod:`~lunaris.client.events`), :func:`humane`
  (:mod:`~lunaris.client.words`).

``lunaris watch``, ``pdm``, ``scenario``, ``fault``, ``rail``, ``clock``, ``input``,
``reset``, ``snapshot``, ``traverse``, ``predict``, ``record`` and the console are its users.
"""

from lunaris.client.events import EventWindow, event_identity
from lunaris.client.link import LINK_TIMEOUT_S, Link, clock_time
from lunaris.client.mirror import Change, Mirror, Session, Token, Value
from lunaris.client.session import (
    START_HINT,
    ToolError,
    close_session,
    describe_endpoint,
    ignored,
    live_rovers,
    open_session,
    require_rover,
    unknown_rover,
)
from lunaris.client.words import humane, shown
from lunaris.client.writer import ANSWER_S, Accepted, Actor, Answer, NotApplied, Rejected, Writer, describe

__all__ = [
    "ANSWER_S",
    "LINK_TIMEOUT_S",
    "START_HINT",
    "Accepted",
    "Actor",
    "Answer",
    "Change",
    "EventWindow",
    "Link",
    "Mirror",
    "NotApplied",
    "Rejected",
    "Session",
    "Token",
    "ToolError",
    "Value",
    "Writer",
    "clock_time",
    "close_session",
    "describe",
    "describe_endpoint",
    "event_identity",
    "humane",
    "ignored",
    "live_rovers",
    "open_session",
    "require_rover",
    "shown",
    "unknown_rover",
]
