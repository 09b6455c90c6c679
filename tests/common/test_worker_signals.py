"""A signal never leaves a wait of the worker (or a tool) waiting for ever.

Found: a battery service outlived its killed supervisor (tests/reliability/test_supervisor.py,
once in five full runs), deaf to SIGTERM, its main thread in an untimed ``sem_wait`` under
the worker's ``SimpleQueue.get(timeout=...)``. CPython 3.11's C queue, interrupted by a signal
whose handler (or getting the GIL back) outlasts the wait's deadline, computes a negative
timeout and then waits for ever. Here the handler is made slow on purpose (20 ms against waits
of a millisecond) so that every signal does so; each case runs in a process of its own, which
the test ends if it hangs.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from tests.harness import ROOT

pytestmark = pytest.mark.timeout(60)

SLOW_HANDLER = """
import os, queue, signal, sys, threading, time
sys.path.insert(0, {root!r})
from common.worker import Worker, wait_get

def signal_later(times=1):
    def send():
        for _ in range(times):
            time.sleep(0.2)
            os.kill(os.getpid(), signal.SIGTERM)
    threading.Thread(target=send, daemon=True).start()
"""

WORKER = SLOW_HANDLER + """
worker = Worker(lambda fn, *args: fn(*args))
worker.every(0.001, lambda: None)  # waits of a millisecond at most

def on_term(*_):
    time.sleep(0.02)  # past the wait's deadline
    worker.signalled = True

signal.signal(signal.SIGTERM, on_term)
signal_later()
worker.run()
print("stopped")
"""

TOOL_LOOP = SLOW_HANDLER + """
heard = []
signal.signal(signal.SIGTERM, lambda *_: (time.sleep(0.02), heard.append(1)))
signal_later(times=3)
q = queue.SimpleQueue()
while len(heard) < 3:
    try:
        {get}
    except queue.Empty:
        pass
print("stopped")
"""


def _run(script: str, timeout_s: float = 10.0) -> subprocess.CompletedProcess | None:
    """The script's run, or None if it still ran after ``timeout_s`` (it was ended)."""
    try:
        return subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True,
                              text=True, timeout=timeout_s, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return None


def test_a_worker_stops_on_sigterm_even_when_its_handler_outlasts_the_wait() -> None:
    done = _run(WORKER.format(root=str(ROOT)))
    assert done is not None, "the worker still waited 10 s after SIGTERM"
    assert done.returncode == 0 and done.stdout.strip() == "stopped", done.stderr


def test_a_tools_wait_on_a_queue_goes_on_after_each_signal() -> None:
    done = _run(TOOL_LOOP.format(root=str(ROOT), get="wait_get(q, 0.001)"))
    assert done is not None, "wait_get still waited 10 s after a signal"
    assert done.returncode == 0 and done.stdout.strip() == "stopped", done.stderr


def test_the_plain_queue_wait_does_hang_so_the_cases_above_can_fail() -> None:
    """What the cases above guard against, shown on the interpreter in use: if this one day
    fails (a fixed CPython), wait_get may go."""
    done = _run(TOOL_LOOP.format(root=str(ROOT), get="q.get(timeout=0.001)"), timeout_s=3.0)
    assert done is None, "the plain SimpleQueue wait no longer hangs after a slow signal handler"
