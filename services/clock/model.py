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
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["ClockModel", "Tick"]


class Tick(NamedTuple):
    t_s: float
    dt_s: float
    seq: int
    time_scale: float
    paused: bool
    epoch: int
    cause: str


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

    def state(self) -> dict[str, float | int | bool | str]:
        return {"t_s": self.t_s, "seq": self.seq, "time_scale": self.time_scale,
                "paused": self.paused, "epoch": self.epoch, "cause": self.cause}

    def set_state(self, state: dict) -> None:
        """Time and speed as saved; the epoch never goes back (see :meth:`new_epoch`)."""
        self.t_s = float(state.get("t_s", 0.0))
        self.seq = int(state.get("seq", 0))
        self.set_scale(float(state.get("time_scale", 1.0)))
        self.paused = bool(state.get("paused", False))
        self.epoch = max(self.epoch, int(state.get("epoch", 0)))
        self.cause = str(state.get("cause", self.cause))

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
        return Tick(self.t_s, 0.0, self.seq, self.time_scale, self.paused, self.epoch, self.cause)

    def tick(self) -> Tick:
        dt = 0.0 if self.paused else self.time_scale / self.tick_hz
        self.t_s += dt
        self.seq += 1
        return Tick(self.t_s, dt, self.seq, self.time_scale, self.paused, self.epoch, self.cause)
