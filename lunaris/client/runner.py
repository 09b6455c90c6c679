"""Playing a scenario against the running twin: one runner for ``lunaris scenario run`` and the
console (issue 24). It prints nothing: :meth:`Runner.run` yields what happens
(:class:`Progress`), the caller shows it as it likes, and every change is published on
``lunaris/<rover>/scenario/progress`` (:class:`common.scenario_progress.ScenarioProgress`).

The runner follows the rover's clock (scenario times are simulated time, so a scenario can play
with the clock sped up) through a :class:`~lunaris.client.mirror.Mirror` of the rover, which
also holds the latest telemetry the conditions read; it makes each step's writes through a
:class:`~lunaris.client.writer.Writer` (as the ``scenario`` actor, D4) and records each
answer: accepted, rejected (and why), not applied (and why). A ramp's first and last values
are awaited, the ones between are only sent.

A scenario may start from a reset or a snapshot (``start``): the runner asks for it and waits
for the clock's first tick of the new epoch before it plays. It marks its start, each step,
each expectation scored (met or missed, SPEC §12d: a ``scenario`` event whose params hold the
outcome, :class:`common.messages.ExpectationMark`) and its end in the journal
(``control/scenario``), and while it plays it is never silent for 10 s of wall time: it says
what it waits for. At the end it puts the clock back to the speed
it had (and, if asked, clears the faults it injected that are still active).

A drill belongs to the trainee session it plays in (SPEC §13a): the first tick of another
session (a new trainee, from the console, the CLI or ``control/session``) ends the run at once,
"stopped: a new session began", and nothing more of it is written to the twin but the clock's
speed put back (no expectation scored missed, no end mark, no fault cleared), so the next
trainee's report holds none of it. Found by an instructor: a drill played on into the next
trainee's session and scored it ("isolate the shorted camera ... waiting: 55 s left").
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.messages import BadInput, Clock, ExpectationMark, ScenarioMark
from common.scenario import Scenario, describe_start
from common.scenario_player import Player, StepResult, StepWrite, describe_action, describe_trigger
from common.scenario_progress import ExpectProgress, ScenarioProgress, StepProgress
from common.worker import wait_get
from common.writes import Write, plan_write
from lunaris.client.mirror import Change, Mirror
from lunaris.client.session import ToolError, live_rovers, unknown_rover
from lunaris.client.writer import ANSWER_S, Accepted, Answer, NotApplied, Pending, Rejected, Writer

__all__ = ["PROGRESS_KEY", "Progress", "Runner"]

PROGRESS_KEY = "scenario/progress"  # under lunaris/<rover>/
SILENT_S = 9.0  # never silent for 10 s of wall time
PUBLISH_S = 1.0  # the progress is published at least this often while it plays


@dataclass(frozen=True)
class Progress:
    """One thing a scenario's run says: ``info`` (before and after it plays) or ``step``
    (while it plays, at ``t_rel_s`` of sim time since its start)."""

    kind: Literal["info", "step"]
    message: str
    t_rel_s: float = 0.0

    def line(self) -> str:
        """As ``lunaris scenario run`` prints it."""
        return f"[t+{self.t_rel_s:8.1f} s] {self.message}" if self.kind == "step" else self.message


class Runner:
    """One run of ``scenario`` on the rover it names, over ``session``."""

    def __init__(self, session: zenoh.Session, scenario: Scenario, *, time_scale: float | None = None,
                 timeout_s: float = ANSWER_S, wait_s: float = 10.0, clear_at_end: bool = False,
                 note: str = ""):
        self.session, self.scenario = session, scenario
        self.rover = scenario.rover
        self.time_scale, self.timeout_s, self.wait_s = time_scale, timeout_s, wait_s
        self.clear_at_end, self.note = clear_at_end, note
        self.player = Player(scenario)
        self.mirror = Mirror(self.rover, events=False)
        self.writer: Writer | None = None
        self.ticks: queue.SimpleQueue[Clock] = queue.SimpleQueue()
        self.answers: queue.SimpleQueue[tuple[int, Answer]] = queue.SimpleQueue()
        self.pending: dict[int, list[Pending]] = {}  # step -> its writes awaiting an answer
        self.awaited: set[int] = set()  # steps whose first write was awaited
        self.injected: dict[str, int] = {}  # fault key -> step, of the faults still active
        self.journalled: set[int] = set()  # the expect steps whose outcome is in the journal
        self.stopped = threading.Event()
        self.state: Literal["starting", "playing", "ended"] = "starting"
        self.first_clock: Clock | None = None
        self.last_clock: Clock | None = None
        self.clock_changed = False
        self.interrupted = False
        self.session_id: str | None = None  # the trainee session it plays in
        self.superseded = False  # another session began: the run ended with nothing more written
        self.ok: bool | None = None
        self.code: int | None = None  # the exit status, once ended: 0 all played, 1 not, 2 could not
        self.message = ""
        self.started_wall = time.monotonic()
        self._last_said = time.monotonic()
        self._published = 0.0
        self._publisher: zext.AdvancedPublisher | None = None

    # -- control from another thread --------------------------------------------------------------

    def stop(self) -> None:
        """End the run at its next turn ("interrupted"): the clock put back, the end marked."""
        self.stopped.set()

    # -- what it is now ------------------------------------------------------------------------------

    def status(self) -> ScenarioProgress:
        p, sc = self.player, self.scenario
        steps = [StepProgress(r.index, r.label, describe_trigger(sc.steps[r.index]),
                              describe_action(sc.steps[r.index]), r.status, r.outcome, r.detail,
                              r.armed_t_s, r.fired_t_s, self._expect_progress(r)) for r in p.results]
        waiting = p.waiting(self.mirror.lookup(self.rover)) if self.state == "playing" else (
            f"ended: {p.end_reason}" if self.state == "ended" else "starting")
        return ScenarioProgress(
            t_s=self.last_clock.t_s if self.last_clock else 0.0, scenario=sc.scenario.name,
            rover=self.rover, state=self.state, t_rel_s=p.t_rel, waiting=waiting,
            message=self.message, steps=steps, end_reason=p.end_reason, ok=self.ok,
            session=self.session_id or "")

    # -- the run ----------------------------------------------------------------------------------------

    def run(self) -> Iterator[Progress]:
        """Play the scenario to its end, saying what happens. Raises :class:`ToolError` when
        it cannot start (exit status 2, or 1 when the twin refuses its start)."""
        sc = self.scenario
        yield self._info(f"scenario {sc.scenario.name!r} for {self.rover}: {len(sc.steps)} steps"
                         + (f" ({self.note})" if self.note else ""))
        self.mirror.listen(self._on_change)
        try:
            self.mirror.start(self.session)
            self.writer = Writer(self.session, self.mirror, "scenario", self.timeout_s)
            self._publisher = zext.declare_advanced_publisher(
                self.session, keys.under(self.rover, PROGRESS_KEY),
                cache=zext.CacheConfig(max_samples=1), publisher_detection=True)
            if not self.writer.ready(self.rover):
                raise ToolError(unknown_rover(self.rover, live_rovers(self.session)))
            first = self._first_tick()
            self._mark("start", f"started ({describe_start(sc.start)})")
            yield from self._start(first)
            yield from self._set_clock()
            self.state = "playing"
            self._publish(force=True)
            yield from self._play()
        except ToolError:
            self.state, self.code = "ended", self.code or 2
            self._publish(force=True)
            raise
        finally:
            self._close()

    def _close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.mirror.close()
        if self._publisher is not None:
            with contextlib.suppress(zenoh.ZError):
                self._publisher.undeclare()

    def _on_change(self, change: Change) -> None:  # on a Zenoh thread
        if change.kind == "value" and isinstance(change.value, Clock):
            self.ticks.put(change.value)

    def _info(self, text: str) -> Progress:
        self.message = text
        return Progress("info", text)

    def _say(self, text: str) -> Progress:
        self.message = text
        self._last_said = time.monotonic()
        self._publish(force=True)
        return Progress("step", text, self.player.t_rel)

    def _publish(self, force: bool = False) -> None:
        now = time.monotonic()
        if self._publisher is None or (not force and now - self._published < PUBLISH_S):
            return
        self._published = now
        with contextlib.suppress(zenoh.ZError):
            self._publisher.put(msgspec.json.encode(self.status()))

    def _first_tick(self) -> Clock:
        try:
            first = wait_get(self.ticks, self.wait_s)
        except queue.Empty:
            raise ToolError(f"no clock from {self.rover} within {self.wait_s:g} s: is its clock "
                            "service running?") from None
        self.first_clock = self.last_clock = first
        self.session_id = first.session
        return first

    def _plan(self, tail: str, body: msgspec.Struct | dict | None) -> Write:
        payload = None if body is None else msgspec.json.encode(body)
        return plan_write(self.rover, tail, payload)

    def _start(self, first: Clock) -> Iterator[Progress]:
        """A reset, or a snapshot restored, when the scenario says so; the first tick after it."""
        start = self.scenario.start
        if start is None:
            return
        assert self.writer is not None
        if start == "reset":
            tail, cause = "control/reset", "reset"
        else:
            tail, cause = f"control/restore/{start.snapshot}", f"restore:{start.snapshot}"
        yield self._info(f"starting {describe_start(start)} ...")
        answer = self.writer.write(self._plan(tail, {}))
        if isinstance(answer, Rejected):
            self.code = 1
            raise ToolError(f"cannot start: {answer.message}", 1)
        if isinstance(answer, NotApplied):
            raise ToolError(f"cannot start: {answer.reason}", 2)
        deadline = time.monotonic() + self.wait_s
        while time.monotonic() < deadline and not self.stopped.is_set():
            try:
                tick = wait_get(self.ticks, 0.1)
            except queue.Empty:
                continue
            self.last_clock = tick
            if tick.cause == cause and tick.epoch > first.epoch:
                yield self._info(f"{self.rover} is at its start: sim t {tick.t_s:.1f} s")
                return
        raise ToolError(f"no clock tick of {self.rover}'s new start within {self.wait_s:g} s", 2)

    def _set_clock(self) -> Iterator[Progress]:
        now = self.last_clock or self.first_clock
        first = self.first_clock
        assert now is not None and first is not None and self.writer is not None
        scale = self.time_scale or self.scenario.time_scale
        body: dict[str, object] = {}
        if scale is not None and scale != now.time_scale:
            body["time_scale"] = scale
        if now.paused and self.scenario.start is not None:
            body["paused"] = False  # a snapshot saved paused: the scenario needs its clock running
        if body:
            self.writer.put(self._plan("clock/control", body))
            self.clock_changed = True
            yield self._info(f"clock of {self.rover} set to x{body.get('time_scale', now.time_scale):g}"
                             f"{', running' if 'paused' in body else ''} (was x{first.time_scale:g})")
        elif self.scenario.start is not None and (now.time_scale != first.time_scale
                                                   or now.paused != first.paused):
            self.clock_changed = True  # the reset changed it: put it back at the end

    def _expect_progress(self, r: StepResult) -> ExpectProgress | None:
        expect = self.scenario.steps[r.index].expect
        if expect is None:
            return None
        return ExpectProgress(r.label, expect.when, expect.within_s, r.met, r.met_t_s, r.deadline_t_s)

    def _mark(self, what: Literal["start", "step", "end", "expect"], message: str,
              step: int | None = None, expectation: ExpectationMark | None = None) -> None:
        """The scenario's progress in the journal (``scenario`` events), for the debrief."""
        if self.writer is None:
            return
        mark = ScenarioMark(self.scenario.scenario.name[:200], what, message[:1000], step, expectation)
        with contextlib.suppress(BadInput, zenoh.ZError):
            self.writer.put(self._plan("control/scenario", mark))

    def _play(self) -> Iterator[Progress]:
        player = self.player
        while not player.finished:
            if self.stopped.is_set():
                player.finish("interrupted")
                self.interrupted = True
                break
            tick = None
            try:
                tick = wait_get(self.ticks, 0.2)
                while True:  # a backlog is folded into its latest tick
                    tick = self.ticks.get_nowait()
            except queue.Empty:
                pass
            if tick is not None and self._other_session(tick):
                player.finish(f"stopped: a new session began ({tick.session})")
                self.superseded = self.interrupted = True
                yield self._say(f"stopped at sim t {tick.t_s:.1f} s: a new session began; "
                                "the drill belonged to the one before")
                break
            if tick is not None:
                self.last_clock = tick
                yield from self._step(tick)
            yield from self._answers()
            if time.monotonic() - self._last_said >= SILENT_S:
                yield self._say(("" if tick else "no clock tick lately (is the clock paused, or the "
                                 "link lost?), ") + (f"sim t {tick.t_s:.1f} s, " if tick else "")
                                + player.waiting(self.mirror.lookup(self.rover)))
            self._publish()
        if self.superseded:  # nothing of it in the next session but its clock (module text)
            self.pending.clear()
            yield from self._finish_clock()
        else:
            yield from self._scores()  # the expectations the end scored (missed)
            yield from self._wait_answers()
            yield from self._finish_clock()
            if self.clear_at_end:
                yield from self._clear_injected()
        self.ok = not self.interrupted and all(
            r.fired_t_s is not None and r.outcome not in ("rejected", "not applied")
            for r in player.results if self.scenario.steps[r.index].expect is None)
        self.code = 0 if self.ok else 1
        self.state = "ended"
        if not self.superseded:
            self._mark("end", f"ended: {player.end_reason}; "
                       + ("every step fired and was accepted" if self.ok else "not every step played"))
        self.message = f"ended: {player.end_reason}"
        self._publish(force=True)

    def _other_session(self, tick: Clock) -> bool:
        """Whether ``tick`` is of another trainee session than the run's (a clock older than
        sessions names none: never)."""
        if not self.session_id:
            self.session_id = tick.session or None
            return False
        return bool(tick.session) and tick.session != self.session_id

    def _step(self, tick: Clock) -> Iterator[Progress]:
        player = self.player
        before = [r.status for r in player.results]
        writes = player.tick(tick.t_s, self.mirror.lookup(self.rover))
        n = len(player.results)
        for i, r in enumerate(player.results):
            if before[i] in ("waiting", "armed") and r.fired_t_s is not None:
                step = self.scenario.steps[i]
                why = f" ({r.detail})" if r.detail else ""
                named = f"{step.name}: " if step.name else ""
                yield self._say(f"step {i + 1}/{n} {named}{describe_action(step)}{why}")
                self._mark("step", f"step {i + 1}/{n} {named}{describe_action(step)}", i + 1)
                if step.note:
                    yield self._say(f"    note: {step.note}")
            elif before[i] != r.status and r.status == "timed out":
                yield self._say(f"step {i + 1} {r.label!r} timed out: {r.detail}")
            elif before[i] == "ramping" and r.status == "done":
                yield self._say(f"step {i + 1} {r.label!r}: ramp complete")
        for w in writes:
            self._send(w)
        yield from self._scores()
        if player.finished:
            yield self._say(f"end: {player.end_reason}")

    def _scores(self) -> Iterator[Progress]:
        """Each expectation scored (met or missed) said and journalled, once."""
        t0 = self.player.t0
        for r in self.player.results:
            step = self.scenario.steps[r.index]
            if step.expect is None or r.met is None or r.index in self.journalled:
                continue
            self.journalled.add(r.index)

            def sim(rel: float | None) -> float | None:
                return None if rel is None or t0 is None else t0 + rel
            if r.met:
                assert r.met_t_s is not None and r.armed_t_s is not None
                words = (f"expectation {r.label!r} met at t+{r.met_t_s:.1f} s, "
                         f"{r.met_t_s - r.armed_t_s:.1f} s of its {step.expect.within_s:g} s")
            else:
                words = f"expectation {r.label!r} MISSED: {r.detail}"
            yield self._say(words)
            self._mark("expect", words[:300], r.index + 1, ExpectationMark(
                index=r.index, label=r.label[:200], condition=step.expect.when[:300],
                within_s=step.expect.within_s, met=r.met, at_t_s=sim(r.met_t_s),
                armed_t_s=sim(r.armed_t_s), start_t_s=t0, detail=r.detail[:300]))

    def _send(self, w: StepWrite) -> None:
        assert self.writer is not None
        if self.scenario.steps[w.step].clock is not None:
            self.clock_changed = True
        if not (w.final or w.step not in self.awaited):
            self.writer.put(w.write)  # a ramp's value between its first and its last
            return
        self.awaited.add(w.step)
        step = w.step

        def answered(answer: Answer) -> None:
            self.answers.put((step, answer))
        self.pending.setdefault(step, []).append(self.writer.submit(w.write, answered))

    def _answers(self) -> Iterator[Progress]:
        """The answers come in; the writes waiting too long are given up (not applied)."""
        assert self.writer is not None
        for ps in list(self.pending.values()):
            for p in [p for p in ps if time.monotonic() >= p.deadline]:
                self.writer.give_up(p)  # its NotApplied comes to the queue
        while True:
            try:
                step, answer = self.answers.get_nowait()
            except queue.Empty:
                return
            ps = self.pending.get(step, [])
            for p in [p for p in ps if p.answer is answer]:
                ps.remove(p)
            if not ps:
                self.pending.pop(step, None)
            yield from self._outcome(step, answer)

    def _outcome(self, step: int, answer: Answer) -> Iterator[Progress]:
        r = self.player.results[step]
        if isinstance(answer, Accepted):
            kind = answer.event.kind
            if kind == "fault_injected":
                self.injected[answer.write.key] = step
            elif kind == "fault_cleared":
                self.injected.pop(answer.write.key, None)
            if r.outcome not in ("rejected", "not applied"):
                r.outcome = "accepted"
            return
        outcome = "rejected" if isinstance(answer, Rejected) else "not applied"
        if r.outcome == "rejected":
            return  # a rejection is what the instructor must see
        r.outcome = outcome
        r.detail = (r.detail + "; " if r.detail else "") + answer.message
        yield self._say(f"    step {step + 1} -> {outcome}: {answer.message}")

    def _wait_answers(self) -> Iterator[Progress]:
        while self.pending:
            yield from self._answers()
            if self.pending:
                time.sleep(0.05)

    def _finish_clock(self) -> Iterator[Progress]:
        first = self.first_clock
        if not self.clock_changed or first is None or self.writer is None:
            return
        self.writer.put(self._plan("clock/control", {"time_scale": first.time_scale,
                                                      "paused": first.paused}))
        yield self._info(f"clock of {self.rover} put back to x{first.time_scale:g}"
                         f"{' (paused)' if first.paused else ''}")

    def _clear_injected(self) -> Iterator[Progress]:
        if not self.injected or self.writer is None:
            return
        yield self._info(f"clearing {len(self.injected)} fault(s) the scenario injected")
        cleared = [self.writer.submit(self._plan("/".join(keys.split(key)[1]), None))
                   for key in list(self.injected)]
        for p in cleared:
            if isinstance(self.writer.wait(p), Accepted):
                self.injected.pop(p.write.key, None)
