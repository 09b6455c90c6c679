"""The worker of a service: the one thread that handles everything the service is given.

Models need no locks: every sample, timer and hook of a service runs here, one at a time.
What comes in, and in what order it is handled:

- urgent inputs (the faults: what the crew is trained on) first, ahead of everything
  waiting; a burst of telemetry being drained breaks off for one, and a hook or timer that
  works through a fleet calls :meth:`Worker.urgent_first` between its parts;
- the telemetry of a fleet, drained from Zenoh channels (:meth:`Worker.add_channel`) every
  ``POLL_S`` while samples come, backing off to ``POLL_MAX_S`` between a fleet's ticks;
- queued inputs (commands, controls, queries), each after the telemetry already waiting in
  the channels: a rail command is judged on the loads heard before it (a reset, on the
  next tick's: see :mod:`services.power.service`);
- once the queue and the channels run dry (lingering ``batch_linger_s`` for the rest of a
  burst), or after ``MAX_BATCH_S`` of a steady stream, the ``after_batch`` hooks: a burst
  of inputs is folded into one recomputation, and a fleet's stream never holds them back;
- then the timers (:meth:`Worker.every`), which skip ahead rather than fire late in a burst.

A handler's failure is the ``guard``'s to report (the runtime turns bad input into a
rejection event and a bug into an ``internal_error`` one); the worker goes on.

The worker waits on a :class:`queue.Queue` (a lock and a condition), not on the C
``queue.SimpleQueue``: CPython 3.11's ``SimpleQueue.get(timeout=...)``, interrupted by a
signal whose handler (or getting the GIL back) outlasts its deadline, computes a negative
timeout and then waits for ever. A battery service so interrupted by its supervisor's death
signal lived on as an orphan, deaf to every SIGTERM after (issue 32). A condition's wait is a
lock's timed acquire, which recomputes its timeout after a signal and gives up once it is
past: no signal, held off or not, can make it hang. It costs ~2.5 us more per input than
``SimpleQueue`` (3 us against 0.8 for a put and a get): nothing beside a service's inputs,
which are commands, controls and queries (the telemetry of a fleet comes through channels).
Holding the signals off around a ``SimpleQueue`` wait (:func:`wait_get`, which the tools
keep for their high-rate queues) guards only against the signals held off.
"""

from __future__ import annotations

import math
import queue
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

__all__ = ["MAX_BATCH_S", "POLL_MAX_S", "POLL_S", "Worker", "wait_get"]

MAX_BATCH_S = 0.02  # the longest a batch runs before its hooks and the timers [s]
POLL_S = 0.002  # how often the channels are drained while they bring samples [s]
POLL_MAX_S = 0.016  # ... backing off to this while they are empty (between a fleet's ticks) [s]

_WAKE = ("wake",)  # queued for an urgent input, which waits in a line of its own
_STOP = ("stop",)

_HELD_OFF = {signal.SIGINT, signal.SIGTERM}  # the signals the tools and services handle


def wait_get(q: queue.SimpleQueue, timeout: float) -> Any:
    """``q.get(timeout=timeout)`` with SIGINT and SIGTERM held off while it waits: their
    handlers run as soon as it returns, within ``timeout``. For the tools' queues, where a
    ``SimpleQueue`` is worth its speed and SIGINT and SIGTERM are the only signals handled;
    the worker waits on a :class:`queue.Queue` instead (see the module).

    CPython 3.11's C ``SimpleQueue``, interrupted by a signal whose handler (or getting the
    GIL back) takes it past its deadline, computes a negative timeout and then waits for
    ever: a service so interrupted by its supervisor's death signal lived on as an orphan,
    deaf to every SIGTERM after (a main thread in an untimed ``sem_wait``); ``lunaris record``
    and ``scenario run`` could hang so on Ctrl-C. A held-off signal waits for the unblock (or
    goes to another thread, whose C handler only trips the flag the main thread then sees)."""
    if timeout <= 0:
        return q.get(timeout=0.0)
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD_OFF)
    try:
        return q.get(timeout=timeout)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


Guard = Callable[..., None]  # guard(fn, *args): run fn(*args), reporting what it raises
Convert = Callable[[Any], Any]  # a Zenoh sample -> the handler's argument, or None to drop it


class Worker:
    def __init__(self, guard: Guard):
        self._guard = guard
        self._queue: queue.Queue = queue.Queue()  # not SimpleQueue: see the module
        self._urgent: deque[tuple] = deque()  # (handler, sample), each with a _WAKE queued
        self._channels: list[tuple[Any, Convert, Callable[[Any], None]]] = []
        self._after_batch: list[Callable[[], None]] = []
        self.batch_linger_s = 0.0
        self._timers: list[list] = []  # [period_s (math.inf: once), due, fn]
        self._poll_s = POLL_S
        self._stop = threading.Event()
        self.signalled = False  # set by a signal handler on this thread: a plain flag, no lock

    # -- what comes in ------------------------------------------------------------------------

    def put(self, handler: Callable[[Any], None], sample: Any, *, urgent: bool = False) -> None:
        """Queue a sample for ``handler`` (from any thread)."""
        if urgent:
            self._urgent.append((handler, sample))
            self._queue.put(_WAKE)
        else:
            self._queue.put((handler, sample))

    def call_soon(self, fn: Callable, *args: Any) -> None:
        self._queue.put((fn, *args))

    def add_channel(self, channel: Any, convert: Convert, handler: Callable[[Any], None]) -> None:
        """Drain a Zenoh channel (``try_recv``): each sample converted, then handled."""
        self._channels.append((channel, convert, handler))

    @property
    def channels(self) -> int:
        return len(self._channels)

    def after_batch(self, fn: Callable[[], None], linger_s: float = 0.0) -> None:
        """Call ``fn`` once the queue has run dry, having waited up to ``linger_s`` after the
        first sample of a batch for more to arrive (a burst of samples that each tick sends
        over a millisecond or so is then folded into one call)."""
        self._after_batch.append(fn)
        self.batch_linger_s = max(self.batch_linger_s, linger_s)

    def every(self, period_s: float, fn: Callable[[], None]) -> None:
        """Call ``fn`` every ``period_s`` of wall time. A timer that falls behind skips ahead
        instead of firing a burst of late calls."""
        self._timers.append([period_s, time.monotonic() + period_s, fn])

    def once(self, delay_s: float, fn: Callable[[], None]) -> None:
        self._timers.append([math.inf, time.monotonic() + delay_s, fn])

    def stop(self) -> None:
        self._stop.set()
        self._queue.put(_STOP)

    def stopping(self) -> bool:
        return self.signalled or self._stop.is_set()

    # -- the loop -----------------------------------------------------------------------------

    def run(self) -> None:
        """Handle what comes until :meth:`stop` (or a signal's flag)."""
        while not self.stopping():
            timeout = self._run_timers()
            if self._channels:
                timeout = min(timeout, self._poll_s)
            try:  # at once while urgent inputs wait (their wake-up taken by a batch)
                item = self._queue.get(timeout=0.0 if self._urgent else timeout)
            except queue.Empty:
                item = None
            if self._batch(None if item is _WAKE or item is _STOP else item):
                for hook in self._after_batch:
                    self._guard(hook)

    def _batch(self, item: tuple | None) -> bool:
        """Handle what has come, as the module says; whether anything had."""
        start = time.monotonic()
        linger_until = start + self.batch_linger_s
        batch_until = start + MAX_BATCH_S
        handled = 0
        first = True
        while True:
            handled += self._handle_urgent()
            drained = self.drain(batch_until)
            handled += drained
            if first:  # drained every 2 ms while samples come, backing off to 16 ms between bursts
                self._poll_s = POLL_S if drained else min(2 * self._poll_s, POLL_MAX_S)
                first = False
            if self._urgent and time.monotonic() < batch_until:
                continue  # an urgent input came while draining
            if item is not None:
                self._guard(*item)
                handled += 1
            if not handled or self.stopping() or time.monotonic() >= batch_until:
                break  # nothing came (a poll of empty channels); under a steady stream the
                # hooks and timers still run
            try:
                item = self._next(self._queue.get_nowait())
                continue
            except queue.Empty:
                item = None
            if drained or self._urgent:
                continue
            wait = linger_until - time.monotonic() if self._after_batch else 0.0
            if wait <= 0:
                break
            try:  # the rest of a burst: a queued sample at once, a channel's within POLL_S
                item = self._next(self._queue.get(timeout=min(wait, POLL_S) if self._channels else wait))
            except queue.Empty:
                if not self._channels:
                    break
        return handled > 0

    @staticmethod
    def _next(item: tuple) -> tuple | None:
        return None if item is _WAKE or item is _STOP else item

    def urgent_first(self) -> None:
        """Handle the urgent inputs waiting (a fault) now. For a hook or timer that works
        through a fleet (a bridge's tick of ~6,000 samples: ~25 ms), between one part and the
        next: a fault must not wait for the rest. On the worker thread only."""
        if self._urgent:
            self._handle_urgent()

    def _handle_urgent(self) -> int:
        n = 0
        while self._urgent:
            self._guard(*self._urgent.popleft())
            n += 1
        return n

    def drain(self, until: float) -> int:
        """Handle what the channels hold (until ``until``, or an urgent input comes); how many
        samples."""
        n = 0
        for channel, convert, handler in self._channels:
            zsample = channel.try_recv()
            while zsample is not None:
                sample = convert(zsample)
                if sample is not None:
                    self._guard(handler, sample)
                n += 1
                if self._urgent or time.monotonic() >= until:
                    return n
                zsample = channel.try_recv()
        return n

    def _run_timers(self) -> float:
        now = time.monotonic()
        wait = 0.25
        for timer in self._timers:
            period, due, fn = timer
            if now >= due:
                timer[1] = max(due + period, now)
                self._guard(fn)
            wait = min(wait, max(0.0, timer[1] - now))
        return wait
