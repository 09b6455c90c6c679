"""Prediction (SPEC §4): a Monte Carlo of the rover's futures, vectorised over the samples.

From a :class:`Start` (the rover file's initial state, or the live twin's), ``N`` futures
run together as numpy arrays, each the way the composed twin (:mod:`services.composed`)
runs the rover: the pack steps at the demand it holds (:class:`~services.battery.packs.Packs`,
the pack's own equations), then the loads draw, then the PDM sheds, protects and trips
rails, and the new net demand goes to the pack. Held over the horizon, as they are now:
the generation (sun, dust, umbilical), the rails' commands and converter failures, every
injected fault. What differs between futures:

- the loads' noise, as the loads service draws it: each tick, each load
  ``clip(N(nominal_w, std_w), 0, max_w)``. With a step of one tick (``step_ticks=1``) it is
  drawn exactly so. A longer step of ``k`` ticks holds the mean of its ``k`` ticks, drawn
  per rail as a normal with the clipped loads' exact mean and variance ``/ k`` (the sum of
  many independent draws; a rail that only trips at the peak of one tick's noise is not
  tripped by it: ``lunaris check`` warns of such rails);
- the rover file's ``battery.uncertainty``: per future, the capacity, every resistance and
  the generation times ``1 + frac * N(0, 1)`` (kept above zero).

With no noise and no uncertainty every future is the composed twin's run (a test holds them
to it). Reported: the time to empty (the pack first depleted or cut off for under-voltage;
``inf`` where not within the horizon) and the state of charge at the horizon, with the
percentiles the ``prediction`` query returns (SPEC §5).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from common.config import Rover
from services.battery.model import BatteryModel
from services.battery.packs import Packs

__all__ = ["MAX_STEPS", "Outcome", "RailStart", "Start", "assumptions", "clipped_moments", "percentiles",
           "predict", "start_of"]


def assumptions(rover: Rover) -> list[str]:
    """What every prediction assumes, in words for its notes: the inputs held and where the
    spread of its futures comes from. Found by a vehicle engineer: four answers to "how long
    does it last" differed and none said why; a rover file without uncertainty gave p05 = p95
    with nothing saying the spread was zero."""
    u = rover.battery.uncertainty
    spread = [f"{name} {frac:.0%}" for name, frac in (("capacity", u.capacity_frac),
              ("resistance", u.resistance_frac), ("generation", u.generation_frac)) if frac > 0.0]
    return ["held over the whole horizon: the sun and the generation as now, the rails' switches "
            "(a shed rail comes back above its threshold), each load's nominal power with its noise",
            ("each future draws its own " + ", ".join(spread) + " (battery.uncertainty: one standard "
             "deviation each)") if spread else
            "the rover file gives no battery.uncertainty: the futures differ by the loads' noise only"]


MAX_STEPS = 10_000  # the default step is the tick, or longer so that a horizon takes no more
_NOISE_BLOCK = 64  # steps of noise drawn at once


class RailStart(NamedTuple):
    """A rail's switches now."""

    commanded_on: bool = True
    tripped: bool = False
    failed: bool = False
    shed: bool = False


class Start(NamedTuple):
    """Where the futures start from: the pack (its state and injected faults), the rails, the
    loads a fault holds at a power, and the generation, all held but for what evolves."""

    rover: Rover
    pack: BatteryModel
    rails: dict[str, RailStart]
    fixed_load_w: dict[str, float]  # short, open, stuck: the power while the rail is on
    generation_w: float
    t_s: float = 0.0
    # A load whose power follows a plan, tick by tick (the drive's load along a traverse),
    # and then stays at the plan's last value; it replaces the load's noise or fixed power.
    profile: tuple[str, tuple[float, ...]] | None = None


def start_of(twin) -> Start:
    """The start of a :class:`~services.composed.ComposedTwin` as it is now."""
    power, loads = twin.power, twin.loads
    rails = {name: RailStart(sw.commanded_on, sw.tripped, sw.failed, sw.shed)
             for name, sw in power.switches.items()}
    fixed = {name: p for name in loads.names if (p := loads.fault_power(name)) is not None}
    for name, power_w in loads.driven_w.items():  # the drive's load, at the drive's present power
        fixed.setdefault(name, power_w)
    return Start(twin.rover, twin.battery, rails, fixed, twin.summary.generation_w, twin.t_s)


class Outcome(NamedTuple):
    t_s: float  # sim time of the start
    horizon_s: float
    step_s: float
    samples: int
    time_to_empty_s: np.ndarray  # from the start; inf where not within the horizon
    soc_at_horizon: np.ndarray


def percentiles(values: np.ndarray, qs: tuple[int, ...] = (5, 50, 95)) -> dict[str, float | None]:
    """``{"p05": ..., "p50": ..., "p95": ...}`` by linear interpolation between order
    statistics; None where the percentile is not reached (it involves an ``inf``)."""
    v = np.sort(np.asarray(values, dtype=float))
    out: dict[str, float | None] = {}
    for q in qs:
        pos = q / 100.0 * (len(v) - 1)
        lo, hi = math.floor(pos), math.ceil(pos)
        if not math.isfinite(v[hi]):
            out[f"p{q:02d}"] = None
        else:
            out[f"p{q:02d}"] = float(v[lo] + (v[hi] - v[lo]) * (pos - lo))
    return out


def clipped_moments(mean: float, std: float, lo: float, hi: float) -> tuple[float, float]:
    """Mean and variance of ``clip(N(mean, std), lo, hi)``, exactly (bounds may be infinite).
    With ``Y = X - mean = clip(std Z, a std, b std)``, ``a = (lo - mean) / std`` and
    ``b = (hi - mean) / std``: ``E[Y] = lo' P(Z < a) + hi' P(Z > b) + std (pdf(a) - pdf(b))``
    and ``E[Y^2] = lo'^2 P(Z < a) + hi'^2 P(Z > b) + std^2 (P(a < Z < b) + a pdf(a) -
    b pdf(b))``, where ``lo' = lo - mean``, ``hi' = hi - mean``."""
    if std <= 0.0:
        return min(max(mean, lo), hi), 0.0
    lo_c, hi_c = lo - mean, hi - mean
    a, b = lo_c / std, hi_c / std
    below, above = _cdf(a), 1.0 - _cdf(b)
    m1 = _times(lo_c, below) + _times(hi_c, above) + std * (_pdf(a) - _pdf(b))
    m2 = (_times(lo_c * lo_c, below) + _times(hi_c * hi_c, above)
          + std * std * (1.0 - below - above + _times(a, _pdf(a)) - _times(b, _pdf(b))))
    return mean + m1, max(0.0, m2 - m1 * m1)


def _times(x: float, weight: float) -> float:
    """``x * weight``, 0 where the weight is (an infinite bound has no mass beyond it)."""
    return x * weight if weight != 0.0 else 0.0


def _cdf(z: float) -> float:
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


def _pdf(z: float) -> float:
    return math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi) if math.isfinite(z) else 0.0


class _Loads:
    """Each rail's load power per step [W], for every future."""

    def __init__(self, start: Start, k: int, n: int, rng: np.random.Generator):
        rover = start.rover
        self.n, self.rng, self.k = n, rng, k
        self.rails = [r.name for r in rover.rails]
        # per rail: the loads in file order, each (nominal, std, max) or a fixed power
        self.members: list[list[tuple[float, float, float] | float]] = [[] for _ in self.rails]
        planned = start.profile[0] if start.profile is not None else None
        for ld in rover.loads:
            if ld.name == planned:
                continue  # added each step from the plan
            held = start.fixed_load_w.get(ld.name)
            self.members[self.rails.index(ld.rail)].append(
                held if held is not None else (ld.nominal_w, ld.std_w, ld.max_w))
        # with no noise, the sum the PDM makes: 0.0 + each load's power, in file order
        self.mean: list[float] = []
        self.spread: list[float] = []  # the rail's std over a step of k ticks
        self.top: list[float] = []
        for members in self.members:
            acc, var, top = 0.0, 0.0, 0.0
            for m in members:
                if isinstance(m, tuple):
                    mu, v = clipped_moments(m[0], m[1], 0.0, m[2])
                    acc, var, top = acc + mu, var + v, top + m[2]
                else:
                    acc, top = acc + m, top + m
            self.mean.append(acc)
            self.spread.append(math.sqrt(var / k))
            self.top.append(top)
        self.noisy = any(s > 0.0 for s in self.spread)
        self._block: list[list[np.ndarray]] = []

    def next(self) -> list[np.ndarray]:
        if not self.noisy:
            return [np.full(self.n, m) for m in self.mean]
        if not self._block:
            self._block = self._draw()
        return self._block.pop()

    def _draw(self) -> list[list[np.ndarray]]:
        if self.k == 1:  # exactly as the loads service: per load, per tick, clipped
            rails = []
            for members in self.members:
                acc = np.zeros((_NOISE_BLOCK, self.n))
                for m in members:  # 0.0 + each load, in file order, as the PDM adds them
                    if isinstance(m, tuple):
                        acc = acc + np.clip(self.rng.normal(m[0], m[1], (_NOISE_BLOCK, self.n)),
                                            0.0, m[2])
                    else:
                        acc = acc + m
                rails.append(acc)
            return [[r[b] for r in rails] for b in range(_NOISE_BLOCK)]
        block = self.rng.standard_normal((_NOISE_BLOCK, len(self.rails), self.n))
        mean, spread, top = (np.array(v)[None, :, None] for v in (self.mean, self.spread, self.top))
        block *= spread
        block += mean  # mean + spread * z, in place
        np.clip(block, 0.0, top, out=block)
        return [list(block[b]) for b in range(_NOISE_BLOCK)]


class _Pdm:
    """:class:`~services.power.model.PowerModel`'s ``set_battery`` and ``resolve`` on arrays."""

    def __init__(self, start: Start, n: int):
        rails = start.rover.rails
        self.cfg = rails
        self.usable = []  # commanded on and its converter alive (held)
        self.tripped, self.shed = [], []
        for r in rails:
            st = start.rails.get(r.name, RailStart(r.initially_on))
            self.usable.append(st.commanded_on and not st.failed)
            self.tripped.append(np.full(n, st.tripped))
            self.shed.append(np.full(n, st.shed))
        self.sheddable = [(k, r.shed_below_soc,
                           r.restore_above_soc if r.restore_above_soc is not None
                           else r.shed_below_soc + 0.05)
                          for k, r in enumerate(rails) if r.shed_below_soc is not None]

    def bus_w(self, soc: np.ndarray, operational: np.ndarray, rail_w: list[np.ndarray]) -> np.ndarray:
        shed = self.shed
        for k, below, restore in self.sheddable:
            shed[k] = (~shed[k] & (soc < below)) | (shed[k] & ~(soc >= restore))
        bus = np.zeros_like(soc)
        for k, r in enumerate(self.cfg):
            if not self.usable[k]:
                continue
            on = operational & ~shed[k] & ~self.tripped[k]
            trip = on & (rail_w[k] / r.voltage_v > r.current_limit_a)
            if trip.any():
                self.tripped[k] = self.tripped[k] | trip
                on = on & ~trip
            bus = bus + np.where(on, rail_w[k] / r.efficiency, 0.0)  # 0.0 + ..., in rail order
        return bus


def predict(start: Start, horizon_s: float, samples: int, seed: int | None = None,
            step_ticks: int | None = None,
            progress: Callable[[int, int], None] | None = None) -> Outcome:
    """Run ``samples`` futures over ``horizon_s`` (rounded to whole steps) from ``start``.
    ``step_ticks``: ticks per step (default: 1, or more so the horizon takes at most
    :data:`MAX_STEPS` steps). ``progress(done, total)`` is called about every 5 %."""
    if not (math.isfinite(horizon_s) and horizon_s > 0.0):
        raise ValueError(f"horizon_s must be finite and > 0, got {horizon_s}")
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    tick_s = 1.0 / start.rover.tick_hz
    k = step_ticks or max(1, math.ceil(horizon_s / tick_s / MAX_STEPS))
    if k < 1:
        raise ValueError(f"step_ticks must be >= 1, got {k}")
    dt = k / start.rover.tick_hz
    steps = max(1, round(horizon_s / dt))
    rng = np.random.default_rng(seed)
    u = start.rover.battery.uncertainty
    packs = Packs(start.pack, _factors(rng, u.capacity_frac, samples),
                  _factors(rng, u.resistance_frac, samples))
    generation = start.generation_w * _factors(rng, u.generation_frac, samples)
    loads, pdm = _Loads(start, k, samples, rng), _Pdm(start, samples)
    planned = _planned(start, k, steps)
    empty = np.where(packs.depleted | packs.uv_cutoff, 0.0, np.inf)
    report = max(1, steps // 20)
    for n in range(1, steps + 1):
        packs.step(dt)
        gone = packs.depleted | packs.uv_cutoff
        empty = np.where(np.isinf(empty) & gone, n * dt, empty)
        rail_w = loads.next()
        if planned is not None:
            rail, power_w = planned
            rail_w = list(rail_w)
            rail_w[rail] = rail_w[rail] + power_w[n - 1]
        packs.demand_w = pdm.bus_w(packs.soc, packs.operational, rail_w) - generation
        if progress is not None and ((n % report == 0 and steps - n >= report // 2) or n == steps):
            progress(n, steps)
    return Outcome(start.t_s, steps * dt, dt, samples, empty, packs.soc)


def _planned(start: Start, k: int, steps: int) -> tuple[int, np.ndarray] | None:
    """The planned load's rail and its mean power over each step of ``k`` ticks."""
    if start.profile is None:
        return None
    name, ticks = start.profile
    load = next(ld for ld in start.rover.loads if ld.name == name)
    per_tick = np.array(ticks or (0.0,), dtype=float)
    need = steps * k
    if len(per_tick) < need:
        per_tick = np.concatenate([per_tick, np.full(need - len(per_tick), per_tick[-1])])
    per_step = per_tick[:need].reshape(steps, k).mean(axis=1)
    return [r.name for r in start.rover.rails].index(load.rail), per_step


def _factors(rng: np.random.Generator, frac: float, n: int) -> np.ndarray:
    if frac <= 0.0:
        return np.ones(n)
    return np.maximum(1.0 + frac * rng.standard_normal(n), 1e-3)
