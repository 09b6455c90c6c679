"""Piecewise-linear curves of plain numbers: a rover file's open-circuit voltage and resistance
curves, as the battery's circuit (:mod:`services.battery.circuit`) steps with them every tick
and as ``lunaris check`` reads a pack's voltage at half charge (:mod:`common.budget`).
"""

from __future__ import annotations

import bisect
from typing import NamedTuple

__all__ = ["Table", "interp", "ocv"]


class Table(NamedTuple):
    """A piecewise-linear function, held flat outside its points."""

    x: list[float]
    y: list[float]
    slope: list[float]

    @classmethod
    def of(cls, x: list[float], y: list[float], scale: float = 1.0) -> Table:
        ys = [scale * v for v in y]
        slopes = [(ys[k + 1] - ys[k]) / (x[k + 1] - x[k]) for k in range(len(x) - 1)]
        return cls(list(x), ys, slopes)


def interp(x: float, t: Table) -> float:
    """``t`` at ``x``: the expression ``numpy.interp`` evaluates, so the scalar pack and the
    vectorised prediction agree to the last bit. (Plain Python: for one value it is several
    times faster than ``numpy.interp``, and it runs every tick.)"""
    xs = t.x
    if x <= xs[0]:
        return t.y[0]
    if x >= xs[-1]:
        return t.y[-1]
    k = bisect.bisect_right(xs, x) - 1
    return t.slope[k] * (x - xs[k]) + t.y[k]


def ocv(soc: float, curve_soc: list[float], curve_volts: list[float], cells_series: int) -> float:
    """Pack open-circuit voltage [V]: ``cells_series`` times the per-cell curve, linearly
    interpolated, held flat outside [0, 1]."""
    return interp(soc, Table.of(curve_soc, curve_volts, cells_series))
