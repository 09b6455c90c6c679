"""The reference cell run by NASA ProgPy's BatteryCircuit and by Lunaris, side by side.

ProgPy's own example current profile (``examples/sim.py``: 2 A, then 1 A from 600 s, 4 A
from 900 s, 2 A from 1800 s, 3 A from 3000 s) and constant-power discharges, ProgPy driven
by a loading function ``i = P / v`` on the terminal voltage at the start of each step, as
Lunaris holds its current over a step. ProgPy integrates with RK4 at :data:`PROGPY_DT_S`;
Lunaris steps the model of ``config/rovers/bc18650.yaml`` at the rover's tick. The end of
discharge is ProgPy's threshold (terminal voltage below VEOD = 3.0 V) and Lunaris's
under-voltage cut-off at the same voltage. Used by ``tests/services/test_progpy_reference.py``
and ``bench/battery.py``; needs ``progpy`` (the ``dev`` extra).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from common.config import Rover, load_rover
from services.battery.model import BatteryModel
from testbed.twin import ROVERS

__all__ = ["PROFILES", "Comparison", "Run", "compare", "energy_soc", "example_current_a",
           "lunaris_run", "progpy_model", "progpy_monte_carlo", "progpy_run", "progpy_state",
           "reference_cell"]

PROGPY_DT_S = 0.5
SAVE_S = 1.0
HORIZON_S = 20_000.0


def reference_cell() -> Rover:
    return load_rover(ROVERS / "bc18650.yaml")


def example_current_a(t: float) -> float:
    """ProgPy's example loading (``examples/sim.py``) [A]."""
    return 2.0 if t < 600 else 1.0 if t < 900 else 4.0 if t < 1800 else 2.0 if t < 3000 else 3.0


class Profile(NamedTuple):
    name: str
    kind: str  # "current" [A] or "power" [W]
    value: Callable[[float], float]


PROFILES = (
    Profile("ProgPy example current profile", "current", example_current_a),
    Profile("constant 8 W", "power", lambda t: 8.0),
    Profile("constant 15 W", "power", lambda t: 15.0),
)


class Run(NamedTuple):
    times_s: np.ndarray
    voltage_v: np.ndarray
    eod_s: float


def progpy_model():
    from progpy.models import BatteryCircuit
    return BatteryCircuit(process_noise=0, measurement_noise=0)


def progpy_run(profile: Profile, dt_s: float = PROGPY_DT_S) -> Run:
    m = progpy_model()

    def loading(t: float, x=None):
        if profile.kind == "current":
            return m.InputContainer({"i": profile.value(t)})
        v = m.output(x)["v"] if x is not None else m.parameters["V0"]
        return m.InputContainer({"i": profile.value(t) / float(v)})

    r = m.simulate_to_threshold(loading, dt=dt_s, integration_method="rk4", save_freq=SAVE_S,
                                horizon=HORIZON_S)
    times = np.asarray(r.times, dtype=float)
    volts = np.array([float(z["v"]) for z in r.outputs])
    return Run(times, volts, float(times[-1]))


def lunaris_run(profile: Profile, rover: Rover | None = None) -> Run:
    """Step the pack at the rover's tick until its cut-off; the terminal voltage every
    :data:`SAVE_S`. A current profile is met by demanding ``P = V_x i`` (no series
    resistance in this cell, so the pack's solution is ``I = P / V_x = i``)."""
    rover = rover or reference_cell()
    pack = BatteryModel(rover.battery)
    dt = 1.0 / rover.tick_hz
    every = max(1, round(SAVE_S / dt))
    times, volts = [0.0], [pack.reading().voltage_v]
    n = 0
    while n * dt < HORIZON_S:
        t = n * dt
        value = profile.value(t + dt / 2)
        if profile.kind == "current":
            pack.set_demand((pack.ocv_v - sum(pack.branch_v)) * value)
        else:
            pack.set_demand(value)
        pack.step(dt)
        n += 1
        if n % every == 0 or pack.uv_cutoff:
            times.append(n * dt)
            volts.append(pack.operating_point().voltage_v if not pack.uv_cutoff else math.nan)
        if pack.uv_cutoff:
            break
    return Run(np.array(times), np.array(volts), n * dt)


class Comparison(NamedTuple):
    profile: str
    eod_progpy_s: float
    eod_lunaris_s: float
    rmse_v: float
    max_abs_v: float

    @property
    def eod_error(self) -> float:
        return self.eod_lunaris_s / self.eod_progpy_s - 1.0


def compare(profile: Profile, rover: Rover | None = None) -> Comparison:
    ref, twin = progpy_run(profile), lunaris_run(profile, rover)
    end = min(ref.eod_s, twin.eod_s) - SAVE_S
    t = ref.times_s[ref.times_s <= end]
    ok = ~np.isnan(twin.voltage_v)
    diff = np.interp(t, twin.times_s[ok], twin.voltage_v[ok]) - ref.voltage_v[: len(t)]
    return Comparison(profile.name, ref.eod_s, twin.eod_s, float(np.sqrt(np.mean(diff**2))),
                      float(np.max(np.abs(diff))))


def progpy_state(m, charge_soc: float):
    """BatteryCircuit's state at a state of charge (by charge, its own), branches relaxed."""
    p = m.parameters
    return m.StateContainer({"tb": p["Ta"], "qb": p["qMax"] - p["CMax"] * (1.0 - charge_soc),
                             "qcp": 0.0, "qcs": 0.0})


def energy_soc(charge_soc: float) -> float:
    """Lunaris's state of charge (by energy) of BatteryCircuit's (by charge): the integral of
    the equilibrium voltage over charge from empty, over the whole of it."""
    m = progpy_model()
    p = m.parameters
    q = np.linspace(p["qMax"] - p["CMax"], p["qMax"], 100_001)
    x = m.StateContainer({"tb": np.full_like(q, p["Ta"]), "qb": q, "qcp": np.zeros_like(q),
                          "qcs": np.zeros_like(q)})
    vb = np.asarray(m.output(x)["v"], dtype=float).ravel()
    energy = np.concatenate([[0.0], np.cumsum(0.5 * (vb[1:] + vb[:-1]) * np.diff(q))])
    return float(np.interp(p["qMax"] - p["CMax"] * (1.0 - charge_soc), q, energy) / energy[-1])


def progpy_monte_carlo(samples: int, charge_soc: float, power_w: float, std_w: float, max_w: float,
                       dt_s: float, seed: int) -> np.ndarray:
    """ProgPy's MonteCarlo predictor on BatteryCircuit: the ends of discharge [s] of
    ``samples`` futures from ``charge_soc``, each drawing ``clip(N(power_w, std_w), 0, max_w)``
    afresh every step of ``dt_s`` (RK4) and meeting it with ``i = P / v``."""
    from progpy.predictors import MonteCarlo
    from progpy.uncertain_data import ScalarData

    m = progpy_model()
    rng = np.random.default_rng(seed)

    def loading(t: float, x=None):
        p = float(np.clip(rng.normal(power_w, std_w), 0.0, max_w))
        v = float(m.output(x)["v"]) if x is not None else m.parameters["V0"]
        return m.InputContainer({"i": p / v})

    result = MonteCarlo(m).predict(ScalarData(progpy_state(m, charge_soc)), loading,
                                   n_samples=samples, dt=dt_s, integration_method="rk4",
                                   horizon=HORIZON_S, save_freq=HORIZON_S, events=["EOD"])
    return np.array([float(s["EOD"]) if s["EOD"] is not None else np.inf
                     for s in result.time_of_event])
