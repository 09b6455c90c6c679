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

The work is bounded (a query of 168 h x 10,000 futures took 25.7 s, and six of them queued
kept the battery process at 75-87 % of a core for minutes after their askers had gone):

- a query may ask for at most ``MAX_WORK`` sample-steps (futures x integration steps:
  1,000 futures over 8 h are ~10 million); more is refused at once, saying what would fit;
- at most ``MAX_QUEUED`` queries whose askers still wait are computed or waiting at once;
  another is refused ("busy"), in words;
- a query is computed only while its asker waits (``timeout_s``, default 60 s): one whose
  asker has gone is dropped before it starts, or stopped where it is.
"""

from __future__ import annotations

import concurrent.futures
import math
import sys
import threading
import time
from collections.abc import Callable

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.config import Rover
from common.faults import held_power_w, injected
from common.messages import (
    COMMANDED_OFF,
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
from services.battery.prediction import MAX_STEPS, RailStart, Start, assumptions, percentiles, predict

__all__ = ["MAX_QUEUED", "MAX_WORK", "PredictionQueries", "rail_start", "steps_of"]

GATHER_S = 2.0  # how long to wait for the rails' and loads' answers
MAX_WORK = 20_000_000  # sample-steps one query may ask for (1,000 x 8 h: ~10 million)
MAX_QUEUED = 3  # queries computed or waiting at once


class _Abandoned(Exception):
    """The asker has stopped waiting: the futures are not worth finishing."""


def steps_of(rover: Rover, hours: float) -> int:
    """The integration steps :func:`~services.battery.prediction.predict` takes over ``hours``."""
    tick_s = 1.0 / rover.tick_hz
    k = max(1, math.ceil(hours * 3600.0 / tick_s / MAX_STEPS))
    return max(1, round(hours * 3600.0 / (k * tick_s)))


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
        self._lock = threading.Lock()
        self._queued: list[float] = []  # the deadline of each query computed or waiting

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
                            f"samples in [1, 10000], seed >= 0, timeout_s in (0, 600])")
            return
        too_much = self._too_much(targets, request)
        if too_much is not None:
            with q:
                q.reply_err(too_much)
            return
        deadline = time.monotonic() + request.timeout_s
        with self._lock:  # those whose asker has gone are about to stop: they do not count
            busy = sum(1 for d in self._queued if d > time.monotonic()) >= MAX_QUEUED
            if not busy:
                self._queued.append(deadline)
        if busy:
            with q:
                q.reply_err(f"the battery service of {', '.join(targets)} is busy: {MAX_QUEUED} "
                            "predictions are being computed or waiting, the most it takes; ask "
                            "again when one has been answered")
            return
        starts = [(rover, *self.snapshot(rover)) for rover in targets]
        self.pool.submit(self._answer, q, request, starts, deadline)

    def _too_much(self, targets: list[str], request: PredictionRequest) -> str | None:
        """Why a query asks for more work than one may, in words; None if it does not."""
        steps = {r: steps_of(self.rovers[r], request.hours) for r in targets}
        work = sum(n * request.samples for n in steps.values())
        if work <= MAX_WORK:
            return None
        most = max(1, MAX_WORK // sum(steps.values()))
        rovers = f" for {len(targets)} rovers" if len(targets) > 1 else ""
        return (f"too much for one prediction: {request.samples:,} futures over {request.hours:g} h"
                f"{rovers} are {work:,} steps to compute, more than the {MAX_WORK:,} one query may "
                f"ask for; ask for at most {most:,} futures over {request.hours:g} h, or a shorter "
                "horizon with fewer futures")

    def _answer(self, q: zenoh.Query, request: PredictionRequest,
                starts: list[tuple[str, BatteryModel, float, float | None]], deadline: float) -> None:
        try:
            with q:
                for rover, pack, t_s, generation_w in starts:
                    if time.monotonic() >= deadline:
                        raise _Abandoned
                    try:
                        msg = self.predict(rover, pack, t_s, generation_w, request, deadline)
                    except _Abandoned:
                        raise
                    except Exception as exc:  # a bug must not leave the querier waiting
                        q.reply_err(f"prediction of {rover} failed: {type(exc).__name__}: {exc}")
                        continue
                    q.reply(keys.prediction(rover), encode(msg),
                            encoding=zenoh.Encoding.APPLICATION_JSON)
        except _Abandoned:
            print(f"battery: a prediction ({request.samples} futures over {request.hours:g} h) "
                  f"stopped: its asker stopped waiting after {request.timeout_s:g} s",
                  file=sys.stderr, flush=True)
        finally:
            with self._lock:
                self._queued.remove(deadline)

    def predict(self, rover: str, pack: BatteryModel, t_s: float, generation_w: float | None,
                request: PredictionRequest, deadline: float = math.inf) -> Prediction:
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
            if driven > cfg.drive.idle_w:
                notes.append(f"the drive draws {driven:.1f} W now, held over the whole horizon: a traverse "
                             "under way is taken as going on (lunaris predict --traverse plans one's end)")
        if generation_w is None:
            notes.append("no power/summary received yet: no generation assumed")
        start = Start(cfg, pack, rails, fixed, generation_w or 0.0, t_s)
        t0 = time.perf_counter()
        def in_time(done: int, total: int) -> None:
            if time.monotonic() >= deadline:
                raise _Abandoned

        out = predict(start, request.hours * 3600.0, request.samples, seed=request.seed,
                      progress=in_time)
        took = time.perf_counter() - t0
        return Prediction(
            t_s=t_s, horizon_s=out.horizon_s, samples=out.samples,
            time_to_empty_s=msgspec.convert(percentiles(out.time_to_empty_s), Percentiles),
            soc_at_horizon=msgspec.convert(percentiles(out.soc_at_horizon), Percentiles),
            computed_in_s=took, step_s=out.step_s, notes=notes + assumptions(cfg))

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
        volts = {r.name: r.voltage_v for r in cfg.rails}
        held: dict[str, float] = {}
        answered = False
        for reply in self.session.get(keys.faults_active(cfg.id, "loads"), timeout=GATHER_S):
            if reply.ok is None:
                continue
            answered = True
            record = decode(reply.ok.payload.to_bytes(), ActiveFaults).faults
            for load in cfg.loads:
                p = held_power_w(injected(record, "load", load.name), volts[load.rail])
                if p is not None:
                    held[load.name] = p
        if not answered:
            notes.append("the loads service did not answer: no load fault assumed")
        return held
