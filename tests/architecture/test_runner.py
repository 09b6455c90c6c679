"""make test's runner (tools/run_tests.py): a failed test is run once more on its own, the run
passes only if it passes then, and every such test is named FLAKY at the end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

RUNNER = Path(__file__).resolve().parents[2] / "tools" / "run_tests.py"

FLAKY_ONCE = '''
import os
def test_fails_the_first_time_only():
    flag = os.path.join(os.path.dirname(__file__), "ran")
    if not os.path.exists(flag):
        open(flag, "w").close()
        raise AssertionError("the first time")
def test_passes():
    pass
'''
ALWAYS_FAILS = '''
def test_always_fails():
    raise AssertionError("every time")
'''


def run(folder: Path, *files: tuple[str, str]) -> subprocess.CompletedProcess:
    for name, text in files:
        (folder / name).write_text(text)
    # (--rootdir: without a configuration file pytest roots the node ids at the common folder
    # of the tests and the runner's, /tmp for a clone in /tmp: the ids then named that path)
    return subprocess.run([sys.executable, str(RUNNER), "--", str(folder), "-q", "-p", "no:randomly",
                           "--rootdir", str(folder)], capture_output=True, text=True, timeout=120)


def test_a_test_that_fails_once_is_run_again_passes_and_is_named_flaky(tmp_path):
    done = run(tmp_path, ("test_once.py", FLAKY_ONCE))
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert ("FLAKY: test_once.py::test_fails_the_first_time_only (failed in the whole run, passed run "
            "again on its own)") in lines
    assert lines[-1] == "tests: 2 passed, 0 failed, 0 skipped"


def test_a_test_that_fails_again_on_its_own_fails_the_run(tmp_path):
    done = run(tmp_path, ("test_once.py", FLAKY_ONCE), ("test_always.py", ALWAYS_FAILS))
    assert done.returncode == 1, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert "FAILED: test_always.py::test_always_fails" in lines
    assert any(line.startswith("FLAKY: test_once.py::") for line in lines)
    assert lines[-1] == "tests: 2 passed, 1 failed, 0 skipped"


def test_more_failures_than_the_reruns_allowed_is_a_broken_build(tmp_path):
    (tmp_path / "test_many.py").write_text("import pytest\n@pytest.mark.parametrize('i', range(3))\n"
                                           "def test_f(i):\n    raise AssertionError(i)\n")
    done = subprocess.run([sys.executable, str(RUNNER), "--max-reruns", "2", "--", str(tmp_path), "-q",
                           "--rootdir", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "3 tests failed, more than 2: not a flake but a broken build" in done.stdout
    assert "running again" not in done.stdout


def test_a_test_of_a_group_is_run_again_with_the_groups_mark_known(tmp_path):
    """Found in a full run: the rerun disabled pytest-xdist, whose ``xdist_group`` mark (which
    tests/conftest.py gives the tests of a module sharing a twin) was then unknown, and every
    such test failed again at collection, however well it would have run."""
    (tmp_path / "test_grouped.py").write_text(
        "import os, pytest\n@pytest.mark.xdist_group('shared')\ndef test_once():\n"
        "    flag = os.path.join(os.path.dirname(__file__), 'ran')\n"
        "    if not os.path.exists(flag):\n        open(flag, 'w').close()\n        raise AssertionError\n")
    (tmp_path / "pytest.ini").write_text("[pytest]\naddopts = --strict-markers\n")  # as ours has
    done = subprocess.run([sys.executable, str(RUNNER), "--", str(tmp_path), "-q"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[-1] == "tests: 1 passed, 0 failed, 0 skipped"
