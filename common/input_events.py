"""Accepted inputs as ``input`` events, without flooding the journal.

An input is journalled so that the debrief can mark it (the sun set to 75 deg at 12:04, the
umbilical plugged in) and so that a tool that sent it can confirm it, as it does a fault. A
ramp re-sends its input every tick, though, and ten events a second would bury the journal.
:class:`InputLog` lets the first input on a key through at once, folds the ones that follow
within ``window_s`` of wall time, and hands back the last of them (saying how many it stands
for) when the window ends. Pure: the caller gives the wall time.
"""

from __future__ import annotations

from typing import Any, NamedTuple

__all__ = ["InputLog", "InputNote"]


class InputNote(NamedTuple):
    rover: str
    key: str
    message: str
    params: dict[str, Any] | None
    actor: str = ""  # who sent the input (common.connection.ACTORS)


class InputLog:
    def __init__(self, window_s: float = 1.0):
        self.window_s = window_s
        self._sent: dict[tuple[str, str], float] = {}  # (rover, key) -> wall time of its last event
        self._held: dict[tuple[str, str], tuple[InputNote, int]] = {}  # the latest folded, how many

    def offer(self, note: InputNote, now_s: float) -> list[InputNote]:
        """The events to publish now for an accepted input received at wall time ``now_s``."""
        out = self.flush(now_s)
        slot = (note.rover, note.key)
        last = self._sent.get(slot)
        if last is None or now_s - last >= self.window_s:
            self._sent[slot] = now_s
            return out + [note]
        _, count = self._held.get(slot, (note, 0))
        self._held[slot] = (note, count + 1)
        return out

    def flush(self, now_s: float) -> list[InputNote]:
        """The folded inputs whose window has ended, each with the count it stands for."""
        out = []
        for slot, (note, count) in list(self._held.items()):
            if now_s - self._sent[slot] >= self.window_s:
                del self._held[slot]
                self._sent[slot] = now_s
                more = f" (the last of {count} inputs within {self.window_s:g} s)" if count > 1 else ""
                out.append(note._replace(message=note.message + more))
        return out
