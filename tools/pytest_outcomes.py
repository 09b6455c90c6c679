"""A pytest plugin of tools/run_tests.py: each test report's outcome and node id, a line in the
file ``LUNARIS_TEST_OUTCOMES`` names, written by pytest's controller only (a pytest-xdist
worker's reports reach it), from which the runner runs the failed tests again."""

from __future__ import annotations

import os

import pytest

ENV = "LUNARIS_TEST_OUTCOMES"


def pytest_configure(config: pytest.Config) -> None:
    """The root the node ids are relative to, first: the runner runs them again from there."""
    path = os.environ.get(ENV)
    if path and not os.environ.get("PYTEST_XDIST_WORKER"):
        with open(path, "a", encoding="utf-8") as f:
            f.write(f"rootdir {config.rootpath}\n")


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    path = os.environ.get(ENV)
    if not path or os.environ.get("PYTEST_XDIST_WORKER"):
        return
    if report.failed:
        outcome = "failed"
    elif report.skipped:
        outcome = "skipped"
    elif report.when == "call":
        outcome = "passed"
    else:
        return
    with open(path, "a", encoding="utf-8") as f:
        f.write(f"{outcome} {report.nodeid}\n")
