"""One write on the twin and its answer, for every tool (STYLE habit 11, DECISIONS D1, D3, D4).

A :class:`Writer` sends a planned write (:func:`common.writes.plan_write`: the key, the
payload, the event that accepts it and the service that answers) and waits for the answer
on the services' own event keys, ``lunaris/<rover>/event/*`` (and the journal's ``event``,
the same events once more, taken once): it works without the faults service. The waiting
itself, Zenoh aside, is :mod:`common.answers` (the bridge's crew controls wait the same way). Each write
carries who made it (``actor``, D4): ``instructor`` from the CLI and the console,
``scenario`` from the scenario player.

The answer is one of three types:

- :class:`Accepted`: the accepting event (``fault_injected``, ``command``, ``input`` ...);
- :class:`Rejected`: the ``rejected`` event, and its reason in words;
- :class:`NotApplied`: the write did not reach its owner, or nothing answered in time, and
  why. A write is not sent at all when its owner is known unreachable (its liveliness token
  went away, or the rover's link is lost: :mod:`lunaris.client.link`); one sent is not
  waited for beyond ``timeout_s`` (3 s, longer than the 2 s after which an owner refuses a
  write that arrives late, D3), so "not applied" is the truth: the twin refuses it if it
  arrives later.

The owner's liveliness and the rover's link come from a :class:`~lunaris.client.mirror.Mirror`
of the rover. Thread-safe; :meth:`Writer.awrite` for asyncio.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any, Literal

import msgspec
import zenoh

from common import keys
from common.answers import ANSWER_S, Accepted, Answer, Awaiting, NotApplied, Pending, Rejected
from common.answers import answers as _answers  # noqa: F401 - its old name, which tests read
from common.connection import write as put_or_delete
from common.messages import Event
from common.writes import Write, unreachable_words
from lunaris.client.link import LINK_TIMEOUT_S, clock_time
from lunaris.client.mirror import Mirror

__all__ = ["ANSWER_S", "Accepted", "Actor", "Answer", "NotApplied", "Pending", "Rejected", "Writer"]

Actor = Literal["crew", "instructor", "scenario"]


class Writer:
    """Writes on one rover's keys (or every rover's, ``mirror.rover == "*"``) and their answers."""

    def __init__(self, session: zenoh.Session, mirror: Mirror, actor: Actor = "instructor",
                 timeout_s: float = ANSWER_S):
        self.session, self.mirror, self.actor, self.timeout_s = session, mirror, actor, timeout_s
        self._awaiting = Awaiting()
        self._decoder = msgspec.json.Decoder(Event)
        # live events only: a cache replayed is an old answer, not this write's
        self._sub = session.declare_subscriber(keys.under(mirror.rover, "event/**"), self._on_event)
        self._synced = False

    def close(self) -> None:
        self._sub.undeclare()

    # -- before sending -----------------------------------------------------------------------

    def ready(self, rover: str, link_wait_s: float = LINK_TIMEOUT_S + 0.5) -> set[str]:
        """Make sure the answer cannot be missed and the rover's state is known: a round trip
        to the router (our subscriptions are in place), and, if the rover's clock is live, its
        first tick awaited (``link_wait_s`` at most) so that a cut link is known before
        sending. The live services of ``rover`` (as the mirror heard when it started)."""
        self.mirror.barrier()
        self._synced = True
        live = self.mirror.services(rover)
        if "clock" in live:
            deadline = time.monotonic() + link_wait_s
            while self.mirror.link(rover).state == "unknown" and time.monotonic() < deadline:
                time.sleep(0.02)
        return live

    def unreachable(self, write: Write, sending: bool = False) -> str | None:
        """Why ``write`` cannot reach its owner now, in words; None when nothing says so. An
        owner never seen live is a reason once the write went unanswered, not before sending
        while the faults service is live: a rover without a drive has no drive service, and
        the faults service (the gatekeeper) says why in its rejection."""
        rover, owner = write.rover, write.owner
        token = self.mirror.token(rover, owner)
        if token is not None and not token.alive:
            return unreachable_words(rover, owner, clock_time(token.since))
        live = self.mirror.services(rover)
        if token is None and not live:
            return f"no Lunaris service of {rover} is reachable (no liveliness)"
        if token is None and not (sending and "faults" in live):
            return unreachable_words(rover, owner, None)
        link = self.mirror.link(rover)
        if link.state == "lost":
            return f"the link to {rover} is lost: {link.reason}"
        return None

    # -- sending and waiting ---------------------------------------------------------------------

    def put(self, write: Write) -> bool:
        """Send without waiting for an answer (a ramp's values between its first and last);
        False, and nothing sent, when the owner is known unreachable."""
        if self.unreachable(write, sending=True) is not None:
            return False
        self._send(write)
        return True

    def submit(self, write: Write, on_answer: Callable[[Answer], None] | None = None) -> Pending:
        """Send ``write`` (unless its owner is known unreachable) and return at once; the
        answer comes to ``on_answer`` (on a Zenoh thread) and to :meth:`wait`."""
        if not self._synced:
            self.mirror.barrier()
            self._synced = True
        p = Pending(write, time.monotonic() + self.timeout_s, on_answer)
        why = self.unreachable(write, sending=True)
        if why is not None:
            self._awaiting.settle(p, NotApplied(write, f"not applied: {why}", True, False))
            return p
        self._awaiting.add(p)
        try:
            self._send(write)
        except zenoh.ZError as exc:
            self._awaiting.settle(p, NotApplied(
                write, f"not applied: the write could not be sent ({exc})", True, False))
        return p

    def wait(self, p: Pending) -> Answer:
        """The answer to ``p``, waiting until its deadline."""
        p.done.wait(max(0.0, p.deadline - time.monotonic()))
        return self.give_up(p)

    def write(self, write: Write) -> Answer:
        """Send ``write`` and wait for its answer."""
        return self.wait(self.submit(write))

    async def awrite(self, write: Write) -> Answer:
        """:meth:`write` for asyncio: no thread is held while the answer is awaited."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Answer] = loop.create_future()

        def settle(answer: Answer) -> None:
            if not future.done():
                future.set_result(answer)

        def deliver(answer: Answer) -> None:
            loop.call_soon_threadsafe(settle, answer)

        p = await asyncio.to_thread(self.submit, write, deliver)
        try:
            return await asyncio.wait_for(asyncio.shield(future),
                                          max(0.0, p.deadline - time.monotonic()))
        except TimeoutError:
            return self.give_up(p)

    def give_up(self, p: Pending) -> Answer:
        """The answer to ``p`` if it came; else stop waiting: not applied, and why."""
        got = self._awaiting.withdraw(p)
        if got is not None:
            return got
        why = self.unreachable(p.write)
        if why is not None:
            answer = NotApplied(p.write, f"not applied: {why}; the twin refuses the write if it "
                                         "arrives later", True, True)
        else:
            answer = NotApplied(p.write, f"no answer within {self.timeout_s:g} s: not applied; the "
                                         "twin refuses it if it arrives later", False, True)
        self._awaiting.settle(p, answer)
        return p.answer or answer

    def _send(self, write: Write) -> None:
        put_or_delete(self.session, write.key, write.payload, actor=write.actor or self.actor)

    # -- the answers -------------------------------------------------------------------------------

    def _on_event(self, s: zenoh.Sample) -> None:
        try:
            rover, parts = keys.split(str(s.key_expr))
            ev = self._decoder.decode(s.payload.to_bytes())
        except (ValueError, msgspec.DecodeError, msgspec.ValidationError):
            return  # said by the mirror, which reads the same keys
        self._awaiting.hear(rover, parts, ev)


def describe(answer: Answer) -> dict[str, Any]:
    """An answer as JSON: the verdict, the message and the event (if any)."""
    verdict = {Accepted: "accepted", Rejected: "rejected"}.get(type(answer), "not applied")
    event = getattr(answer, "event", None)
    return {"verdict": verdict, "message": answer.message,
            "event": msgspec.structs.asdict(event) if event is not None else None}
