"""A service's own state through a training session: kept on disk, reset, saved and restored.

A service hands its runtime three functions per rover (:meth:`common.runtime.Runtime.own_state`):
``get(rover) -> dict`` (everything that evolves: stored energy, rail switches, inputs ...),
``set(rover, dict)`` and ``reset(rover)`` (back to the rover file's initial conditions).
Then, with no more code in the service:

- **persistence**: the state is written under ``--state-dir`` every ``persist_every_s`` of
  wall time and when the service stops, and read back when it starts, so a restarted
  service resumes where it was;
- ``lunaris/<rover>/control/snapshot/<name>``: the state and the injected faults are saved
  under ``<state-dir>/snapshots/<name>/`` (so they survive a restart);
- **reset and restore** follow the clock. ``control/reset`` and ``control/restore/<name>``
  go to the clock, which starts a new *epoch* of the session; every tick carries its epoch
  and what began it (``cause``). When a service's first tick of a new epoch comes, it
  clears its injected faults (each journalled), then resets or restores its state, before
  it handles the tick. Ticks of an older epoch that arrive late are dropped. So every
  service acts at the same point of simulated time, a tick from before a reset is never
  integrated after it, and a service that was down during a reset catches up with it when
  it comes back (the epoch it last followed is persisted with its state);
- ``lunaris/<rover>/snapshots/<service>`` answers a query with the snapshots this service
  holds (the faults service gathers them for ``get lunaris/<rover>/snapshots``).

The faults service answers each control with the one ``session`` event that marks it in
the journal, or refuses it (``rejected``: an unknown control or snapshot, a bad name); a
service ignores a control it cannot act on.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import msgspec
import zenoh

from common import keys
from common.messages import ActiveFault, Clock, SnapshotInfo, encode
from common.state_store import StateStore

if TYPE_CHECKING:
    from common.runtime import Runtime, Sample

__all__ = ["RESTORE", "SNAPSHOT_NAME", "SessionKeeper", "StateGet", "StateReset", "StateSet", "parse_control"]

StateGet = Callable[[str], dict[str, Any]]
StateSet = Callable[[str, dict[str, Any]], None]
StateReset = Callable[[str], None]
SNAPSHOT_NAME = keys.SNAPSHOT_NAME
RESTORE = "restore:"


def parse_control(parts: list[str]) -> tuple[str, str] | None:
    """``("reset", "")``, ``("snapshot", name)`` or ``("restore", name)`` from a control key's
    chunks after ``lunaris/<rover>/``; None when it is none of them."""
    what = parts[1:] if parts[:1] == ["control"] else []
    if what == ["reset"]:
        return "reset", ""
    if len(what) == 2 and what[0] in ("snapshot", "restore") and SNAPSHOT_NAME.match(what[1]):
        return what[0], what[1]
    return None


class SessionKeeper:
    """Persistence, reset, snapshots and restores of one service's state."""

    def __init__(self, rt: Runtime, get: StateGet, set_: StateSet, reset: StateReset,
                 after: Callable[[str], None] | None, persist_every_s: float | None):
        self.rt, self._get, self._set, self._reset = rt, get, set_, reset
        self._after = after or (lambda rover: None)
        self.epoch: dict[str, int] = {}  # rover -> the epoch of the session followed
        # Without a state directory, snapshots live as long as the service.
        self._memory: dict[str, dict[str, Any]] = {}
        saved = rt.store.load("state") or {}
        for rover, record in saved.items():
            if rover in rt.rovers and isinstance(record, dict) and "state" in record:
                set_(rover, record["state"])
                self.epoch[rover] = int(record.get("epoch", 0))
        if persist_every_s is not None:
            rt.every(persist_every_s, self.persist)
        rt.on_exit(self.persist)
        rt.subscribe(keys.under("*", "control/snapshot/*"), self._on_snapshot)
        rt.queryable(keys.snapshots_of("*", rt.name), self._on_query)

    # -- persistence -------------------------------------------------------------------------

    def persist(self) -> None:
        self.rt.store.save("state", {
            rover: {"state": self._get(rover), "epoch": self.epoch.get(rover, 0)}
            for rover in sorted(self.rt.rovers)})

    # -- following the clock's epochs ---------------------------------------------------------

    def follow(self, rover: str, tick: Clock) -> bool:
        """Act on a new epoch's reset or restore; False for a tick of an older epoch."""
        known = self.epoch.get(rover)
        if known is None:  # first tick ever: nothing to catch up with
            self.epoch[rover] = tick.epoch
            return True
        if tick.epoch < known:
            return False
        if tick.epoch > known:
            self.epoch[rover] = tick.epoch
            self.begin(rover, tick.cause)
        return True

    def begin(self, rover: str, cause: str) -> None:
        """A new epoch: ``reset`` or ``restore:<name>``."""
        if cause == "reset":
            self.reset(rover)
        elif cause.startswith(RESTORE):
            name = cause[len(RESTORE):]
            if name in self.names(rover):
                self.restore(rover, name)
            else:
                print(f"{self.rt.name}: no snapshot {name!r} of {rover} here: state kept",
                      file=sys.stderr, flush=True)

    def reset(self, rover: str) -> None:
        """Every injected fault cleared (journalled), the state back to the rover file's."""
        if self.rt.has_faults:
            self.rt.faults.clear_all(rover)
        self._reset(rover)
        self.rt.t_s[rover] = 0.0
        self._changed(rover)

    def restore(self, rover: str, name: str) -> None:
        saved = (self._read(name) or {})[rover]
        if self.rt.has_faults:
            self.rt.faults.clear_all(rover)
        self._set(rover, saved["state"])
        self.rt.t_s[rover] = float(saved.get("t_s", self.rt.t_s[rover]))
        if self.rt.has_faults:
            for raw in saved.get("faults", []):
                self.rt.faults.reinject(rover, msgspec.convert(raw, ActiveFault))
        self._changed(rover)

    def _changed(self, rover: str) -> None:
        if self.rt.has_faults:
            self.rt.faults.publish(rover)
        self.persist()
        self._after(rover)

    # -- snapshots ---------------------------------------------------------------------------

    def _on_snapshot(self, s: Sample) -> None:
        control = parse_control(s.parts)
        if control is None or s.deleted:
            return  # refused, once for the twin, by the faults service
        self.save(s.rover, control[1])

    def save(self, rover: str, name: str) -> None:
        faults = ([msgspec.structs.asdict(f) for f in self.rt.faults.injected_faults(rover)]
                  if self.rt.has_faults else [])
        record = {"state": self._get(rover), "faults": faults, "t_s": self.rt.t_s[rover],
                  "saved_at": time.time()}
        store = self._store(name)
        if store is None:
            self._memory.setdefault(name, {})[rover] = record
        else:
            existing = store.load("snapshot") or {}
            existing[rover] = record
            store.save("snapshot", existing)

    def _store(self, name: str) -> StateStore | None:
        if self.rt.store.dir is None:
            return None
        return StateStore(self.rt.store.dir / "snapshots" / name, self.rt.name)

    def _read(self, name: str) -> dict[str, Any] | None:
        store = self._store(name)
        return self._memory.get(name) if store is None else store.load("snapshot")

    def names(self, rover: str) -> list[str]:
        """The snapshots of ``rover`` this service holds its part of."""
        if self.rt.store.dir is None:
            return sorted(n for n, rovers in self._memory.items() if rover in rovers)
        root = self.rt.store.dir / "snapshots"
        if not root.is_dir():
            return []
        return sorted(d.name for d in root.iterdir()
                      if d.is_dir() and rover in (self._read(d.name) or {}))

    def info(self, rover: str) -> list[SnapshotInfo]:
        out = []
        for name in self.names(rover):
            record = (self._read(name) or {})[rover]
            out.append(SnapshotInfo(name=name, t_s=float(record.get("t_s", 0.0)),
                                    saved_at=float(record.get("saved_at", 0.0)),
                                    services=[self.rt.name]))
        return out

    def _on_query(self, q: zenoh.Query) -> None:
        with q:
            for rover in sorted(self.rt.rovers):
                key = keys.snapshots_of(rover, self.rt.name)
                if zenoh.KeyExpr(key).intersects(q.key_expr):
                    body = b"[" + b",".join(encode(i) for i in self.info(rover)) + b"]"
                    q.reply(key, body, encoding=zenoh.Encoding.APPLICATION_JSON)
