"""``lunaris predict``: Monte Carlo time to empty and state of charge (SPEC §4, §8).

    lunaris predict FILE [--hours H] [--samples N] [--seed S] [--json] [--traverse T.yaml [--return]]
    lunaris predict --rover ID [--hours H] [--samples N] [--seed S] [--json] [--timeout S]

With a rover FILE the futures start from the file's initial state and run in this process
(no Zenoh), with progress on stderr; with ``--traverse`` the rover drives that traverse file
from its start (``--return``: and back), its drive load following the traverse tick by tick
and then parked, so a vehicle engineer asks "can this rover do this traverse and come back
with 20 % left?" with the spread of the answer. With ``--rover`` the live twin answers: the tool sends
``get lunaris/<rover>/prediction?hours=H;samples=N`` and prints the answer. Percentiles 5,
50 and 95 of the time to empty (depleted or cut off) and of the state of charge at the
horizon; "not within" where that share of the futures does not empty within the horizon.

Exit status: 0 answered; 1 refused (bad parameters); 2 no answer, unknown rover or bad file.
"""

from __future__ import annotations

import argparse
import sys
import time

import msgspec

from common import keys
from common.connection import add_connection_args
from common.messages import BadInput, Percentiles, Prediction, PredictionRequest, decode, encode
from lunaris.client import ToolError, open_session, require_rover

__all__ = ["add_arguments", "format_prediction", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", nargs="?", metavar="FILE", help="rover definition: predict from its "
                   "initial state, in this process")
    p.add_argument("--rover", metavar="ID", help="predict from the live twin's state instead")
    p.add_argument("--traverse", metavar="TRAVERSE.yaml",
                   help="with FILE: the rover drives this traverse file from its start")
    p.add_argument("--return", dest="back", action="store_true",
                   help="with --traverse: and back through its waypoints to the start")
    p.add_argument("--hours", type=float, default=8.0, help="horizon (default 8)")
    p.add_argument("--samples", type=int, default=1000, help="futures (default 1000)")
    p.add_argument("--seed", type=int, default=None, help="random seed, for a repeatable answer")
    p.add_argument("--json", action="store_true", help="print the Prediction payload as JSON")
    p.add_argument("--timeout", type=float, default=120.0, metavar="S",
                   help="how long to wait for the live twin's answer (default 120 s)")
    p.add_argument("--wait", type=float, default=10.0, metavar="S",
                   help="how long to wait for the router (default 10 s)")
    add_connection_args(p)


def main(args: argparse.Namespace) -> int:
    try:
        if (args.file is None) == (args.rover is None):
            raise ToolError("give a rover FILE or --rover ID (one of them)")
        try:
            request = msgspec.convert({"hours": args.hours, "samples": args.samples,
                                       "seed": args.seed}, PredictionRequest)
        except msgspec.ValidationError as exc:
            raise ToolError(f"bad arguments: {_option_names(str(exc))}", 1) from None
        if (args.traverse or args.back) and args.file is None:
            raise ToolError("--traverse and --return go with a rover FILE")
        if args.back and not args.traverse:
            raise ToolError("--return needs --traverse")
        msg, origin = (_from_file(args.file, request, args.traverse, args.back)
                       if args.file is not None else _from_twin(args, request))
    except ToolError as exc:
        print(f"lunaris predict: {exc}", file=sys.stderr)
        return exc.code
    print(encode(msg).decode() if args.json else format_prediction(msg, origin))
    return 0


def _option_names(text: str) -> str:
    return text.replace("`$.hours`", "--hours").replace("`$.samples`", "--samples").replace(
        "`$.seed`", "--seed")


def _from_file(path: str, request: PredictionRequest, traverse: str | None = None,
               back: bool = False) -> tuple[Prediction, str]:
    from common.config import ConfigError, load_rover
    from common.traverse import load_traverse
    from services.battery.prediction import assumptions, percentiles, predict, start_of
    from services.composed import ComposedTwin
    from services.composed.budget import power_profile

    try:
        rover = load_rover(path)
    except ConfigError as exc:
        raise ToolError(str(exc)) from None
    start = start_of(ComposedTwin(rover, seed=request.seed))
    notes: list[str] = []
    if traverse is not None:
        if rover.drive is None:
            raise ToolError(f"rover {rover.id} has no drive section: it cannot follow a traverse")
        try:
            cmd = load_traverse(traverse, rover).command()
        except ConfigError as exc:
            raise ToolError(str(exc)) from None
        if back:
            cmd.return_to_start = True
        try:
            ticks = power_profile(rover, cmd)
        except ValueError as exc:
            raise ToolError(f"{traverse}: {exc}") from None
        idle = rover.drive.idle_w
        start = start._replace(profile=(rover.drive.load, (*ticks, idle)))
        notes.append(f"the traverse {traverse}{' and back' if back else ''} takes "
                     f"{_hms(len(ticks) / rover.tick_hz)}; then parked")
    print(f"{rover.id}: {request.samples} futures over {_hms(request.hours * 3600.0)} from the "
          "rover file's initial state", file=sys.stderr, flush=True)
    t0 = time.perf_counter()

    def progress(done: int, total: int) -> None:
        elapsed = time.perf_counter() - t0
        if elapsed < 1.0 and done < total:
            return  # a short run needs no progress
        left = elapsed * (total - done) / done
        print(f"  {100 * done // total:3d} %  {elapsed:5.1f} s, about {left:.0f} s left",
              file=sys.stderr, flush=True)

    out = predict(start, request.hours * 3600.0, request.samples, seed=request.seed,
                  progress=progress)
    took = time.perf_counter() - t0
    return Prediction(
        t_s=out.t_s, horizon_s=out.horizon_s, samples=out.samples,
        time_to_empty_s=msgspec.convert(percentiles(out.time_to_empty_s), Percentiles),
        soc_at_horizon=msgspec.convert(percentiles(out.soc_at_horizon), Percentiles),
        computed_in_s=took, step_s=out.step_s, notes=notes + assumptions(rover)), f"{rover.id}, from {path}"


def _from_twin(args: argparse.Namespace, request: PredictionRequest) -> tuple[Prediction, str]:
    selector = f"{keys.prediction(args.rover)}?hours={request.hours:g};samples={request.samples}"
    if request.seed is not None:
        selector += f";seed={request.seed}"
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    try:
        require_rover(session, args.rover)
        print(f"asking {args.rover} (get {selector}) ...", file=sys.stderr, flush=True)
        for reply in session.get(selector, timeout=args.timeout):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), Prediction), f"{args.rover}, live"
            why = reply.err.payload.to_string() if reply.err is not None else "no reason given"
            raise ToolError(f"{args.rover} refused: {why}", 1)
    except BadInput as exc:
        raise ToolError(f"unreadable answer: {exc}") from None
    finally:
        session.close()
    raise ToolError(f"no answer from {args.rover} within {args.timeout:g} s: is its battery "
                    "service running?")


def format_prediction(p: Prediction, origin: str) -> str:
    horizon = _hms(p.horizon_s)
    t = p.time_to_empty_s
    soc = p.soc_at_horizon

    def when(v: float | None) -> str:
        return f"{_hms(v):>12}" if v is not None else f"{'not within':>12}"

    def frac(v: float | None) -> str:
        return f"{v:12.4f}" if v is not None else f"{'-':>12}"

    lines = [f"{origin}: {p.samples} futures over {horizon} from t = {_hms(p.t_s)} "
             f"(step {p.step_s:g} s, computed in {p.computed_in_s:.2f} s)",
             f"  {'':22}{'p05':>12}{'p50':>12}{'p95':>12}",
             f"  {'time to empty':22}{when(t.p05)}{when(t.p50)}{when(t.p95)}",
             f"  {'soc at ' + horizon:22}{frac(soc.p05)}{frac(soc.p50)}{frac(soc.p95)}"]
    lines += [f"  note: {n}" for n in p.notes]
    return "\n".join(lines)


def _hms(t_s: float) -> str:
    h, rem = divmod(int(round(t_s)), 3600)
    return f"{h:d}:{rem // 60:02d}:{rem % 60:02d}"
