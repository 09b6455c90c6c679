"""What makes an event the same event, wherever it was read (DECISIONS D1): the one copy is
:mod:`common.events`, which the bridge uses too; the tools take it from here.
:func:`in_session` and :func:`session_opened` read an event's trainee session (SPEC §12c).
"""

from __future__ import annotations

from common.events import EVENT_WINDOW, EventWindow, event_identity, source_mismatch
from common.messages import Event

__all__ = ["EVENT_WINDOW", "EventWindow", "event_identity", "in_session", "session_opened",
           "source_mismatch"]


def in_session(ev: Event, session: str) -> bool:
    """Whether ``ev`` is read as the running session's: of it, of no session (a service that
    had heard no tick), or any while no session is known."""
    return not session or not ev.session or ev.session == session


def session_opened(ev: Event) -> tuple[str, str] | None:
    """(session, trainee) of the clock's event that opens a session, or None."""
    p = ev.params
    if ev.kind != "session" or ev.source != "clock" or not isinstance(p, dict):
        return None
    session, trainee = p.get("session"), p.get("trainee")
    if "started_wall" not in p or not isinstance(session, str) or not isinstance(trainee, str):
        return None
    return session, trainee
