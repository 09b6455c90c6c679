"""``lunaris console`` as an instructor runs it, in its own process on a free loopback port:
what the console's tests and ``bench/reliability_console.py`` start."""

from __future__ import annotations

import json
import subprocess
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from testbed.twin import ROOT, env_without_zenoh_config, free_port, lunaris_cmd, wait_for

__all__ = ["Console", "start_console"]


@dataclass
class Console:
    url: str
    proc: subprocess.Popen
    log: Path

    @property
    def port(self) -> int:
        return int(self.url.rsplit(":", 1)[1])

    def why_down(self) -> str:
        """Why the console does not answer, in words: its exit status and its log's last lines
        (a test that finds its port refused says this rather than 'connection refused')."""
        status = self.proc.poll()
        tail = "\n".join(self.log.read_text(errors="replace").splitlines()[-30:]) if self.log.exists() else ""
        return (f"the console at {self.url} does not answer: "
                + ("it is still running" if status is None else f"it exited with status {status}")
                + f"; its log ({self.log}) ends:\n{tail}")

    def get(self, path: str) -> tuple[int, dict]:
        try:
            with urllib.request.urlopen(self.url + path, timeout=5) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"{}")


def start_console(endpoint: str, folder: Path, *extra: str) -> Console:
    """``lunaris console`` on a free loopback port, its recordings in ``folder/recordings``
    and its log in ``folder``; returns once it answers."""
    port = free_port()
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / f"console-{port}.log"
    with open(log, "ab") as out:
        proc = subprocess.Popen(lunaris_cmd("console", "--http", f"127.0.0.1:{port}", "--connect", endpoint,
                                            "--recordings", str(folder / "recordings"), *extra),
                                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=ROOT,
                                env=env_without_zenoh_config())
    c = Console(f"http://127.0.0.1:{port}", proc, log)

    def up() -> bool:
        assert proc.poll() is None, log.read_text()
        try:
            urllib.request.urlopen(c.url + "/favicon.ico", timeout=1)
            return True
        except OSError:
            return False
    wait_for(up, 30, "the console to answer", poll_s=0.2)
    return c
