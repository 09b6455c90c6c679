"""Simulated time: a tick of ``time_scale / tick_hz`` seconds each wall tick.

The clock owns the simulated time ``t_s`` of one rover. Ticks come at the
rover's ``tick_hz`` in wall time; each advances ``t_s`` by
``dt_s = time_scale / tick_hz`` (zero while paused), so scaling time changes
how much each tick integrates, not how often models run.
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

    @property
    def period_s(self) -> float:
        """Wall time between ticks [s]."""
        return 1.0 / self.tick_hz

    def set_scale(self, time_scale: float) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.time_scale = time_scale

    def tick(self) -> Tick:
        dt = 0.0 if self.paused else self.time_scale / self.tick_hz
        self.t_s += dt
        self.seq += 1
        return Tick(self.t_s, dt, self.seq, self.time_scale, self.paused)
