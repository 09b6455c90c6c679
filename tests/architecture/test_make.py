"""``make run`` installs what running needs and nothing of the tests (issue 26.7), and runs the
rover, port and state folder it is given.

What each target would install is read from ``make -n`` (a dry run: nothing is installed)
against a virtual environment that does not exist yet, as on a fresh clone; the packages an
install line brings in are the closure of what it asks for, its extras included, over the
requirements pyproject.toml lists and the installed packages declare.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from tests.harness import ROOT

PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
TEST_EXTRAS = ("dev", "test-ros2")

if shutil.which("make") is None:
    pytest.skip("make is not installed", allow_module_level=True)


def dry_run(target: str, tmp_path: Path, *variables: str) -> list[str]:
    """The commands ``make -n target`` would run on a fresh clone (no virtual environment), as
    typed in a shell (not the settings of a make that runs these tests)."""
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}
    out = subprocess.run(["make", "-n", target, f"VENV={tmp_path / 'venv'}", *variables], cwd=ROOT,
                         capture_output=True, text=True, timeout=30, check=True, env=env)
    return out.stdout.splitlines()


def asked_extras(lines: list[str]) -> list[set[str]]:
    """The extras of this project each ``pip install`` line asks for (``-e .`` asks none)."""
    asked = []
    for line in lines:
        if " pip install " not in line or "--upgrade pip" in line:
            continue
        words = shlex.split(line)
        spec = words[words.index("-e") + 1]
        m = re.fullmatch(r"\.(?:\[(.*)\])?", spec)
        assert m, f"not an install of this project: {line}"
        asked.append({e.strip() for e in (m[1] or "").split(",") if e.strip()})
    return asked


def closure(extras: set[str]) -> set[str]:
    """Every package an install of this project with ``extras`` brings in (its own included)."""
    wanted = [Requirement(r) for r in PROJECT["dependencies"]]
    for extra in sorted(extras):
        wanted += [Requirement(r) for r in PROJECT["optional-dependencies"][extra]]
    found: set[str] = {canonicalize_name(PROJECT["name"])}
    while wanted:
        req = wanted.pop()
        name = canonicalize_name(req.name)
        if name == canonicalize_name(PROJECT["name"]):  # lunaris[ros2] inside an extra
            wanted += [Requirement(r) for e in req.extras
                       for r in PROJECT["optional-dependencies"][e]]
            continue
        if name in found:
            continue
        found.add(name)
        try:
            requires = metadata.requires(req.name) or []
        except metadata.PackageNotFoundError:
            continue  # not installed here (another platform's): its own name is what counts
        for r in map(Requirement, requires):
            if r.marker is None or any(r.marker.evaluate({"extra": e}) for e in (*req.extras, "")):
                wanted.append(r)
    return found


def test_make_run_installs_no_test_only_package(tmp_path):
    (run_asks,) = asked_extras(dry_run("run", tmp_path))
    (test_asks,) = asked_extras(dry_run("test", tmp_path))
    assert test_asks == set(TEST_EXTRAS)  # the tests keep their extras
    test_only = closure(set(TEST_EXTRAS)) - closure(set())
    assert {"pytest", "mypy", "selenium", "ros-rclpy"} <= test_only  # the reading works
    brought = closure(run_asks)
    assert not brought & test_only, sorted(brought & test_only)
    print(f"make run installs {len(brought)} packages; make test {len(closure(set(TEST_EXTRAS)))}")


def test_make_run_runs_the_rover_port_and_state_it_is_given(tmp_path):
    assert dry_run("run", tmp_path)[-1].endswith(
        "/lunaris up --rover config/rovers/mapp.yaml --state-dir var/state --console 127.0.0.1:8080")
    state = tmp_path / "state"
    assert dry_run("run", tmp_path, "ROVER=config/rovers/ltv.yaml", "PORT=9001", f"STATE={state}")[-1] \
        .endswith(f"/lunaris up --rover config/rovers/ltv.yaml --state-dir {state} --console 127.0.0.1:9001")
    for made in ("var/state/battery.json", "recordings/session.html"):  # what make run leaves
        ignored = subprocess.run(["git", "check-ignore", "-q", made], cwd=ROOT, timeout=30)
        assert ignored.returncode == 0, f"{made} is not git-ignored"
