"""Every bad input of the bad-input suite, through the command line and the console's API, is
answered in words (issue 26.9): no raw JSON, no ``$.field`` paths, no Python reprs, no
tracebacks (:func:`tests.vocabulary.unplain`).

The bad inputs are the suite's own: the live matrix of ``tests/integration/test_bad_input.py``
(every key an instructor writes, with the payloads wrong for it and the ones wrong everywhere,
and the keys wrong whatever the payload) and the decoding cases of
``tests/common/test_messages_and_faults.py``, read from their modules, so a case added there is
checked here too. Each becomes the command an instructor would type (``lunaris fault inject``,
``input``, ``rail``, ``clock``; a key no command writes is the API's alone) and runs in-process
against no twin: what the tools refuse before sending must be refused (exit 1) in words. What
only the twin can refuse (a load, rail, panel, radio or rover it does not have) goes to a live
twin, and its answer, as the command prints it, must be in words too.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from collections.abc import Iterator
from typing import Any

import pytest

from common import keys
from common.messages import BadInput
from common.writes import plan_write
from lunaris import cli
from lunaris.client import humane
from tests.common import test_messages_and_faults as common_cases
from tests.integration import test_bad_input as matrix
from tests.vocabulary import unplain

pytestmark = pytest.mark.timeout(300)

NOWHERE = "tcp/127.0.0.1:9"  # nothing listens there: a command that gets that far says so at once
PLACEHOLDER = {"radio": "lander", "rail": "12V", "panel": "left", "load": "drive_motors"}


def _common_cases() -> list[tuple[str, bytes]]:
    """The bad payloads of tests/common, as (key, payload): each decoding case (payload, Struct)
    on the first key of the Struct's family, each fault case (fault path, payload) on its key."""
    out: list[tuple[str, bytes]] = []
    for name in dir(common_cases):
        func = getattr(common_cases, name)
        for mark in getattr(func, "pytestmark", []):
            if mark.name != "parametrize":
                continue
            names = [n.strip() for n in (mark.args[0].split(",") if isinstance(mark.args[0], str)
                                         else mark.args[0])]
            for row in mark.args[1]:
                case = dict(zip(names, row.values if hasattr(row, "values") else row, strict=True))
                if "payload" not in case or "reason" not in case:
                    continue  # an accepted input, or no payload
                if "typ" in case:
                    fam = next((f for f in keys.families("in") if f.payload is case["typ"]), None)
                    if fam is not None:
                        tail = "/".join(PLACEHOLDER.get(c[1:-1], c) if c.startswith("{") else c
                                        for c in fam.chunks)
                        out.append((keys.under(matrix.R, tail), case["payload"]))
                elif "path" in case:
                    out.append((keys.under(matrix.R, f"fault/{case['path']}"), case["payload"]))
    assert len(out) >= 15, f"the cases of tests/common were not found ({len(out)})"
    return out


CASES = list(dict.fromkeys(matrix.CASES + _common_cases()))


def argv_of(key: str, payload: bytes) -> list[str] | None:
    """The command an instructor types for a put of ``payload`` on ``key`` (None: no command
    writes that key; the console's API does)."""
    rover, parts = keys.split(key)
    value = os.fsdecode(payload)  # bytes that are not text reach argv as the shell passes them
    head = parts[0]
    if head == "fault":
        return ["fault", "inject", rover, "/".join(parts[1:-1]), parts[-1], *([value] if payload else [])]
    if head == "input":
        return ["input", rover, "/".join(parts[1:]), value]
    if parts[:2] == ["cmd", "rail"] and len(parts) == 3:
        return ["rail", rover, parts[2], value]
    if parts == ["clock", "control"]:
        try:
            asked = json.loads(payload)
        except ValueError:
            asked = None
        if isinstance(asked, dict) and set(asked) == {"time_scale"}:
            return ["clock", rover, "scale", str(asked["time_scale"])]
        return ["clock", rover, "scale", value]
    return None


def run(argv: list[str], *connection: str) -> tuple[int, str]:
    """``lunaris ARGV`` in this process: its exit status and everything it printed."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = cli.main([*argv, *(connection or ("--connect", NOWHERE, "--wait", "1"))])
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue()


def refused_by_the_tools(key: str, payload: bytes) -> str | None:
    """Why the tools refuse the put before sending (None: only the twin can)."""
    rover, parts = keys.split(key)
    try:
        plan_write(rover, parts, payload)
    except BadInput as exc:
        return str(exc)
    return None


def case_id(x: object) -> str:
    return x.removeprefix(f"{keys.ROOT}/") if isinstance(x, str) else repr(x)[:24]


# A key no command writes (cmd/self_destruct) is the API's alone: its words are checked below.
COMMANDS = [(k, p) for k, p in CASES if argv_of(k, p) is not None]


@pytest.mark.parametrize(("key", "payload"), COMMANDS, ids=case_id)
def test_the_command_refuses_it_in_words(key, payload):
    argv = argv_of(key, payload)
    assert argv is not None
    code, said = run(argv)
    assert said.strip(), "nothing said"
    assert unplain(said, [os.fsdecode(payload)]) == [], said
    if refused_by_the_tools(key, payload) is not None:
        assert code in (1, 2) and "No Zenoh router answered" not in said, said  # refused before sending


# What the tools let through only the twin can refuse: its words are checked live, below.
REFUSED = [(k, p) for k, p in CASES if refused_by_the_tools(k, p) is not None]


@pytest.mark.parametrize(("key", "payload"), REFUSED, ids=case_id)
def test_the_console_refuses_it_in_words(key, payload):
    reason = refused_by_the_tools(key, payload)
    assert reason is not None
    said = f"not sent: {humane(reason)}"  # the console's 422, as lunaris.console.api words it
    assert unplain(said, [payload.decode("utf-8", "replace")]) == [], said


# -- what only the twin refuses, through a live twin ---------------------------------------------


VALID = [b"", b"0.5", b"60", b'{"distance_m": 300, "angle_deg": 45}', b'{"on": true}']


def _twin_only() -> list[tuple[str, bytes]]:
    """Each key the matrix holds wrong whatever the payload, with a payload the tools accept
    for its shape (so that only the twin can refuse it), and the matrix's own such cases."""
    out = [(k, p) for k, p in matrix.CASES if refused_by_the_tools(k, p) is None]
    for key in matrix.UNKNOWN:
        payload = next((p for p in VALID if refused_by_the_tools(key, p) is None), None)
        if payload is not None:
            out.append((key, payload))
    return list(dict.fromkeys(out))


TWIN_ONLY = _twin_only()


@pytest.fixture(scope="module")
def twin(mapp_twin) -> Iterator[Any]:
    probe, _ = mapp_twin
    yield probe


def test_what_only_the_twin_refuses_is_said_in_words(twin):
    assert len(TWIN_ONLY) >= 8, TWIN_ONLY
    endpoint = twin.endpoint
    said_all = []
    for key, payload in TWIN_ONLY:
        argv = argv_of(key, payload)
        if argv is None or payload == b"{}":  # no command writes it, or asks for nothing
            continue
        if argv[0] == "rail":  # the command's own actions, on the rail the case names
            argv = [*argv[:3], "on"]
        elif argv[0] == "input" and argv[2].startswith("radio/"):
            argv = [*argv[:3], "300", "45"]
        code, said = run(argv, "--connect", endpoint)
        said_all.append(said)
        assert code in (1, 2), (argv, said)
        assert unplain(said, [os.fsdecode(payload)]) == [], said
    assert any("has no load 'no_such_load'" in s for s in said_all), said_all
    assert any("unknown rover 'no-such-rover'" in s for s in said_all), said_all
