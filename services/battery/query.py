"""The ``prediction`` queryable (SPEC §5): the Monte Carlo of a rover's futures from its live state.

``get lunaris/<rover>/prediction?hours=8;samples=1000`` is answered by the battery service.
Why there: the futures are the pack's. Its charge, its branch voltages, its temperature, its
latches and the parameters of its injected faults exist only in this service, and the net
demand on it arrives here every tick; no other service could start a future from them. What
the pack does not hold is read when a query comes, so that the service pays nothing for it
in between (a fleet of 100 rovers is served by one battery process):

- the rails' switches: the power service's cached ``rail/<rail>/state`` samples (an advanced
  subscriber's history; a rail ``off`` with the reason ``commanded off`` stays off, one off
  because the pack is not operational comes back with it);
- the loads held by a fault: the loads service's ``faults/active/loads`` (short, open, stuck);
- the generation: the last ``power/summary`` this service received;
- the loads' noise and the uncertainty: the rover file.

What cannot be read is assumed from the rover file and said in the answer's ``notes``.
The pack is copied on the worker thread when the query arrives (a consistent state), and
the futures run on a thread of their own, one query at a time, so the pack keeps stepping
with the clock while they do. Bad parameters are refused with an error reply that names
the problem.
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from collections.abc import Callable

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.config import Rover
from common.faults import injected
from common.messages import (
    ActiveFaults,
    BadInput,
    LoadPower,
    Percentiles,
    Prediction,
    PredictionRequest,
    RailState,
    decode,
    decode_parameters,
    encode,
)
from services.battery.model import BatteryModel
from services.battery.prediction import RailStart, Start, percentiles, predict
from services.loads.model import LoadsModel
from services.power.model import COMMANDED_OFF

__all__ = ["PredictionQueries", "rail_start"]

GATHER_S = 2.0  # how long to wait for the rails' and loads' answers


def rail_start(state: RailState, soc: float, shed_below: float | None) -> RailStart:
    """A rail's switches from what the power service publishes of it."""
    if state.state == "off":
        if state.reason == COMMANDED_OFF:
            return RailStart(commanded_on=False)
        # off because the pack is not operational: as it comes back, shed or not by its charge
        return RailStart(shed=shed_below is not None and soc < shed_below)
    return RailStart(tripped=state.state == "tripped", failed=state.state == "failed",
                     shed=state.state == "shed")


class PredictionQueries:
    """Answers ``prediction`` queries for the rovers of one battery service."""

    def __init__(self, session: zenoh.Session, rovers: dict[str, Rover],
                 snapshot: Callable[[str], tuple[BatteryModel, float, float | None]]):
        """``snapshot(rover)`` (called on the worker thread) returns a copy of the pack, the
        sim time it has reached and the last generation it was told of (None: not yet)."""
        self.session = session
        self.rovers = rovers
        self.snapshot = snapshot
        self.pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="prediction")

    def close(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)

    def on_query(self, q: zenoh.Query) -> None:
        """On the worker thread: parse, copy the pack, and hand the rest to the pool."""
        targets = [r for r in sorted(self.rovers) if zenoh.KeyExpr(keys.prediction(r)).intersects(
            q.key_expr)]
        if not targets:  # another battery process serves the rover asked about
            q.drop()
            return
        try:
            request = decode_parameters(str(q.parameters), PredictionRequest)
        except BadInput as exc:
            with q:
                q.reply_err(f"bad prediction query: {exc} (parameters: hours in (0, 168], "
                            f"samples in [1, 10000], seed >= 0)")
            return
        starts = [(rover, *self.snapshot(rover)) for rover in targets]
        self.pool.submit(self._answer, q, request, starts)

    def _answer(self, q: zenoh.Query, request: PredictionRequest,
                starts: list[tuple[str, BatteryModel, float, float | None]]) -> None:
        with q:
            for rover, pack, t_s, generation_w in starts:
                try:
                    msg = self.predict(rover, pack, t_s, generation_w, request)
                except Exception as exc:  # a bug must not leave the querier waiting
                    q.reply_err(f"prediction of {rover} failed: {type(exc).__name__}: {exc}")
                    continue
                q.reply(keys.prediction(rover), encode(msg), encoding=zenoh.Encoding.APPLICATION_JSON)

    def predict(self, rover: str, pack: BatteryModel, t_s: float, generation_w: float | None,
                request: PredictionRequest) -> Prediction:
        cfg = self.rovers[rover]
        notes: list[str] = []
        rails = self._rails(cfg, pack.soc, notes)
        fixed = self._fixed_loads(cfg, notes)
        if cfg.drive is not None and cfg.drive.load not in fixed:
            driven = self._last_load_power(cfg, cfg.drive.load)
            if driven is None:
                notes.append(f"no power from the drive's load {cfg.drive.load} yet: its idle power assumed")
                driven = cfg.drive.idle_w
            fixed[cfg.drive.load] = driven  # the drive's present power, held like every input
        if generation_w is None:
            notes.append("no power/summary received yet: no generation assumed")
        start = Start(cfg, pack, rails, fixed, generation_w or 0.0, t_s)
        t0 = time.perf_counter()
        out = predict(start, request.hours * 3600.0, request.samples, seed=request.seed)
        took = time.perf_counter() - t0
        return Prediction(
            t_s=t_s, horizon_s=out.horizon_s, samples=out.samples,
            time_to_empty_s=msgspec.convert(percentiles(out.time_to_empty_s), Percentiles),
            soc_at_horizon=msgspec.convert(percentiles(out.soc_at_horizon), Percentiles),
            computed_in_s=took, step_s=out.step_s, notes=notes)

    def _rails(self, cfg: Rover, soc: float, notes: list[str]) -> dict[str, RailStart]:
        wanted = {r.name for r in cfg.rails}
        got: dict[str, RailState] = {}
        lock, done = threading.Lock(), threading.Event()

        def on_sample(s: zenoh.Sample) -> None:
            name = str(s.key_expr).split("/")[-2]
            if name in wanted:
                with lock:
                    got[name] = decode(s.payload.to_bytes(), RailState)
                    if len(got) == len(wanted):
                        done.set()

        if wanted:
            sub = zext.declare_advanced_subscriber(self.session, keys.rail_state(cfg.id, "*"),
                                                   on_sample, history=zext.HistoryConfig())
            done.wait(GATHER_S)
            sub.undeclare()
        with lock:
            heard = dict(got)
        missing = sorted(wanted - set(heard))
        if missing:
            notes.append(f"no state from the power service for rails {', '.join(missing)}: as "
                         "the rover file starts them")
        below = {r.name: r.shed_below_soc for r in cfg.rails}
        return {r.name: rail_start(heard[r.name], soc, below[r.name]) if r.name in heard
                else RailStart(commanded_on=r.initially_on) for r in cfg.rails}

    def _last_load_power(self, cfg: Rover, load: str) -> float | None:
        """The last power a load published [W] (from its publisher's cache), None if none."""
        got: list[float] = []
        done = threading.Event()

        def on_sample(s: zenoh.Sample) -> None:
            got.append(decode(s.payload.to_bytes(), LoadPower).power_w)
            done.set()

        sub = zext.declare_advanced_subscriber(self.session, keys.load_power(cfg.id, load),
                                               on_sample, history=zext.HistoryConfig())
        done.wait(GATHER_S)
        sub.undeclare()
        return got[-1] if got else None

    def _fixed_loads(self, cfg: Rover, notes: list[str]) -> dict[str, float]:
        if not cfg.loads:
            return {}
        loads = LoadsModel(cfg)
        answered = False
        for reply in self.session.get(keys.faults_active(cfg.id, "loads"), timeout=GATHER_S):
            if reply.ok is None:
                continue
            answered = True
            record = decode(reply.ok.payload.to_bytes(), ActiveFaults).faults
            for name in loads.names:
                loads.set_faults(name, injected(record, "load", name))
        if not answered:
            notes.append("the loads service did not answer: no load fault assumed")
        return {name: p for name in loads.names if (p := loads.fault_power(name)) is not None}
