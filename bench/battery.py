"""The battery against NASA ProgPy, the composed twin's speed, and the prediction, in one run.

1. ProgPy comparison (SPEC §10: end of discharge within 0.5 %, terminal voltage RMSE under
   5 mV): ``config/rovers/bc18650.yaml`` stepped by Lunaris at 10 Hz and BatteryCircuit by
   ProgPy (RK4, 0.5 s) on ProgPy's example current profile and at 8 W and 15 W; and the
   first release's model of the same cell (one resistance, the sum of BatteryCircuit's at
   full charge, no branches; the same cut-off) for contrast, in the column "one R".
2. The whole MAPP rover in one process (ComposedTwin) at 10 Hz, 8 simulated hours, best of 3
   (SPEC §10: at least 10,000x real time).
3. The prediction: 1,000 futures x 8 h of MAPP (SPEC §10: under 10 s); then Lunaris's
   prediction and ProgPy's MonteCarlo on the reference cell with the same sample count, the
   same 1 s step and the same load noise (8 W, std 3 W, drawn every step), horizon 3,600 s
   (the cell empties at about 3,360 s). ProgPy integrates with its default method (Euler).

Run: ``.venv/bin/python bench/battery.py [--progpy-samples N]`` (default 1000, about 4 min
of ProgPy; fewer for a quick look).
"""

from __future__ import annotations

import argparse
import time

import msgspec
import numpy as np
from benchlib import ROOT, machine

from common.config import Rover, load_rover
from services.battery.prediction import percentiles, predict, start_of
from services.composed import ComposedTwin, run_budget
from testbed import progpy_cell as pc


def progpy_comparison() -> None:
    print("1. the reference cell against ProgPy's BatteryCircuit (targets: end of discharge "
          "within 0.5 %, RMSE under 5 mV)")
    raw = msgspec.to_builtins(pc.reference_cell())
    raw["battery"].update(internal_resistance_ohm=0.0538926 + 0.0697776, rc_pairs=[])
    first_release = msgspec.convert(raw, Rover)
    print(f"   {'profile':<33}{'ProgPy EOD':>11}{'Lunaris EOD':>12}{'error':>9}{'RMSE':>9}"
          f"{'max':>9}{'one R':>13}")
    for profile in pc.PROFILES:
        c = pc.compare(profile)
        old = pc.compare(profile, first_release)
        print(f"   {profile.name:<33}{c.eod_progpy_s:>10.1f}s{c.eod_lunaris_s:>11.1f}s"
              f"{c.eod_error * 100:>+8.3f}%{c.rmse_v * 1e3:>6.2f} mV{c.max_abs_v * 1e3:>6.1f} mV"
              f"{old.eod_error * 100:>+10.2f} % ({old.rmse_v * 1e3:.0f} mV)")


def composed_speed(hours: float = 8.0) -> None:
    rover = load_rover(ROOT / "config/rovers/mapp.yaml")
    walls = []
    for _ in range(3):
        t0 = time.perf_counter()
        budget = run_budget(rover, hours, seed=0)
        walls.append(time.perf_counter() - t0)
    best = min(walls)
    print(f"2. the whole MAPP rover in one process at {rover.tick_hz:g} Hz (target: at least "
          "10,000x real time)")
    print(f"   {budget.ticks} ticks ({hours:g} h): best {best:.2f} s, worst {max(walls):.2f} s of 3 "
          f"= {budget.simulated_s / best:,.0f}x real time ({best / budget.ticks * 1e6:.1f} us/tick)")


def prediction_speed(progpy_samples: int) -> None:
    rover = load_rover(ROOT / "config/rovers/mapp.yaml")
    print("3. the prediction (target: 1,000 futures x 8 h of MAPP under 10 s)")
    t0 = time.perf_counter()
    out = predict(start_of(ComposedTwin(rover)), 8 * 3600.0, 1000, seed=1)
    wall = time.perf_counter() - t0
    tte = percentiles(out.time_to_empty_s)
    print(f"   MAPP, 1000 futures x 8 h (step {out.step_s:g} s): {wall:.2f} s; time to empty "
          f"p05/p50/p95 = " + "/".join(f"{v / 3600:.2f} h" if v is not None else "-"
                                       for v in tte.values()))
    # the same cell, sample count, step, noise and horizon for both predictors
    raw = msgspec.to_builtins(pc.reference_cell())
    raw["battery"]["uncertainty"] = {}
    raw["tick_hz"] = 1.0
    raw["loads"][0].update(nominal_w=8.0, std_w=3.0, max_w=20.0)
    cell = msgspec.convert(raw, Rover)
    n, horizon = progpy_samples, 3600.0
    t0 = time.perf_counter()
    ours = predict(start_of(ComposedTwin(cell)), horizon, n, seed=1, step_ticks=1)
    ours_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    theirs = _progpy_euler(n, horizon)
    theirs_s = time.perf_counter() - t0
    print(f"   reference cell, {n} futures, horizon {horizon:g} s, 1 s step, 8 W with std 3 W "
          f"each step:")
    print(f"     Lunaris prediction  {ours_s:7.2f} s   median end of discharge "
          f"{np.median(ours.time_to_empty_s):.0f} s, std {np.std(ours.time_to_empty_s):.1f} s")
    print(f"     ProgPy MonteCarlo   {theirs_s:7.2f} s   median end of discharge "
          f"{np.median(theirs):.0f} s, std {np.std(theirs):.1f} s   ({theirs_s / ours_s:,.0f}x "
          "the time)")


def _progpy_euler(samples: int, horizon: float) -> np.ndarray:
    from progpy.predictors import MonteCarlo
    from progpy.uncertain_data import ScalarData

    m = pc.progpy_model()
    rng = np.random.default_rng(2)

    def loading(t: float, x=None):
        p = float(np.clip(rng.normal(8.0, 3.0), 0.0, 20.0))
        v = float(m.output(x)["v"]) if x is not None else m.parameters["V0"]
        return m.InputContainer({"i": p / v})

    result = MonteCarlo(m).predict(ScalarData(pc.progpy_state(m, 1.0)), loading, n_samples=samples,
                                   dt=1.0, horizon=horizon, save_freq=horizon, events=["EOD"])
    return np.array([float(s["EOD"]) if s["EOD"] is not None else np.inf
                     for s in result.time_of_event])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--progpy-samples", type=int, default=1000,
                        help="futures for the two predictors on the reference cell (default 1000)")
    args = parser.parse_args()
    print(f"battery: reference, speed and prediction ({machine()})")
    progpy_comparison()
    composed_speed()
    prediction_speed(args.progpy_samples)


if __name__ == "__main__":
    main()
