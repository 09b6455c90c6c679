"""A service's own state through a training session: kept on disk, reset, saved and restored.

A service hands its runtime three functions per rover (:meth:`common.runtime.Runtime.own_state`):
``get(rover) -> dict`` (everything that evolves: stored energy, rail switches, inputs ...),
``set(rover, dict)`` and ``reset(rover)`` (back to the rover file's initial conditions).
Then, with no more code in the service:

- **persistence**: the state is written under ``--state-dir`` every ``persist_every_s`` of
  wall time and when the service stops, and read back when it starts, so a restarted
  service resumes where it was. What is read back is checked before it is used: the saved
  record of each rover must have the shape of the state the service has now (the same
  fields, of the same types; every number finite) and pass the service's own ``check``
  (ranges). A rover whose record is damaged is reset (or what the service's ``damaged``
  does), the others resume; a ``critical`` event says what was damaged and what was done,
  and the damaged file is moved aside (``<file>.damaged-<time>``);
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
- **trainee sessions** (``control/session``, SPEC §12c) begin with an epoch whose ticks carry
  the new ``session``: a service clears its faults in the ending session, enters the new one
  (``Runtime.enter_session``), then resets or restores (re-injected faults are the new one's);
- ``lunaris/<rover>/snapshots/<service>`` answers a query with the snapshots this service
  holds (the faults service gathers them for ``get lunaris/<rover>/snapshots``); with
  ``?check=<name>`` it checks its part of that snapshot as a restore would read it, and
  answers ``[info]`` (intact), ``[]`` (no part) or an error saying what is damaged.

A restore is all or nothing: the clock, which begins its epoch, first asks every service
to check its part (``?check=``) and begins it only when every part is intact; else it
refuses the restore, naming the damaged parts, and nothing changes. The clock answers a
restore; the faults service answers the other controls with the one ``session`` event that
marks each in the journal, or refuses them (``rejected``: an unknown control, a bad name).
A service ignores a control it cannot act on.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import msgspec
import zenoh

from common import keys
from common.fault_book import saved_fault
from common.host import Host, Sample
from common.messages import Clock, SnapshotInfo, encode
from common.state_store import Damaged, StateStore, kind_of, not_finite, quoted, shape_problem

__all__ = ["RESTORE", "SNAPSHOT_NAME", "SessionKeeper", "StateCheck", "StateDamaged", "StateGet",
           "StateReset", "StateSet", "parse_control"]

StateGet = Callable[[str], dict[str, Any]]
StateSet = Callable[[str, dict[str, Any]], None]
StateReset = Callable[[str], None]
StateCheck = Callable[[str, dict[str, Any]], None]  # raises ValueError naming the problem
StateDamaged = Callable[[str], str]  # resets a rover whose state was damaged; says what it did
SNAPSHOT_NAME = keys.SNAPSHOT_NAME
RESTORE = "restore:"
NO_PART = "no part"  # check_part: this service holds no part of the snapshot


def parse_control(parts: list[str]) -> tuple[str, str] | None:
    """``(action, name)`` of a control key's chunks after ``lunaris/<rover>/``: ``reset``,
    ``session``, ``mark`` (name ""), ``snapshot`` or ``restore`` (a name); None for others."""
    what = parts[1:] if parts[:1] == ["control"] else []
    if what in (["reset"], ["session"], ["mark"]):
        return what[0], ""
    if len(what) == 2 and what[0] in ("snapshot", "restore") and SNAPSHOT_NAME.match(what[1]):
        return what[0], what[1]
    return None


class SessionKeeper:
    """Persistence, reset, snapshots and restores of one service's state."""

    def __init__(self, rt: Host, get: StateGet, set_: StateSet, reset: StateReset,
                 after: Callable[[str], None] | None, persist_every_s: float | None,
                 check: StateCheck | None = None, damaged: StateDamaged | None = None,
                 files: dict[str, str] | None = None):
        self.rt, self._get, self._set, self._reset = rt, get, set_, reset
        self._files = files or {}  # rover -> the fingerprint of its rover file (common.config)
        self._after = after or (lambda rover: None)
        self._check = check
        self._damaged = damaged or self._reset_damaged
        self.epoch: dict[str, int] = {}  # rover -> the epoch of the session followed
        self.resumed: set[str] = set()  # rovers whose saved state was read back
        self.damaged: dict[str, str] = {}  # rover -> what was wrong with its saved state
        # Without a state directory, snapshots live as long as the service.
        self._memory: dict[str, dict[str, Any]] = {}
        self._templates = {rover: get(rover) for rover in rt.rovers}  # the rover file's state
        self._load()
        if persist_every_s is not None:
            rt.every(persist_every_s, self.persist)
        rt.on_exit(self.persist)
        rt.subscribe(keys.under("*", "control/snapshot/*"), self._on_snapshot)
        rt.queryable(keys.snapshots_of("*", rt.name), self._on_query)

    # -- persistence -------------------------------------------------------------------------

    def _load(self) -> None:
        """Read the saved state back: every rover whose record is intact resumes; the others
        are reset, each said in a ``critical`` event, and the damaged file moved aside."""
        rt = self.rt
        try:
            saved = rt.store.load("state")
        except Damaged as exc:
            for rover in sorted(rt.rovers):
                self._report(rover, exc.reason, exc.where())
            return
        if saved is None:
            return
        bad: dict[str, str] = {}
        changed: list[str] = []  # saved with another version of the rover file
        if not isinstance(saved, dict):
            bad = dict.fromkeys(sorted(rt.rovers), f"the file holds {kind_of(saved)}, not a "
                                                     "mapping of rovers")
        for rover in sorted(rt.rovers) if not bad else ():
            record = saved.get(rover)
            if record is None:
                continue  # not saved yet (a rover new to the fleet)
            if self._other_file(rover, record):
                changed.append(rover)
                continue
            try:
                state, epoch = self._record(rover, record)
            except ValueError as exc:
                bad[rover] = str(exc)
                continue
            try:
                self._set(rover, state)
            except Exception as exc:  # a value the service's set refuses: damaged all the same
                bad[rover] = f"{type(exc).__name__}: {exc}"
                continue
            self.epoch[rover] = epoch
            self.resumed.add(rover)
        if bad or changed:
            moved = rt.store.set_aside("state", "damaged" if bad else "old-rover-file")
            where = f"the file was moved to {moved.name}" if moved else "the file is left where it is"
            for rover, reason in bad.items():
                self._report(rover, reason, where)
            for rover in changed:
                self._reset(rover)
                rt.state_damaged(rover, f"{rt.name} state of {rover} not resumed: it was saved with "
                                 "another version of the rover file, changed since; started from the "
                                 f"rover file as it is now; {where}",
                                 params={"what": "state", "reason": "rover file changed",
                                         "done": "started from the rover file"}, severity="warning")
            self.persist()  # the intact rovers' records, in a file of their own again

    def _other_file(self, rover: str, record: Any) -> bool:
        """Whether ``record`` was saved with another version of the rover's file (a record
        saved before files were fingerprinted says nothing: it resumes)."""
        saved = record.get("file") if isinstance(record, dict) else None
        return saved is not None and rover in self._files and saved != self._files[rover]

    def _record(self, rover: str, record: Any) -> tuple[dict[str, Any], int]:
        """The state and epoch of a saved record, checked; ValueError naming the problem."""
        if not isinstance(record, dict) or not isinstance(record.get("state"), dict):
            what = kind_of(record.get("state")) if isinstance(record, dict) else kind_of(record)
            raise ValueError(f"the state is {what}, not a mapping")
        epoch = record.get("epoch", 0)
        if type(epoch) is not int or epoch < 0:
            raise ValueError(f"epoch is {quoted(epoch)}, not a whole number >= 0")
        state = record["state"]
        self.check(rover, state)
        return state, epoch

    def check(self, rover: str, state: dict[str, Any]) -> None:
        """Check a saved state of ``rover`` without applying it: ValueError naming what is
        wrong (a field's type, a number that is not finite, a value out of range)."""
        problem = shape_problem(state, self._templates.get(rover, {}))
        if problem:
            raise ValueError(problem)
        if self._check is not None:
            try:
                self._check(rover, state)
            except (TypeError, KeyError, msgspec.ValidationError) as exc:
                raise ValueError(str(exc)) from None

    def _report(self, rover: str, reason: str, where: str) -> None:
        self.damaged[rover] = reason
        done = self._damaged(rover)
        self.rt.state_damaged(
            rover, f"{self.rt.name} state of {rover} damaged ({reason}): {done}; {where}",
            params={"what": "state", "reason": reason, "done": done})

    def _reset_damaged(self, rover: str) -> str:
        self._reset(rover)
        return "reset to the rover file"

    def persist(self, durable: bool = True) -> None:
        self.rt.save_state("state", {
            rover: {"state": self._get(rover), "epoch": self.epoch.get(rover, 0),
                    **({"file": self._files[rover]} if rover in self._files else {})}
            for rover in sorted(self.rt.rovers)}, durable)

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
            self.begin(rover, tick.cause, tick.session)
        return True

    def begin(self, rover: str, cause: str, session: str = "") -> None:
        """A new epoch: ``reset`` or ``restore:<name>``, in ``session`` (the same one, or a
        new trainee's)."""
        if cause == "reset":
            self.reset(rover, session)
        elif cause.startswith(RESTORE):
            self.restore(rover, cause[len(RESTORE):], session)
        else:
            self._enter(rover, session)

    def _enter(self, rover: str, session: str) -> None:
        self.rt.enter_session(rover, session)  # once the ending session's faults are cleared

    def reset(self, rover: str, session: str = "") -> None:
        """Every injected fault cleared (journalled), the state back to the rover file's."""
        if self.rt.has_faults:
            self.rt.faults.clear_all(rover)
        self._enter(rover, session)
        self._reset(rover)
        self.rt.t_s[rover] = 0.0
        self._changed(rover)

    def restore(self, rover: str, name: str, session: str = "") -> bool:
        """Put this service's part of snapshot ``name`` back; whether it could. A part that is
        missing or damaged (the clock checks every part before it begins a restore: a service
        that was down then) is said aloud, and the service keeps its state."""
        try:
            state, t_s, faults = self._part(rover, name)
        except ValueError as exc:
            self._enter(rover, session)
            if str(exc) == NO_PART:
                self.rt.event(rover, "warning", "session", keys.control_restore(rover, name),
                              f"{self.rt.name} holds no part of snapshot {name!r} of {rover} "
                              "(it was not running when it was saved): its state is kept")
            else:
                self.rt.state_damaged(
                    rover, f"{self.rt.name} part of snapshot {name!r} of {rover} damaged ({exc}): "
                    "its state is kept", keys.control_restore(rover, name))
            return False
        if self.rt.has_faults:
            self.rt.faults.clear_all(rover)
        self._enter(rover, session)
        self._set(rover, state)
        self.rt.t_s[rover] = t_s
        if self.rt.has_faults:
            for fault in faults:
                self.rt.faults.reinject(rover, fault)
        self._changed(rover)
        return True

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
            return
        try:
            existing = store.load("snapshot") or {}
        except Damaged as exc:
            existing = {}
            self.rt.state_damaged(rover, f"{self.rt.name} part of snapshot {name!r} damaged "
                                  f"({exc.reason}): saved anew with this rover only (the other "
                                  f"rovers' parts of it are lost); {exc.where()}",
                                  keys.control_snapshot(rover, name))
        if not isinstance(existing, dict):
            existing = {}
        existing[rover] = record
        try:
            store.save("snapshot", existing)
        except OSError as exc:
            self.rt.state_damaged(rover, f"{self.rt.name} could not save its part of snapshot "
                                  f"{name!r} ({exc.strerror or exc})", keys.control_snapshot(rover, name))

    def _store(self, name: str) -> StateStore | None:
        if self.rt.store.dir is None:
            return None
        return StateStore(self.rt.store.dir / "snapshots" / name, self.rt.name)

    def _read(self, name: str) -> Any:
        """This service's file of snapshot ``name`` as read (None: none); Damaged, left in place."""
        store = self._store(name)
        return self._memory.get(name) if store is None else store.load("snapshot", set_aside=False)

    def _part(self, rover: str, name: str) -> tuple[dict[str, Any], float, list]:
        """(state, t_s, faults) of this service's part of snapshot ``name``, every piece
        checked as it will be used; ValueError(NO_PART) when there is none, ValueError naming
        the damage otherwise."""
        try:
            saved = self._read(name)
        except Damaged as exc:
            raise ValueError(exc.reason) from None
        if saved is None or (isinstance(saved, dict) and rover not in saved):
            raise ValueError(NO_PART)
        if not isinstance(saved, dict):
            raise ValueError(f"the file holds {kind_of(saved)}, not a mapping of rovers")
        record = saved[rover]
        if not isinstance(record, dict) or not isinstance(record.get("state"), dict):
            raise ValueError("the part is not a mapping with a state")
        t_s = record.get("t_s", 0.0)
        if isinstance(t_s, bool) or not isinstance(t_s, int | float) or not_finite(float(t_s)) \
                or t_s < 0:
            raise ValueError(f"t_s is {quoted(t_s)}, not a finite number >= 0")
        self.check(rover, record["state"])
        raw_faults = record.get("faults", [])
        if not isinstance(raw_faults, list):
            raise ValueError(f"faults is {kind_of(raw_faults)}, not a list")
        faults = []
        for raw in raw_faults:
            try:
                faults.append(saved_fault(raw)[0])
            except ValueError as exc:
                raise ValueError(f"a saved fault: {exc}") from None
        return record["state"], float(t_s), faults

    def check_part(self, rover: str, name: str) -> str | None:
        """None when this service's part of snapshot ``name`` is intact, :data:`NO_PART` when
        it holds none, else what is damaged."""
        try:
            self._part(rover, name)
        except ValueError as exc:
            return str(exc)
        return None

    def names(self, rover: str) -> list[str]:
        """The snapshots of ``rover`` this service holds a part of (a damaged file counts:
        it may hold one, and a restore must not go on without it)."""
        if self.rt.store.dir is None:
            return sorted(n for n, rovers in self._memory.items() if rover in rovers)
        root = self.rt.store.dir / "snapshots"
        if not root.is_dir():
            return []
        return sorted(d.name for d in root.iterdir() if d.is_dir() and self._holds(rover, d.name))

    def _holds(self, rover: str, name: str) -> bool:
        try:
            saved = self._read(name)
        except Damaged:
            return True
        return saved is not None and (not isinstance(saved, dict) or rover in saved)

    def info(self, rover: str) -> list[SnapshotInfo]:
        """The intact snapshots of ``rover`` this service holds, as listed."""
        out = []
        for name in self.names(rover):
            try:
                record = self._read(name)[rover]
                out.append(SnapshotInfo(name=name, t_s=float(record.get("t_s", 0.0)),
                                        saved_at=float(record.get("saved_at", 0.0)),
                                        services=[self.rt.name]))
            except (Damaged, TypeError, KeyError, ValueError, AttributeError):
                continue  # damaged: a restore says so
        return out

    def _on_query(self, q: zenoh.Query) -> None:
        with q:
            check = q.parameters.get("check")
            for rover in sorted(self.rt.rovers):
                key = keys.snapshots_of(rover, self.rt.name)
                if not zenoh.KeyExpr(key).intersects(q.key_expr):
                    continue
                if check is None:
                    body = b"[" + b",".join(encode(i) for i in self.info(rover)) + b"]"
                    q.reply(key, body, encoding=zenoh.Encoding.APPLICATION_JSON)
                    continue
                problem = self.check_part(rover, check) if SNAPSHOT_NAME.match(check) else NO_PART
                if problem is None:
                    infos = [i for i in self.info(rover) if i.name == check]
                    q.reply(key, b"[" + b",".join(encode(i) for i in infos) + b"]",
                            encoding=zenoh.Encoding.APPLICATION_JSON)
                elif problem == NO_PART:
                    q.reply(key, b"[]", encoding=zenoh.Encoding.APPLICATION_JSON)
                else:
                    q.reply_err(msgspec.json.encode({"service": self.rt.name, "rover": rover,
                                                     "problem": problem}))
