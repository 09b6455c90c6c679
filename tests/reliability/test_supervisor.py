"""Nothing doubled: services die with their supervisor, and never run twice for a rover.

Found by killing `lunaris up` with kill -9: its services lived on (their own session,
retrying forever), and the next `lunaris up` on the same port ran two of each - the
clock ticking 20 times a second, the battery drained twice.
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import lunaris.supervised as supervised_module
import lunaris.up as up_module
from common import keys
from lunaris.up import Supervisor
from testbed.supervisor import kill_up_at
from tests.harness import ALL_SERVICES, ROOT, Probe, free_endpoint, lunaris_cmd, wait_for
from tests.reliability.conftest import MAPP, R, alive

pytestmark = pytest.mark.timeout(120)


def command(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[-120:]
    except OSError:
        return "?"


def children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().split(") ", 1)[1].split()
        except (FileNotFoundError, IndexError):
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def start_up(endpoint: str, state_dir: Path) -> subprocess.Popen:
    return subprocess.Popen(
        lunaris_cmd("up", "--rover", str(MAPP), "--listen", endpoint, "--state-dir", str(state_dir),
                    "--services", ",".join(ALL_SERVICES), "--no-status"),
        cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True)


def one_clock(p: Probe, seconds: float = 2.0) -> bool:
    """One clock ticks mapp-1: at most its 10 ticks a second (a loaded machine may give
    fewer), their sequence numbers only ever rising (two clocks interleave two sequences)."""
    key = keys.clock(R)
    before = len(p.samples(key))
    time.sleep(seconds)  # a measurement window, not a synchronisation
    ticks = p.samples(key)[before:]
    seqs = [t["seq"] for t in ticks]
    return 0 < len(ticks) <= 12.5 * seconds and seqs == sorted(set(seqs))


def test_kill_9_of_up_leaves_no_orphan_and_the_next_up_runs_one_of_each(tmp_path):
    endpoint = free_endpoint()
    first = start_up(endpoint, tmp_path / "state")
    second = None
    try:
        with Probe(endpoint) as p:  # connects once the up's router is there
            p.watch(keys.clock(R))
            p.wait_services(R, ALL_SERVICES, timeout_s=60)
            services = children(first.pid)
            assert len(services) == len(ALL_SERVICES), services
            first.send_signal(signal.SIGKILL)
            first.wait(10)
            # SIGTERM from the kernel at once (PR_SET_PDEATHSIG); each then saves its state and
            # closes its session, which took over 10 s with three test workers on two cores
            # (before lunaris.supervised ended a process still there GRACE_S after)
            wait_for(lambda: not any(alive(pid) for pid in services), 30,
                     lambda: f"the services of the killed up to stop: "
                             f"{[(pid, command(pid)) for pid in services if alive(pid)]}")
        second = start_up(endpoint, tmp_path / "state")
        with Probe(endpoint) as p:
            p.watch(keys.clock(R))
            p.wait_services(R, ALL_SERVICES, timeout_s=60)
            p.wait_value(keys.clock(R))
            assert one_clock(p)  # one clock, not two
    finally:
        for proc in (first, second):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()


def test_kill_9_of_up_at_any_moment_of_its_start_leaves_no_service(tmp_path):
    """Found (issue 32): kill -9 of up at random moments of its first seconds, 64 runs: twice
    a battery service lived on for good, deaf to SIGTERM (a worker's wait that a signal broke).
    Here 10 rounds, one moment in each 0.5 s of the first 5 s (the router opening, services
    starting, connecting, claiming, serving): 10 s later none of them runs. The issue's 200
    rounds: bench/supervisor_death.py."""
    seed = random.randrange(2**32)
    rng = random.Random(seed)
    started = []
    for i in range(10):
        moment_s = (i + rng.random()) * 0.5
        round_ = kill_up_at(moment_s, MAPP, tmp_path / f"round-{i}", ALL_SERVICES)
        assert not round_.left, (f"kill -9 of up {moment_s:.2f} s after its start (seed {seed}), "
                                 f"{round_.started} processes started: still running 10 s later: "
                                 f"{round_.left}")
        started.append(round_.started)
    assert max(started) >= len(ALL_SERVICES), (f"no round killed up with all its services "
                                                f"started (processes started per round: {started})")


PARENT = """
import os, subprocess, sys
env = {**os.environ, "LUNARIS_SUPERVISOR_PID": str(os.getpid())}
child = subprocess.Popen(sys.argv[1:], env=env, stdin=subprocess.DEVNULL)  # its stdout: ours
print(child.pid, flush=True)
sys.stdin.read()  # until the test kills this process
"""

DEAF = """
import signal, time
from lunaris.supervised import follow_supervisor
follow_supervisor()
signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a loop that no longer hears: stuck
print("deaf", flush=True)
while True:
    time.sleep(1)
"""


@contextlib.contextmanager
def supervised(cmd: list[str], ready: str) -> Iterator[tuple[subprocess.Popen, int]]:
    """``cmd`` started as ``lunaris up`` starts a service, by a stand-in for ``up``: the
    stand-in and the child's pid, once the child has said ``ready``. Both ended after."""
    parent = subprocess.Popen([sys.executable, "-c", PARENT, *cmd], cwd=ROOT, text=True,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True)
    child = None
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        for line in parent.stdout:
            if ready in line:
                break
        yield parent, child
    finally:
        parent.kill()
        parent.wait(10)
        if child is not None and alive(child):
            os.kill(child, signal.SIGKILL)


def test_the_kernel_ends_a_supervised_process_at_once_when_up_is_killed():
    """The parent-death signal itself (lunaris.supervised): a router (no watch of its parent
    of its own) is gone well before the last resort's GRACE_S."""
    with supervised(lunaris_cmd("router", "--listen", free_endpoint()), "listening") as (up, child):
        up.kill()
        wait_for(lambda: not alive(child), supervised_module.GRACE_S - 1.0,
                 lambda: f"the router of the killed up to stop: {command(child)}")


def test_a_supervised_process_deaf_to_sigterm_is_ended_all_the_same():
    """The last resort (lunaris.supervised): a process stuck, SIGTERM no longer heard, ends
    GRACE_S after its supervisor."""
    with supervised([sys.executable, "-c", DEAF], "deaf") as (up, child):
        up.kill()
        wait_for(lambda: not alive(child), supervised_module.GRACE_S + 5.0,
                 lambda: f"the deaf child of the killed up to end: {command(child)}")


def test_a_second_instance_of_a_service_refuses_to_start(twin_factory, probe_solo, tmp_path):
    twin_factory([MAPP], services=("clock",))
    probe_solo.watch(keys.clock(R))
    probe_solo.wait_services(R, ("clock",))
    out = subprocess.run(
        lunaris_cmd("run", "clock", "--rover", str(MAPP), "--connect", probe_solo.endpoint,
                    "--state-dir", str(tmp_path / "other")),
        cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 3, out.stderr
    assert "another clock service already serves mapp-1" in out.stderr
    assert one_clock(probe_solo)


def test_two_instances_on_one_state_directory_are_refused(twin_factory, probe_solo):
    twin = twin_factory([MAPP], services=("clock",))
    probe_solo.wait_services(R, ("clock",))
    out = subprocess.run(
        lunaris_cmd("run", "clock", "--rover", str(MAPP), "--connect", probe_solo.endpoint,
                    "--state-dir", str(twin.state_dir)),
        cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 3 and f"holds {twin.state_dir}" in out.stderr, out.stderr


class _Exits(Supervisor):
    """A supervisor whose every service exits at once with a given status."""

    def __init__(self, code: int, tmp: Path):
        super().__init__(["bridge"], [], "tcp/127.0.0.1:1", tmp, None)
        self.code = code

    def command(self, service: str) -> list[str]:
        return [sys.executable, "-c", f"import sys; print('mapping problem'); sys.exit({self.code})"]


@pytest.mark.parametrize("code, restarted", [(2, False), (3, False), (1, True)])
def test_a_service_that_cannot_work_is_shown_failed_not_restarted(tmp_path, capsys, code, restarted):
    sup = _Exits(code, tmp_path)
    sup.start_all()
    first = sup.procs["bridge"]
    first.wait(10)
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and sup.procs["bridge"] is first:
        sup.poll()
        time.sleep(0.05)  # the supervisor's own poll period
    out = capsys.readouterr().out
    assert (sup.procs["bridge"] is not first) == restarted
    assert ("bridge" in sup.failed) == (not restarted)
    if not restarted:
        assert "FAILED" in out and "mapping problem" in out
    sup.stop_all()


def test_a_service_whose_supervisor_is_gone_before_it_starts_exits(router, tmp_path):
    """The race of the kernel's parent-death signal: a supervisor dead before the child asked
    for the signal; the child, given to another parent, checks whom it has (lunaris.supervised)."""
    env = {**os.environ, "LUNARIS_SUPERVISOR_PID": "1"}  # a parent it does not have
    proc = subprocess.Popen(lunaris_cmd("run", "clock", "--rover", str(MAPP), "--connect", router,
                                        "--state-dir", str(tmp_path)),
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and "supervisor 1 is gone (before this process started)" in out



class _Crashes(Supervisor):
    """A supervisor whose every service dies at once of the same error."""

    def __init__(self, tmp: Path):
        super().__init__(["faults"], [], "tcp/127.0.0.1:1", tmp, None)

    def command(self, service: str) -> list[str]:
        return [sys.executable, "-c", "import msgspec; msgspec.json.decode(b'{\"t_s\": 1')"]


def test_a_service_that_keeps_failing_is_shown_failed_with_its_error(tmp_path, capsys):
    """Found: a faults service with a torn journal restarted 9 times in 25 s, for ever, and
    was never shown FAILED."""
    sup = _Crashes(tmp_path)
    sup.start_all()
    try:
        wait_for(lambda: (sup.poll(), "faults" in sup.failed)[1], 30,
                 lambda: f"the faults service shown failed (restarts: {sup.restarts})", poll_s=0.05)
        assert sup.restarts["faults"] == up_module.FAILING_AFTER - 1
        assert "msgspec.DecodeError: Input data was truncated" in sup.failed["faults"]
        out = capsys.readouterr().out
        assert "faults" in out and "FAILED" in out and "not restarting it" in out
        first = sup.procs["faults"]
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:  # no longer restarted
            sup.poll()
            time.sleep(0.05)
        assert sup.procs["faults"] is first
    finally:
        sup.stop_all()


def _claim_at_once(router: str, n: int, state_dirs: list[Path]) -> list[str | None]:
    """``n`` clocks of mapp-1 on their own state dirs claim at the same moment (threads of
    one test process, each its own session); each one's AlreadyRunning message, or None."""
    from common.connection import make_config
    from common.runtime import AlreadyRunning, Runtime

    rts = [Runtime("clock", [R], make_config("client", connect=[router]), state_dirs[i])
           for i in range(n)]
    for rt in rts:
        rt.__enter__()
    barrier = threading.Barrier(n)
    outcome: list[str | None] = [None] * n

    def claim(i: int) -> None:
        barrier.wait()
        try:
            rts[i].claim()
        except AlreadyRunning as exc:
            outcome[i] = str(exc)

    threads = [threading.Thread(target=claim, args=(i,)) for i in range(n)]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
    finally:
        for rt in rts:
            rt.close()
    return outcome


def test_simultaneous_starts_leave_exactly_one_instance(router, tmp_path):
    """Found: two clocks with different state dirs both ran (20 ticks/s) in 1 of 4
    simultaneous starts: each looked for the other's token before either had declared it."""
    for round_ in range(3):
        n = 2 if round_ < 2 else 3
        outcome = _claim_at_once(router, n, [tmp_path / f"r{round_}-{i}" for i in range(n)])
        winners = [i for i, why in enumerate(outcome) if why is None]
        assert len(winners) == 1, outcome
        assert all("another clock service" in why for why in outcome if why), outcome


def test_two_clocks_started_at_once_one_exits_3(router, tmp_path):
    procs = [subprocess.Popen(lunaris_cmd("run", "clock", "--rover", str(MAPP), "--connect", router,
                                          "--state-dir", str(tmp_path / f"s{i}")),
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    try:
        with Probe(router) as p:
            p.watch(keys.clock(R))
            loser = wait_for(lambda: next((q for q in procs if q.poll() is not None), None), 30,
                             "one of the two clocks to give way")
            assert loser.returncode == 3, loser.communicate()
            assert "another clock service" in loser.communicate()[1]
            p.wait_value(keys.clock(R))
            assert one_clock(p)
    finally:
        for q in procs:
            if q.poll() is None:
                q.send_signal(signal.SIGINT)
                q.communicate(timeout=20)
