"""``make test``'s runner: the whole suite once, then each test that failed once more on its
own; the run passes only if every such test passes then, and each is named ``FLAKY: <node id>``
at the end (CPython's ``regrtest --rerun``, STYLE 15), so one timing accident cannot throw a
submission away and no flake goes unseen.

    python tools/run_tests.py [--since EPOCH_S] [--max-reruns N] -- PYTEST_ARGS...

The first run's outcomes come from the plugin ``tools/pytest_outcomes.py`` (one line per report,
written by pytest's controller). Coverage is judged here, once, from the first
run's combined data (``coverage report``'s ``fail_under``), not by pytest-cov, so a failed test
and a low total are told apart. More than ``--max-reruns`` failures is not a flake but a broken
build: nothing is run again. The last line is the plain count, ``tests: N passed, N failed``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the repository's root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tools import pytest_outcomes  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RERUN_TIMEOUT_S = 600  # one test alone, its twin included, however slow the machine


def read_outcomes(path: Path) -> tuple[Path, dict[str, str]]:
    """The root the node ids are relative to, and node id -> ``passed``, ``failed`` or
    ``skipped``: a failure in any phase wins."""
    root, outcomes = ROOT, {}
    if not path.exists():
        return root, outcomes
    for line in path.read_text(encoding="utf-8").splitlines():
        outcome, _, nodeid = line.partition(" ")
        if outcome == "rootdir":
            root = Path(nodeid)
        elif nodeid and (outcome == "failed" or outcomes.get(nodeid) != "failed"):
            outcomes[nodeid] = outcome
    return root, outcomes


def rerun(pytest: list[str], root: Path, nodeid: str) -> bool:
    """Whether ``nodeid`` passes, run alone in a pytest of its own (no workers, no coverage)."""
    # (-n 0: pytest-xdist loaded, its marks known, no workers; -p no:xdist failed every module
    # whose tests it groups at collection, 'xdist_group' not found)
    cmd = [*pytest, nodeid, "-p", "no:cacheprovider", "-n", "0", "--no-cov", "-q", "-rfE"]
    print(f"\n--- running again on its own: {nodeid}", flush=True)
    t0 = time.monotonic()
    try:
        rc = subprocess.run(cmd, cwd=root, timeout=RERUN_TIMEOUT_S).returncode
    except subprocess.TimeoutExpired:
        print(f"--- {nodeid}: still running after {RERUN_TIMEOUT_S} s, counted as failed", flush=True)
        return False
    print(f"--- {nodeid}: {'passed' if rc == 0 else 'failed'} alone in {time.monotonic() - t0:.1f} s",
          flush=True)
    return rc == 0


def coverage_ok(python: str) -> bool:
    """The first run's total against the configured floor (``coverage report`` exits 2 below
    it); the table itself pytest-cov printed."""
    done = subprocess.run([python, "-m", "coverage", "report", "--format=total"], cwd=ROOT,
                          capture_output=True, text=True)
    total = done.stdout.strip() or "unknown"
    if done.returncode == 0:
        print(f"coverage: {total} % (the floor is met)")
        return True
    print(f"coverage: {total} % is below the floor of pyproject.toml [tool.coverage.report] "
          f"fail_under{': ' + done.stderr.strip() if done.stderr.strip() else ''}")
    return False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--since", type=float, default=time.time(),
                        help="the epoch second make test began (for the time it took)")
    parser.add_argument("--max-reruns", type=int, default=10)
    parser.add_argument("--coverage", action="store_true", help="judge the first run's coverage")
    parser.add_argument("pytest_args", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    pytest_args = [a for a in args.pytest_args if a != "--"]
    python = sys.executable
    pytest = [python, "-m", "pytest"]

    with tempfile.TemporaryDirectory(prefix="lunaris-tests-") as tmp:
        outcomes_file, starts_file = Path(tmp) / "outcomes", Path(tmp) / "starts"
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_XDIST_")}  # run inside one
        env |= {pytest_outcomes.ENV: str(outcomes_file),
               "LUNARIS_COUNT_STARTS": str(starts_file)}
        rc = subprocess.run([*pytest, "-p", "tools.pytest_outcomes", *pytest_args], cwd=ROOT,
                            env=env).returncode
        root, outcomes = read_outcomes(outcomes_file)
        lines = starts_file.read_text(encoding="utf-8").splitlines() if starts_file.exists() else []
        starts = [line.split(" ")[0] for line in lines]
        by_module: dict[str, int] = {}
        for line in lines:
            module = line.partition(" ")[2].split("::")[0] or "(no test)"
            by_module[module] = by_module.get(module, 0) + 1

    failed = [n for n, o in outcomes.items() if o == "failed"]
    status = 0
    flaky: list[str] = []
    still: list[str] = []
    if rc not in (0, 1):
        print(f"\npytest stopped with exit status {rc} (not a test's failure: an interruption, an "
              "internal or usage error, or no test collected); nothing is run again")
        status = rc
    elif rc == 1 and not failed:
        print("\npytest failed with no failed test on record: see its output above")
        status = 1
    elif len(failed) > args.max_reruns:
        print(f"\n{len(failed)} tests failed, more than {args.max_reruns}: not a flake but a broken "
              "build; nothing is run again")
        still = failed
        status = 1
    else:
        for nodeid in failed:
            (flaky if rerun(pytest, root, nodeid) else still).append(nodeid)
        if still:
            status = 1
    if args.coverage and status == 0 and not coverage_ok(python):
        status = 1

    took = int(time.time() - args.since)
    print(f"\nmake test took {took // 60} min {took % 60} s ({took} s)")
    kinds = ", ".join(f"{s} {starts.count(s)}" for s in sorted(set(starts), key=starts.count, reverse=True))
    print(f"service processes started by the whole run: {len(starts)}{' (' + kinds + ')' if kinds else ''}")
    most = sorted(by_module.items(), key=lambda kv: -kv[1])[:8]
    if most:
        print("  the most by test module: " + ", ".join(f"{m} {n}" for m, n in most))
    for nodeid in flaky:
        print(f"FLAKY: {nodeid} (failed in the whole run, passed run again on its own)")
    for nodeid in still:
        print(f"FAILED: {nodeid}")
    passed = sum(1 for o in outcomes.values() if o == "passed") + len(flaky)
    skipped = sum(1 for o in outcomes.values() if o == "skipped")
    print(f"tests: {passed} passed, {len(failed) - len(flaky)} failed, {skipped} skipped")
    return status


if __name__ == "__main__":
    sys.exit(main())
