"""Simulated time: a tick of ``time_scale / tick_hz`` seconds each wall tick.

The clock owns the simulated time ``t_s`` of one rover. Ticks come at the
rover's ``tick_hz`` in wall time; each advances ``t_s`` by
``dt_s = time_scale / tick_hz`` (zero while paused), so scaling time changes
how much each tick integrates, not how often models run.

The clock also counts the session's *epochs*: a reset, or the restore of a snapshot,
starts a new epoch, and every tick carries the epoch and what started it (``cause``).
The other services follow the tick stream, so each acts on a reset or a restore at the
same point of simulated time, and a tick from before it can never be taken for one
after it.

And the trainee *session* each tick belongs to (SPEC §12c): a session begins with an epoch
(the twin reset, or a snapshot restored) and lasts until the next session begins; resets
and restores within it keep it. Its id is the UTC wall time it began (:func:`session_id`),
one second past the previous id when two begin within a second, so ids grow and never repeat
for a rover. The session is the one begun last: a snapshot of an earlier session, restored,
never brings that session back (:meth:`ClockModel.set_state`).
"""

from __future__ import annotations

import calendar
import time
from typing import NamedTuple

from common.messages import SESSION_ID

__all__ = ["ClockModel", "Tick", "session_id"]

_FORMAT = "%Y%m%d-%H%M%S"
_PER_SECOND = 999  # sessions counted within one second of the wall clock (.001 to .999)


def session_id(wall_s: float, after: str = "") -> str:
    """The id of a session begun at wall time ``wall_s`` [s since the Unix epoch]: its UTC
    time to the second, ``20250114-195312``; when that would not come after ``after`` (the
    previous session's id: two begun in one second, or a clock behind), the second of
    ``after`` with a count, ``20250114-195312.001``, which sorts after it and before the next
    second. Ids stay at the wall clock in a burst (they went one second ahead per session: 100
    sessions begun at once were 89 s ahead) and never collide.

    >>> session_id(1736884392.7)
    '20250114-195312'
    >>> session_id(1736884392.7, after='20250114-195312')
    '20250114-195312.001'
    >>> session_id(1736884392.9, after='20250114-195312.001')
    '20250114-195312.002'
    >>> session_id(1736884393.1, after='20250114-195312.002')
    '20250114-195313'
    """
    second = int(wall_s)
    if SESSION_ID.match(after):
        last = calendar.timegm(time.strptime(after[:15], _FORMAT))
        if second <= last:
            count = int(after[16:] or 0) + 1
            if count <= _PER_SECOND:
                return f"{after[:15]}.{count:03d}"
            second = last + 1
    return time.strftime(_FORMAT, time.gmtime(second))


class Tick(NamedTuple):
    t_s: float
    dt_s: float
    seq: int
    time_scale: float
    paused: bool
    epoch: int
    cause: str
    session: str


class ClockModel:
    def __init__(self, tick_hz: float, t_s: float = 0.0, seq: int = 0,
                 time_scale: float = 1.0, paused: bool = False):
        if tick_hz <= 0:
            raise ValueError(f"tick_hz must be > 0, got {tick_hz}")
        self.tick_hz = tick_hz
        self.t_s = t_s
        self.seq = seq
        self.time_scale = time_scale
        self.paused = paused
        self.epoch = 0
        self.cause = ""
        # the session running: its id, the epoch it began with, its trainee, when it began
        self.session = ""
        self.session_epoch = -1
        self.trainee = ""
        self.session_wall = 0.0

    def state(self) -> dict[str, float | int | bool | str]:
        return {"t_s": self.t_s, "seq": self.seq, "time_scale": self.time_scale,
                "paused": self.paused, "epoch": self.epoch, "cause": self.cause,
                "session": self.session, "session_epoch": self.session_epoch,
                "trainee": self.trainee, "session_wall": self.session_wall}

    def set_state(self, state: dict) -> None:
        """Time and speed as saved; the epoch never goes back (see :meth:`new_epoch`), nor
        does the session: a state saved in the session running (or a later one: the state
        read back at a restart) brings its session, one saved in an earlier session (a
        snapshot restored) leaves the running session as it is."""
        self.t_s = float(state.get("t_s", 0.0))
        self.seq = int(state.get("seq", 0))
        self.set_scale(float(state.get("time_scale", 1.0)))
        self.paused = bool(state.get("paused", False))
        self.epoch = max(self.epoch, int(state.get("epoch", 0)))
        self.cause = str(state.get("cause", self.cause))
        saved_epoch = int(state.get("session_epoch", -1))
        if state.get("session") and saved_epoch >= self.session_epoch:
            self.session, self.session_epoch = str(state["session"]), saved_epoch
            self.trainee = str(state.get("trainee", ""))
            self.session_wall = float(state.get("session_wall", 0.0))

    def begin_session(self, trainee: str, wall_s: float) -> str:
        """A new session from now (the epoch that begins it already begun): its id."""
        self.session = session_id(wall_s, after=self.session)
        self.session_epoch = self.epoch
        self.trainee = trainee
        self.session_wall = wall_s
        return self.session

    def resume_session(self, session: str, epoch: int) -> None:
        """Go on in ``session`` (learnt from the twin by a clock that lost its state)."""
        self.session, self.session_epoch = session, epoch

    def new_epoch(self, cause: str) -> None:
        """A reset or a restore begins: later ticks say so."""
        self.epoch += 1
        self.cause = cause

    def reset(self) -> None:
        """Back to the start: t = 0, real time, running, in a new epoch."""
        self.set_state({"epoch": self.epoch})
        self.new_epoch("reset")

    @property
    def period_s(self) -> float:
        """Wall time between ticks [s]."""
        return 1.0 / self.tick_hz

    def set_scale(self, time_scale: float) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.time_scale = time_scale

    def mark(self) -> Tick:
        """A tick that advances nothing: the present time, at once (after a reset)."""
        self.seq += 1
        return Tick(self.t_s, 0.0, self.seq, self.time_scale, self.paused, self.epoch, self.cause,
                    self.session)

    def tick(self) -> Tick:
        dt = 0.0 if self.paused else self.time_scale / self.tick_hz
        self.t_s += dt
        self.seq += 1
        return Tick(self.t_s, dt, self.seq, self.time_scale, self.paused, self.epoch, self.cause,
                    self.session)
