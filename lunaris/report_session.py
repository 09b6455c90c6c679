"""One session of one rover as ``lunaris report`` draws it: its time series on the session's
timeline (a reset or a restore within the session goes on from where it was) and its score.
Filled by :mod:`lunaris.report`, drawn by :mod:`lunaris.report_draw`."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

from common.response import SessionResponse

__all__ = ["Series", "Session"]


Series = tuple[list[float], list[float]]


def _series() -> defaultdict[str, Series]:
    return defaultdict(lambda: ([], []))


@dataclass
class Session:
    """The time series of one session of one rover, by sim time [s], and its score."""

    rover: str
    id: str = ""
    battery: dict[str, Series] = field(default_factory=_series)
    loads: dict[str, Series] = field(default_factory=_series)
    panels: dict[str, Series] = field(default_factory=_series)
    summary: dict[str, Series] = field(default_factory=_series)
    umbilical: Series = field(default_factory=lambda: ([], []))
    path: tuple[list[float], list[float], list[float]] = field(default_factory=lambda: ([], [], []))
    radios: dict[str, Series] = field(default_factory=_series)
    events: list[dict] = field(default_factory=list)  # each with "at_s": its time in the session, or None
    thresholds: dict[str, list[tuple[float, str]]] = field(default_factory=dict)  # plot -> (value, label)
    score: SessionResponse | None = None
    # the timeline: time in the session = sim time + offset, the offset changing with each epoch
    offset_s: float | None = None
    epoch: int | None = None
    last_s: float = 0.0

    @property
    def span_s(self) -> tuple[float, float]:
        ts = self.battery["soc"][0] or self.summary["load_power_w"][0]
        return (min(ts), max(ts)) if ts else (0.0, 0.0)

    def at(self, t_s: float) -> float:
        """The session's time [s since its start] of a sim time of the current epoch."""
        if self.offset_s is None:
            self.offset_s = -t_s
        return t_s + self.offset_s

    def x(self, t_s: float | None) -> float:
        """Where a sim time of the session's (last) epoch falls on its timeline."""
        return 0.0 if t_s is None else t_s + (self.offset_s or 0.0)

    def on_clock(self, t_s: float, epoch: int) -> None:
        """A restore within the session goes on from where it was, not back in time."""
        if self.epoch is not None and epoch != self.epoch:
            self.offset_s = self.last_s - t_s
        self.epoch = epoch
        self.last_s = max(self.last_s, self.at(t_s))

    @property
    def telemetry(self) -> bool:
        return bool(self.battery["soc"][0] or self.summary["load_power_w"][0])

    def add_event(self, v: dict) -> None:
        t_sim = float(v.get("t_s", 0.0))
        at = self.at(t_sim) if self.offset_s is not None else None
        # replayed from the caches: older than the session's first tick in the recording
        v["at_s"] = at if at is not None and at >= -1e-9 and self.epoch is not None else None
        self.events.append(v)

    def add_value(self, family: str, parts: list[str], v: dict) -> None:
        t_sim = float(v.get("t_s", 0.0))
        if family == "clock":
            self.on_clock(t_sim, int(v.get("epoch", 0)))
        elif self.offset_s is None:
            return  # before the first tick: no place on the timeline yet
        t = self.at(t_sim)
        if t > self.last_s + 2.0 or t < -1e-9:
            return  # a straggler of the epoch before a restore
        if family == "battery/state":
            for name in ("soc", "voltage_v", "current_a", "temperature_c", "power_w"):
                _add(self.battery[name], t, v.get(name))
        elif family == "load/*/power":
            _add(self.loads[parts[1]], t, v.get("power_w"))
        elif family == "solar/*/power":
            _add(self.panels[parts[1]], t, v.get("power_w"))
        elif family == "power/summary":
            for name in ("load_power_w", "generation_w", "net_battery_power_w"):
                _add(self.summary[name], t, v.get(name))
        elif family == "umbilical/state":
            _add(self.umbilical, t, v.get("power_w"))
        elif family == "drive/state":
            if None not in (v.get("x_m"), v.get("y_m"), v.get("power_w")):
                for series, name in zip(self.path, ("x_m", "y_m", "power_w"), strict=True):
                    series.append(float(v[name]))
        elif family == "radio/*/link":
            _add(self.radios[parts[1]], t, 1.0 if v.get("in_range") else 0.0)


def _add(series: Series, t: float, v: float | None) -> None:
    if v is not None:
        series[0].append(t)
        series[1].append(float(v))
