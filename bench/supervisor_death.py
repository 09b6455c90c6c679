"""A supervisor's death: kill -9 of ``lunaris up`` at a random moment of its first 8 s, N times.

SPEC §13e: a service never outlives its supervisor. Issue 32's adversary: kill -9 of ``up``
at random moments of its first seconds, 64 runs, left a battery service running for good
twice. Each round here (testbed/supervisor.py): ``lunaris up`` with every service for the
MAPP (config/rovers/mapp.yaml, its drive included) on a free 127.0.0.1 port and a state folder
of its own, SIGKILL after a moment drawn uniformly from [0, 8) s, then the processes given
that folder polled until none is left or 10 s have passed. Whatever is left is counted, then
ended by its pid.

Printed: per round, the moment, the processes up had started by then and those left;
at the end how many services were left running 10 s later, over how many rounds, and the
slowest to go. A figure, never an assertion.
Run: `.venv/bin/python bench/supervisor_death.py [N]` (default 200: about 20 minutes).
"""

from __future__ import annotations

import random
import sys
import tempfile
import time
from pathlib import Path

from benchlib import ROOT, machine

from lunaris.run import SERVICES
from testbed.supervisor import kill_up_at

MAPP = ROOT / "config" / "rovers" / "mapp.yaml"
FIRST_S = 8.0  # the kill falls in up's first FIRST_S [s]
SETTLE_S = 10.0  # what is still running this long after the kill is counted [s]


def main(rounds: int) -> None:
    seed = random.randrange(2**32)
    rng = random.Random(seed)
    print(f"kill -9 of lunaris up, {rounds} rounds, moments uniform in [0, {FIRST_S:g}) s "
          f"(seed {seed}); {machine()}", flush=True)
    left_total, rounds_left, slowest = 0, 0, 0.0
    with tempfile.TemporaryDirectory(prefix="lunaris-death-") as tmp:
        for i in range(rounds):
            moment_s = rng.uniform(0.0, FIRST_S)
            start = time.monotonic()
            r = kill_up_at(moment_s, MAPP, Path(tmp) / f"round-{i}", SERVICES, settle_s=SETTLE_S)
            gone_s = time.monotonic() - start - moment_s  # the kill to the last one gone (or 10 s)
            slowest = max(slowest, gone_s)
            left_total += len(r.left)
            rounds_left += bool(r.left)
            print(f"round {i + 1:3d}: kill at {moment_s:4.2f} s, {r.started} started, "
                  f"{len(r.left)} left, all gone within {gone_s:4.2f} s"
                  + "".join(f"\n    left: {pid} {cmd}" for pid, cmd in r.left.items()), flush=True)
    print(f"services left running {SETTLE_S:g} s after kill -9 of up: {left_total} in "
          f"{rounds_left} of {rounds} rounds; the slowest round was clear {slowest:.2f} s after "
          "its kill", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
