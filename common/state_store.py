"""What a service keeps on disk so that a restarted service resumes where it was.

One JSON file per service and kind of state, ``<state_dir>/<service>-<what>.json``,
written atomically (a kill mid-write leaves the previous file). Without a state
directory nothing is kept, and nothing is read.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import msgspec

__all__ = ["StateStore"]


class StateStore:
    def __init__(self, state_dir: str | os.PathLike | None, service: str):
        self.dir = Path(state_dir) if state_dir else None
        self.service = service

    def path(self, what: str) -> Path | None:
        if self.dir is None:
            return None
        return self.dir / f"{self.service}-{what}.json"

    def save(self, what: str, data: Any) -> None:
        path = self.path(what)
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(msgspec.json.encode(data))
        os.replace(tmp, path)  # atomic: a kill mid-write leaves the previous state

    def load(self, what: str) -> Any:
        """The saved data, or None when there is none. An unreadable file is reported and
        ignored: the service starts from the rover file rather than not at all."""
        path = self.path(what)
        if path is None or not path.is_file():
            return None
        try:
            return msgspec.json.decode(path.read_bytes())
        except msgspec.DecodeError as exc:
            print(f"{self.service}: ignoring unreadable state {path}: {exc}", file=sys.stderr)
            return None
