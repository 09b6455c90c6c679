"""What the faults service tells the instructor about the state folder's disk (SPEC 13e), in
words: the journal refused (``critical``), written again (``info``), space running low
(``warning``, and ``info`` once back). Each is a ``disk_full`` event; the words and the
hysteresis here, the events the service's (:mod:`services.faults.service`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

from common.messages import Severity
from services.faults.journal import Journal

__all__ = ["LOW_SPACE_BYTES", "LowSpace", "Said", "journal_said"]

# Free space of the state folder under which the instructor is warned: about 50,000 events
# of journal (a day's session journals ~1-5 MB; a flood, folded, ~70 kB a second at most).
LOW_SPACE_BYTES = 16 * 2**20


class Said(NamedTuple):
    severity: Severity
    message: str
    params: dict[str, Any]


def journal_said(rover: str, journal: Journal, was: str | None) -> Said | None:
    """What to say when the journal's disk began to refuse it, or takes it again (``was``:
    its :attr:`~Journal.disk_error` before); None when nothing changed."""
    now = journal.disk_error
    if (was is None) == (now is None):
        return None
    where = str(journal.path.parent) if journal.path is not None else "?"
    if now is not None:
        return Said("critical",
                    f"the journal of {rover} cannot be written in {where} ({now}): the faults "
                    f"service goes on, holding up to {journal.hold_max} events in memory to "
                    "write when space returns (the rest counted in a journal_gap); marks and "
                    "session controls are answered \"not recorded\" until then. Free space on "
                    "that disk", {"full": True, "error": now, "folder": where})
    return Said("info",
                f"the journal of {rover} is written again in {where}: the events held in memory "
                "are on disk (those that could not be held counted in a journal_gap event)",
                {"full": False, "folder": where})


class LowSpace:
    """Whether the state folder is short of space: said once as its free space falls under
    ``LOW_SPACE_BYTES``, once as it is back above twice that."""

    def __init__(self, folder: Path, low_bytes: int = LOW_SPACE_BYTES):
        self.folder, self.low_bytes = folder, low_bytes
        self.low = False

    def look(self) -> Said | None:
        """What to say now, if anything (``os.statvfs`` of the folder)."""
        try:
            st = os.statvfs(self.folder)
        except OSError:
            return None
        free = st.f_bavail * st.f_frsize
        if self.low == (free < self.low_bytes) or (self.low and free < 2 * self.low_bytes):
            return None
        self.low = not self.low
        params = {"low": self.low, "free_bytes": free, "folder": str(self.folder)}
        if self.low:
            return Said("warning",
                        f"the state folder {self.folder} has {free / 2**20:.1f} MB free (under "
                        f"{self.low_bytes / 2**20:g} MB): the journal and the services' state "
                        "stop being recorded when it is full. Free space on that disk", params)
        return Said("info", f"the state folder {self.folder} has {free / 2**20:.1f} MB free again",
                    params)
