"""``lunaris scenario run|check FILE``: play or validate a scripted training scenario.

The format is :mod:`common.scenario` and the player's logic :mod:`common.scenario_player`; this is
the Zenoh shell around them. ``run`` follows the rover's clock (scenario times
are simulated time, so a scenario can play with the clock sped up), keeps the
latest telemetry for the conditions, makes each step's writes, and reports each
step as it fires and the twin's answer to it (``fault_injected``, ``rejected``
...). At the end it prints a summary, puts the clock back to the speed it had,
and exits 0 when every step fired and was accepted, 1 otherwise, 2 when it
could not start.

A scenario may start from a reset or a snapshot (``start``): the run asks for it and waits
for the clock's first tick of the new epoch before it plays. It marks its start, each step
and its end in the journal (``control/scenario``), and while it plays it is never silent
for 10 s of wall time: it says what it waits for. Longer than 450 lines: one run's state
(the telemetry, the answers awaited, the clock to put back) is one class, kept whole.
"""

from __future__ import annotations

import argparse
import json
import queue
import signal
import sys
import threading
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.config import ConfigError, Rover, load_rover
from common.connection import add_connection_args, write
from common.messages import Event, decode
from common.scenario import Scenario, ScenarioError, describe_start, load_scenario, rover_id_of
from common.scenario_player import Player, Write, describe_action, describe_trigger
from lunaris.client import ToolError, describe_endpoint, ignored, open_session, require_rover

__all__ = ["add_arguments", "find_rover", "main"]

REPO_ROVERS = Path(__file__).resolve().parent.parent / "config" / "rovers"


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    rover_help = "rover definition to check names against (default: the config/rovers file of its id)"

    run = sub.add_parser("run", help="play a scenario against the running twin")
    run.add_argument("file", metavar="FILE")
    run.add_argument("--rover-file", metavar="FILE", help=rover_help)
    run.add_argument("--time-scale", type=float, metavar="X",
                     help="clock speed while the scenario plays (overrides the scenario's time_scale)")
    run.add_argument("--timeout", type=float, default=3.0, metavar="S",
                     help="how long to wait for the twin's answer to each write (default 3 s)")
    run.add_argument("--wait", type=float, default=10.0, metavar="S",
                     help="how long to wait for the router and the rover's clock (default 10 s)")
    run.add_argument("--clear-at-end", action="store_true",
                     help="clear the faults this scenario injected that are still active at the end")
    run.add_argument("--json-summary", metavar="FILE", help="also write the summary as JSON")
    run.add_argument("--status-json", metavar="FILE",
                     help="keep the steps' progress in this JSON file while it plays (the console)")
    add_connection_args(run)

    check = sub.add_parser("check", help="validate scenarios and print every problem")
    check.add_argument("files", nargs="+", metavar="FILE")
    check.add_argument("--rover-file", metavar="FILE", help=rover_help)


def find_rover(rover_id: str | None, explicit: str | None) -> tuple[Rover | None, str]:
    """The rover definition to check names against, and a note saying where it came from."""
    if explicit:
        try:
            return load_rover(explicit), f"names checked against {explicit}"
        except ConfigError as exc:
            raise ToolError(str(exc)) from None
    folders = [Path("config/rovers"), REPO_ROVERS]
    for folder in dict.fromkeys(f.resolve() for f in folders if f.is_dir()):
        for path in sorted(folder.glob("*.yaml")):
            try:
                rover = load_rover(path)
            except ConfigError:
                continue
            if rover.id == rover_id:
                return rover, f"names checked against {path}"
    return None, f"names not checked: no rover definition with id {rover_id!r} found (give --rover-file)"


def _load(path: str, rover_file: str | None) -> tuple[Scenario, str]:
    """Load and validate; names are checked against the rover's definition when one is found."""
    try:
        rover_id = rover_id_of(Path(path).read_text())
    except OSError:
        rover_id = None  # load_scenario says what is wrong with the file
    rover, note = find_rover(rover_id, rover_file) if rover_id or rover_file else (None, "")
    try:
        return load_scenario(path, rover), note
    except ScenarioError as exc:
        raise ToolError(str(exc), 1) from None


def main(args: argparse.Namespace) -> int:
    try:
        if args.action == "check":
            return _check_files(args.files, args.rover_file)
        return _Run(args).run()
    except ToolError as exc:
        print(f"lunaris scenario: {exc}", file=sys.stderr)
        return exc.code if args.action == "run" else 1


def _check_files(files: Iterable[str], rover_file: str | None) -> int:
    status = 0
    for path in files:
        try:
            sc, note = _load(path, rover_file)
        except ToolError as exc:
            print(exc, file=sys.stderr)
            status = 1
            continue
        span = f", runs {sc.duration_s:g} s" if sc.duration_s else ""
        scale = f", clock x{sc.time_scale:g}" if sc.time_scale else ""
        print(f"{path}: ok - {sc.scenario.name!r} for {sc.rover}: {len(sc.steps)} steps{span}{scale} "
              f"({note})")
    return status


# -- playing --------------------------------------------------------------------------------


@dataclass
class _Pending:
    write: Write
    deadline: float  # wall time


class _Run:
    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.scenario, self.note = _load(args.file, args.rover_file)
        self.rover = self.scenario.rover
        self.player = Player(self.scenario)
        self.latest: dict[tuple[str, ...], dict] = {}
        self.lock = threading.Lock()
        self.ticks: queue.SimpleQueue[dict] = queue.SimpleQueue()
        self.events: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self.pending: list[_Pending] = []
        self.injected: dict[str, int] = {}  # fault key -> step, of the faults still active
        self.stop = threading.Event()
        self.started_wall = time.monotonic()
        self.first_clock: dict | None = None
        self.last_said = time.monotonic()
        self.clock_changed = False

    # Zenoh callbacks -------------------------------------------------------------------

    def _on_sample(self, s: zenoh.Sample) -> None:
        try:
            rover, parts = keys.split(str(s.key_expr))
        except ValueError:
            return
        fam = keys.telemetry_family(parts)
        family = fam.name if fam is not None else None
        if family is None or family == "event" or rover != self.rover:
            return
        try:
            value = msgspec.json.decode(s.payload.to_bytes())
        except msgspec.DecodeError as exc:
            ignored(str(s.key_expr), f"not JSON ({exc})")
            return
        with self.lock:
            self.latest[tuple(parts)] = value
        if family == "clock":
            self.ticks.put(value)

    def _on_event(self, s: zenoh.Sample) -> None:
        try:
            self.events.put(decode(s.payload.to_bytes(), Event))
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            ignored(str(s.key_expr), f"not an event ({exc})")

    def lookup(self, parts: tuple[str, ...]) -> dict | None:
        with self.lock:
            return self.latest.get(parts)

    # output ----------------------------------------------------------------------------

    def say(self, text: str) -> None:
        t = self.player.t_rel
        print(f"[t+{t:8.1f} s] {text}", flush=True)
        self.last_said = time.monotonic()

    # the run ---------------------------------------------------------------------------

    def run(self) -> int:
        sc = self.scenario
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self.stop.set())
        print(f"scenario {sc.scenario.name!r} for {self.rover}: {len(sc.steps)} steps ({self.note})",
              flush=True)
        session = open_session(self.args, wait_s=self.args.wait, on_waiting=lambda: print(
            f"waiting for the Zenoh router at {describe_endpoint(self.args)} ...", flush=True))
        keep: list[zenoh.Subscriber[None] | zext.AdvancedSubscriber[None]] = []  # alive until closed
        try:
            keep.append(zext.declare_advanced_subscriber(
                session, keys.under(self.rover), self._on_sample,
                history=zext.HistoryConfig(detect_late_publishers=True)))
            keep.append(session.declare_subscriber(keys.event(self.rover), self._on_event))
            require_rover(session, self.rover)  # also a round trip: our subscriptions are in place
            first = self._first_tick()
            self.session = session
            self._mark("start", f"started ({describe_start(self.scenario.start)})")
            start = self._start(first)
            self._set_clock(start)
            code = self._play()
        finally:
            keep.clear()
            session.close()
        return code

    def _first_tick(self) -> dict:
        try:
            first = self.ticks.get(timeout=self.args.wait)
        except queue.Empty:
            raise ToolError(f"no clock from {self.rover} within {self.args.wait:g} s: "
                            "is its clock service running?") from None
        self.first_clock = first
        return first

    def _start(self, first: dict) -> dict:
        """A reset, or a snapshot restored, when the scenario says so; the first tick after it."""
        start = self.scenario.start
        if start is None:
            return first
        key = (keys.control_reset(self.rover) if start == "reset"
               else keys.control_restore(self.rover, start.snapshot))
        cause = "reset" if start == "reset" else f"restore:{start.snapshot}"
        print(f"starting {describe_start(start)} ...", flush=True)
        write(self.session, key, b"")
        deadline = time.monotonic() + self.args.wait
        answered = False
        while time.monotonic() < deadline and not self.stop.is_set():
            try:
                ev = self.events.get(timeout=0.1)
            except queue.Empty:
                continue
            if ev.key == key and ev.kind == "rejected":
                raise ToolError(f"cannot start: {ev.message}", 1)
            if ev.key == key and ev.kind == "session":
                answered = True
                break
        while answered and time.monotonic() < deadline and not self.stop.is_set():
            try:
                tick = self.ticks.get(timeout=0.1)
            except queue.Empty:
                continue
            if tick.get("cause") == cause and tick.get("epoch", 0) > first.get("epoch", 0):
                print(f"{self.rover} is at its start: sim t {tick['t_s']:.1f} s", flush=True)
                return tick
        raise ToolError(f"no answer from {self.rover} to {key} within {self.args.wait:g} s", 2)

    def _set_clock(self, now: dict) -> None:
        scale = self.args.time_scale or self.scenario.time_scale
        body: dict = {}
        if scale is not None and scale != now.get("time_scale"):
            body["time_scale"] = scale
        if now.get("paused") and self.scenario.start is not None:
            body["paused"] = False  # a snapshot saved paused: the scenario needs its clock running
        if body:
            self._put(keys.clock_control(self.rover), body)
            self.clock_changed = True
            first = self.first_clock or now
            print(f"clock of {self.rover} set to x{body.get('time_scale', now.get('time_scale', 1)):g}"
                  f"{', running' if 'paused' in body else ''} (was x{first.get('time_scale', 1):g})",
                  flush=True)
        elif self.scenario.start is not None and self.first_clock is not None and (
                now.get("time_scale") != self.first_clock.get("time_scale")
                or now.get("paused") != self.first_clock.get("paused")):
            self.clock_changed = True  # the reset changed it: put it back at the end

    def _mark(self, what: str, message: str, step: int | None = None) -> None:
        """The scenario's progress in the journal (``scenario`` events), for the debrief."""
        body: dict[str, object] = {"scenario": self.scenario.scenario.name, "what": what,
                                   "message": message[:1000]}
        if step is not None:
            body["step"] = step
        try:
            write(self.session, keys.control_scenario(self.rover), json.dumps(body))
        except zenoh.ZError as exc:  # the journal misses a mark; the scenario goes on
            print(f"could not mark the journal: {exc}", file=sys.stderr, flush=True)

    def _save_status(self) -> None:
        if not self.args.status_json:
            return
        p = self.player
        data = {"scenario": self.scenario.scenario.name, "rover": self.rover, "t_rel_s": p.t_rel,
                "finished": p.finished, "end_reason": p.end_reason,
                "waiting": p.waiting(self.lookup),
                "steps": [{**asdict(r), "trigger": describe_trigger(self.scenario.steps[r.index]),
                           "action": describe_action(self.scenario.steps[r.index])} for r in p.results]}
        tmp = Path(self.args.status_json + ".tmp")
        tmp.write_text(json.dumps(data))
        tmp.replace(self.args.status_json)

    def _put(self, key: str, body: dict) -> None:
        write(self.session, key, json.dumps(body))

    def _play(self) -> int:
        player = self.player
        interrupted = False
        last_saved = 0.0
        while not player.finished:
            if self.stop.is_set():
                player.finish("interrupted")
                interrupted = True
                break
            tick = None
            try:
                tick = self.ticks.get(timeout=0.2)
                while True:  # a backlog is folded into its latest tick
                    tick = self.ticks.get_nowait()
            except queue.Empty:
                pass
            if tick is not None:
                self._step(tick)
            self._answers()
            now = time.monotonic()
            if now - self.last_said >= 9.0:  # never silent for 10 s of wall time
                self._status(tick)
            if now - last_saved >= 0.5:
                last_saved = now
                self._save_status()
        self._wait_answers()
        self._finish_clock()
        if self.args.clear_at_end:
            self._clear_injected()
        code = self._summary(interrupted)
        self._mark("end", f"ended: {player.end_reason}; "
                   + ("every step fired and was accepted" if code == 0 else "not every step played"))
        self._save_status()
        return code

    def _step(self, tick: dict) -> None:
        player = self.player
        before = [r.status for r in player.results]
        writes = player.tick(float(tick["t_s"]), self.lookup)
        for i, r in enumerate(player.results):
            if before[i] in ("waiting", "armed") and r.fired_t_s is not None:
                step = self.scenario.steps[i]
                why = f" ({r.detail})" if r.detail else ""
                named = f"{step.name}: " if step.name else ""
                self.say(f"step {i + 1}/{len(player.results)} {named}{describe_action(step)}{why}")
                self._mark("step", f"step {i + 1}/{len(player.results)} {named}{describe_action(step)}",
                           i + 1)
                if step.note:
                    self.say(f"    note: {step.note}")
            elif before[i] != r.status and r.status == "timed out":
                self.say(f"step {i + 1} {r.label!r} timed out: {r.detail}")
            elif before[i] == "ramping" and r.status == "done":
                self.say(f"step {i + 1} {r.label!r}: ramp complete")
        for w in writes:
            write(self.session, w.key, w.payload)
            if self.scenario.steps[w.step].clock is not None:
                self.clock_changed = True
            if w.final:
                self.pending.append(_Pending(w, time.monotonic() + self.args.timeout))
        if player.finished:
            self.say(f"end: {player.end_reason}")

    def _answers(self) -> None:
        """Match the twin's events with the writes waiting for them; expire the others."""
        while True:
            try:
                ev = self.events.get_nowait()
            except queue.Empty:
                break
            if ev.kind == "rejected":
                # A rejection names the key; it may answer a ramp's intermediate write too.
                match = next((p for p in self.pending if p.write.key == ev.key), None)
                step = match.write.step if match else self._step_of_key(ev.key)
                if match:
                    self.pending.remove(match)
                if step is not None:
                    self._outcome(step, "rejected", ev.message)
                continue
            match = next((p for p in self.pending if p.write.key == ev.key and p.write.answer == ev.kind),
                         None)
            if match is not None:
                self.pending.remove(match)
                self._outcome(match.write.step, "accepted", ev.message)
                if ev.kind == "fault_injected":
                    self.injected[ev.key] = match.write.step
                elif ev.kind == "fault_cleared":
                    self.injected.pop(ev.key, None)
        now = time.monotonic()
        for p in [p for p in self.pending if now >= p.deadline]:
            self.pending.remove(p)
            if p.write.answer is None:
                self._outcome(p.write.step, "sent", "")  # inputs are not acknowledged, only refused
            else:
                self._outcome(p.write.step, "no answer", f"no {p.write.answer} event within "
                              f"{self.args.timeout:g} s")

    def _step_of_key(self, key: str) -> int | None:
        fired = [r.index for r in self.player.results if r.fired_t_s is not None]
        for i in reversed(fired):
            if any(w.key == key for w in self.player.writes_of(i, 0.0)):
                return i
        return None

    def _outcome(self, step: int, outcome: str, message: str) -> None:
        r = self.player.results[step]
        if r.outcome == "rejected":
            return  # a rejection is what the instructor must see
        r.outcome = outcome
        if message and outcome != "accepted":
            r.detail = (r.detail + "; " if r.detail else "") + message
        if outcome != "sent":
            self.say(f"    step {step + 1} -> {outcome}: {message}")

    def _wait_answers(self) -> None:
        while self.pending:
            self._answers()
            if self.pending:
                time.sleep(0.05)

    def _status(self, tick: dict | None) -> None:
        sim = (f"sim t {tick['t_s']:.1f} s, " if tick
               else "no clock tick lately (is the clock paused?), ")
        self.say(sim + self.player.waiting(self.lookup))

    def _finish_clock(self) -> None:
        first = self.first_clock
        if not self.clock_changed or first is None:
            return
        body = {"time_scale": first.get("time_scale", 1.0), "paused": bool(first.get("paused", False))}
        self._put(keys.clock_control(self.rover), body)
        print(f"clock of {self.rover} put back to x{body['time_scale']:g}"
              f"{' (paused)' if body['paused'] else ''}", flush=True)

    def _clear_injected(self) -> None:
        if not self.injected:
            return
        for key in list(self.injected):
            write(self.session, key, None)
            self.pending.append(_Pending(Write(key, None, self.injected[key], "fault_cleared"),
                                         time.monotonic() + self.args.timeout))
        print(f"clearing {len(self.injected)} fault(s) the scenario injected", flush=True)
        deadline = time.monotonic() + self.args.timeout
        while self.injected and time.monotonic() < deadline:
            self._answers()
            time.sleep(0.05)
        self.pending.clear()

    def _summary(self, interrupted: bool) -> int:
        p, sc = self.player, self.scenario
        print()
        print(f"summary of {sc.scenario.name!r} on {self.rover}: {p.end_reason} "
              f"at {p.t_rel:.1f} s of sim time ({time.monotonic() - self.started_wall:.1f} s of wall time)")
        print(f"  {'#':>2}  {'fired at':>9}  {'status':<10} {'outcome':<10} step")
        ok = not interrupted
        for r in p.results:
            fired = f"{r.fired_t_s:8.1f}s" if r.fired_t_s is not None else f"{'-':>9}"
            print(f"  {r.index + 1:>2}  {fired}  {r.status:<10} {r.outcome or '-':<10} {r.label}"
                  + (f"  ({r.detail})" if r.detail and r.outcome != "accepted" else ""))
            if r.fired_t_s is None or r.outcome in ("rejected", "no answer"):
                ok = False
        if self.args.json_summary:
            Path(self.args.json_summary).write_text(json.dumps({
                "scenario": sc.scenario.name, "rover": self.rover,
                "start_t_s": p.t0, "end_reason": p.end_reason, "ok": ok,
                "steps": [{**asdict(r), "trigger": describe_trigger(sc.steps[r.index]),
                           "action": describe_action(sc.steps[r.index])} for r in p.results],
            }, indent=2))
        verdict = "every step fired and was accepted" if ok else "NOT every step played as planned"
        print(f"result: {verdict}")
        return 0 if ok else 1
