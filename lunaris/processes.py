"""Lunaris in processes: the command lines that start it, and the stopping of what was started.

One place for what ``lunaris up`` (its :class:`~lunaris.up.Supervisor`), the tests' harness
and the benchmarks (:mod:`testbed`) all do with Lunaris processes:

- :func:`lunaris_cmd`: ``python -m lunaris.cli ARGS`` with this interpreter (so a test runs the
  code of its own tree, from the working directory it gives);
- :func:`run_args`: the ``lunaris run`` arguments of one service for some rovers;
- :func:`start_router_process`: ``lunaris router`` in a process of its own, once it listens;
- :func:`stop_process`, :func:`stop_processes`: SIGINT (what Ctrl-C sends, so each process
  closes its session and saves its state), then SIGKILL for one that does not go in time;
- :func:`wait_for`: a condition polled until a deadline, failing in words: never a fixed sleep.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["SOURCE", "lunaris_cmd", "quiet_stdout", "run_args", "start_router_process", "stop_process",
           "stop_processes", "wait_for"]

SOURCE = Path(__file__).resolve().parents[1]  # the folder this lunaris is imported from


def lunaris_cmd(*args: str) -> list[str]:
    """``lunaris ARGS`` as this interpreter runs it: ``python -m lunaris.cli ARGS``."""
    return [sys.executable, "-m", "lunaris.cli", *args]


def run_args(service: str, rover_files: Iterable[str | Path], state_dir: str | Path, *,
             connect: str | None = None, config: str | Path | None = None,
             seed: int | None = None, extra: Sequence[str] = ()) -> list[str]:
    """The arguments of ``lunaris run`` for ``service`` serving the rovers of ``rover_files``:
    connected to ``connect`` and/or with the Zenoh client file ``config``, its state in
    ``state_dir``. ``service`` may be ``kind-k`` (``bridge-2``): the k-th process of that kind,
    whose own arguments (``--shard 2/3``) come in ``extra``."""
    args = ["run", service.split("-")[0], "--state-dir", str(state_dir)]
    if config is not None:
        args += ["--config", str(config)]
    if connect is not None:
        args += ["--connect", connect]
    for f in rover_files:
        args += ["--rover", str(f)]
    if seed is not None:
        args += ["--seed", str(seed)]
    return [*args, *extra]


def wait_for(predicate: Callable[[], Any], timeout_s: float = 10.0,
             what: str | Callable[[], str] = "condition", poll_s: float = 0.01) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail with ``what`` on timeout
    (a callable is asked only then, so it can describe the last state seen)."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for "
                                 f"{what() if callable(what) else what}")
        time.sleep(poll_s)


def stop_process(proc: subprocess.Popen, timeout_s: float = 5.0) -> None:
    """SIGINT (what Ctrl-C sends), then kill if it does not go."""
    stop_processes([proc], timeout_s)


def stop_processes(procs: Iterable[subprocess.Popen], timeout_s: float = 5.0) -> None:
    """SIGINT to every process still running, all at once; then each that has not gone by
    the common deadline ``timeout_s`` later is killed."""
    procs = list(procs)
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + timeout_s
    for proc in procs:
        try:
            proc.wait(max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def start_router_process(endpoint: str, log: Path, cwd: str | Path = SOURCE,
                         timeout_s: float = 30.0) -> subprocess.Popen:
    """``lunaris router`` on ``endpoint`` in a process of its own, its output in ``log``;
    returned once it listens (and stopped again if it never does). It runs in ``cwd``, by
    default the folder this lunaris comes from, so it is the same code."""
    with log.open("wb") as out:
        proc = subprocess.Popen(lunaris_cmd("router", "--listen", endpoint), cwd=cwd,
                                stdout=out, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: b"listening" in log.read_bytes() or proc.poll() is not None, timeout_s,
                 "the router")
        if proc.poll() is not None:
            raise AssertionError(f"the router stopped (exit {proc.returncode}): "
                                 f"{log.read_text(errors='replace')[-2000:]}")
    except BaseException:
        stop_process(proc)
        raise
    return proc


def quiet_stdout() -> None:
    """Point stdout at /dev/null: its reader has gone (``| head``), and the interpreter's last
    flush must not fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    finally:
        os.close(devnull)
