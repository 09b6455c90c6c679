"""What makes an event the same event, wherever it was read (DECISIONS D1): the one copy is
:mod:`common.events`, which the bridge uses too; the tools take it from here."""

from __future__ import annotations

from common.events import EVENT_WINDOW, EventWindow, event_identity, source_mismatch

__all__ = ["EVENT_WINDOW", "EventWindow", "event_identity", "source_mismatch"]
