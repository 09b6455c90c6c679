"""The console is up before the twin (issue 26.7): ``lunaris console`` with no router answers
at once, its live stream says it waits for the twin at its endpoint, and it connects when the
twin comes. An address in use is said in words, with what holds it, by ``lunaris console`` and
by ``lunaris up`` before it starts anything."""

from __future__ import annotations

import http.client
import json
import os
import socket
import subprocess
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from testbed.twin import free_port
from tests.console.conftest import MAPP
from tests.console.test_server import FakeRover
from tests.harness import (
    ROOT,
    env_without_zenoh_config,
    free_endpoint,
    lunaris_cmd,
    open_router,
    stop_process,
    wait_for,
)

pytestmark = pytest.mark.timeout(120)


def _console(endpoint: str, port: int, log: Path, *extra: str,
             env: dict[str, str] | None = None) -> subprocess.Popen:
    with open(log, "ab") as out:
        return subprocess.Popen(lunaris_cmd("console", "--http", f"127.0.0.1:{port}", "--connect", endpoint,
                                            "--recordings", str(log.parent / "recordings"), *extra),
                                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=ROOT,
                                env={**env_without_zenoh_config(), **(env or {})})


def _status_as(port: int, host: str) -> tuple[int, str]:
    """A plain request to the console on 127.0.0.1 carrying ``Host: host`` (as a browser that
    reached it by that name sends); its status and body."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    try:
        conn.request("GET", "/api/about", headers={"Host": host})
        answer = conn.getresponse()
        return answer.status, answer.read().decode(errors="replace")
    finally:
        conn.close()


def _get(url: str) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


def _put(url: str, body: bytes) -> tuple[int, dict]:
    request = urllib.request.Request(url, data=body, method="PUT")
    try:
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(lunaris_cmd(*args), capture_output=True, text=True, timeout=60, cwd=ROOT,
                          env=env_without_zenoh_config())


def _messages(url: str) -> Iterator[dict]:
    with urllib.request.urlopen(url, timeout=20) as r:
        for line in r:
            if line.startswith(b"data: "):
                yield json.loads(line[6:])


def test_the_page_is_up_before_the_twin_and_says_it_waits_for_it(tmp_path):
    endpoint, port = free_endpoint(), free_port()  # no router there yet
    log = tmp_path / "console.log"
    console = _console(endpoint, port, log)
    base = f"http://127.0.0.1:{port}"
    router = rover = None
    try:
        def answers() -> bool:
            assert console.poll() is None, log.read_text()
            try:
                with urllib.request.urlopen(base + "/", timeout=1) as r:
                    return r.status == 200 and b"<html" in r.read().lower()
            except OSError:
                return False
        wait_for(answers, 30, lambda: f"the page with no twin (console said: {log.read_text()})", poll_s=0.2)
        messages = _messages(base + "/api/live")
        first = next(messages)
        assert first["type"] == "snapshot" and first["connected"] is False
        assert first["router"]["state"] == "waiting" and first["router"]["endpoint"] == endpoint
        assert first["router"]["message"].startswith(f"waiting for the twin at {endpoint}")
        status, answer = _put(base + "/api/rovers/mapp-1/keys/input/sun_angle", b"60")
        assert status == 503 and "not connected to the twin yet" in answer["message"], answer
        status, answer = _get(base + "/api/rovers/mapp-1/faults")
        assert status == 503 and "not connected to the twin yet" in answer["message"], answer
        assert _get(base + "/api/about")[1] == {"app": "lunaris console", "twin": endpoint,
                                                "connected": False, "rovers": []}
        wait_for(lambda: "waiting for the twin at" in log.read_text(), 10, "the console to say it waits")

        router = open_router(endpoint)  # the twin comes
        rover = FakeRover(endpoint)
        seen: list[dict] = []
        for m in messages:  # the router comes, then the rover (in one order or the other)
            seen.append(m)
            if {"link", "rover"} <= {"link" if x["type"] == "link" else
                                     "rover" if "mapp-1" in x.get("services", {}) else "" for x in seen}:
                break
        (up,) = [m for m in seen if m["type"] == "link"]
        assert up["connected"] is True and up["router"] == {
            "state": "connected", "endpoint": endpoint, "message": f"connected to the twin at {endpoint}"}
        wait_for(lambda: _get(base + "/api/about")[1].get("rovers") == ["mapp-1"], 10, "the rover")
        assert "connected to the twin at" in log.read_text()
    finally:
        stop_process(console, 10)
        if rover is not None:
            rover.close()
        if router is not None:
            router.close()


def test_the_names_in_lunaris_allow_host_are_the_consoles_too(tmp_path):
    """A console in a container is reached by the host's name (``http://<host>:8080/``); the
    compose files cannot give it --allow-host, so LUNARIS_ALLOW_HOST names them (issue 33)."""
    port = free_port()
    log = tmp_path / "console.log"
    console = _console(free_endpoint(), port, log, "--allow-host", "given.example",
                       env={"LUNARIS_ALLOW_HOST": "ground.lunaris.example, Ground-2.example,,"})
    try:
        def answers() -> bool:
            assert console.poll() is None, log.read_text()
            try:
                return _status_as(port, f"127.0.0.1:{port}")[0] == 200
            except OSError:
                return False
        wait_for(answers, 30, lambda: f"the console (it said: {log.read_text()})", poll_s=0.2)
        for name in ("ground.lunaris.example", "ground-2.example", "given.example"):
            status, body = _status_as(port, f"{name}:8080")
            assert status == 200, (name, body)
        status, body = _status_as(port, "elsewhere.example:8080")
        assert status == 421 and "LUNARIS_ALLOW_HOST" in body, body
    finally:
        stop_process(console, 10)


def test_the_console_gives_up_after_wait_in_words(tmp_path):
    port, endpoint = free_port(), free_endpoint()
    done = _run("console", "--http", f"127.0.0.1:{port}", "--connect", endpoint, "--wait", "1.5")
    assert done.returncode == 2, done
    assert "No Zenoh router answered" in done.stderr and "make run" in done.stderr
    assert "Traceback" not in done.stderr + done.stdout


@pytest.fixture
def held_port() -> Iterator[int]:
    """A port this test's own process listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def test_a_console_address_in_use_is_said_with_what_holds_it(held_port, tmp_path):
    done = _run("console", "--http", f"127.0.0.1:{held_port}", "--connect", free_endpoint())
    assert done.returncode == 2
    said = done.stderr
    assert (f"the console's address 127.0.0.1:{held_port} is taken by another program "
            f"(pid {os.getpid()}: ") in said
    assert "lunaris console --http 127.0.0.1:" in said and "Traceback" not in said

    # Another Lunaris console there: named as one, with the twin it serves.
    endpoint, port = free_endpoint(), free_port()
    first = _console(endpoint, port, tmp_path / "first.log")
    try:
        wait_for(lambda: _up(port) and _get(f"http://127.0.0.1:{port}/api/about")[0] == 200, 30,
                 "the first console")
        done = _run("up", "--rover", str(MAPP), "--listen", free_endpoint(), "--no-status",
                    "--state-dir", str(tmp_path / "state"), "--console", f"127.0.0.1:{port}")
        said = done.stdout + done.stderr
        assert done.returncode == 1, said
        assert (f"the console's address 127.0.0.1:{port} is taken by another Lunaris console (pid "
                f"{first.pid}: lunaris console --http 127.0.0.1:{port} --connect {endpoint}") in said
        assert f"serving the twin at {endpoint} (rovers: none yet)" in said
        assert "lunaris up --console 127.0.0.1:" in said and "make run PORT=" in said
        assert "nothing was started" in said
        assert "[up] router listening" not in said and "started (pid" not in said
    finally:
        stop_process(first, 10)


def _up(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1):
            return True
    except OSError:
        return False


def test_up_says_the_router_s_address_is_taken_before_starting_anything(tmp_path, held_port):
    endpoint = f"tcp/127.0.0.1:{held_port}"
    done = _run("up", "--rover", str(MAPP), "--listen", endpoint, "--no-status", "--state-dir",
                str(tmp_path / "state"))
    said = done.stdout + done.stderr
    assert done.returncode == 1, said
    assert f"the router's address {endpoint} is taken by another program (pid {os.getpid()}" in said
    assert "lunaris up --listen tcp/127.0.0.1:" in said and "started (pid" not in said
