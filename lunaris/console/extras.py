"""The console's longer jobs: scenarios played, sessions recorded, debrief reports drawn.

A scenario plays in the console itself, on a thread of its own, with the runner
``lunaris scenario run`` uses (:class:`lunaris.client.runner.Runner`): what it says and its
step table are shown on the page as it plays (and published on
``lunaris/<rover>/scenario/progress`` for any other tool); Stop ends it as it always ends: the
clock put back, the end marked in the journal. A recording and a report run as their own
``lunaris`` process, as an instructor would run them in a terminal, with the console's own
connection settings: ``lunaris record`` (Stop is Ctrl-C: the file is complete) and ``lunaris
report`` (an HTML debrief, drawn once per recording and kept beside it). One scenario and one
recording at a time: a second start is refused, with the reason, rather than doubled.
"""

from __future__ import annotations

import asyncio
import json
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.parse
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import zenoh
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from common.messages import SESSION_ID
from common.scenario import Scenario, ScenarioError, describe_start, load_scenario
from lunaris.client import ToolError
from lunaris.client.runner import Runner
from lunaris.console.auth import User

__all__ = ["Extras", "routes"]

# a recording's name: a plain name, never '..' nor a hidden file ('.x'): it begins with a letter or a digit
# The debrief page runs nothing and loads nothing but its own inline style and plots (data:);
# framed by the console's own Recordings view only.
REPORT_POLICY = ("default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; "
                 "form-action 'none'; frame-ancestors 'self'")
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,79}$")
NAME_WORDS = "letters, digits, '.', '_' and '-', beginning with a letter or a digit"
LINES = 400
MCAP_TYPE = "application/vnd.mcap"  # IANA's media type for MCAP


class _Job:
    """A ``lunaris`` process and what it printed."""

    def __init__(self, args: list[str], what: str):
        self.what = what
        self.started = time.time()
        self.lines: deque[str] = deque(maxlen=LINES)
        self.proc = subprocess.Popen([sys.executable, "-m", "lunaris.cli", *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
                                     bufsize=1)
        self._reader = asyncio.get_running_loop().run_in_executor(None, self._read)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
        self.proc.wait()

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        if self.running:
            self.proc.send_signal(signal.SIGINT)

    def kill(self) -> None:
        if self.running:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()


class _Play:
    """A scenario playing in the console: the runner on a thread of its own, what it said."""

    def __init__(self, runner: Runner):
        self.runner = runner
        self.started = time.time()
        self.lines: deque[str] = deque(maxlen=LINES)
        self.code: int | None = None
        self._thread = threading.Thread(target=self._play, name="scenario", daemon=True)
        self._thread.start()

    def _play(self) -> None:
        try:
            for progress in self.runner.run():
                self.lines.append(progress.line())
            self.code = self.runner.code
        except ToolError as exc:
            self.lines.append(f"cannot play: {exc}")
            self.code = exc.code
        except Exception as exc:  # the console goes on; the page says what ended the run
            self.lines.append(f"the scenario stopped on an internal error: {exc!r}")
            self.code = 2
            raise

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def stop(self) -> None:
        self.runner.stop()

    def kill(self) -> None:
        self.runner.stop()
        self._thread.join(10)


class Extras:
    def __init__(self, session: zenoh.Session | None, scenarios_dir: Path | None, recordings_dir: Path | None,
                 connection: list[str], live_rovers: Callable[[], list[str]] | None = None):
        self.session = session
        self.scenarios_dir = scenarios_dir
        self.recordings_dir = recordings_dir
        self.connection = connection
        self.live_rovers = live_rovers or (lambda: [])
        self.scenario: _Play | None = None
        self.scenario_file: str | None = None
        self.recording: _Job | None = None
        self.recording_file: Path | None = None

    def close(self) -> None:
        for job in (self.scenario, self.recording):
            if job is not None:
                job.kill()

    # -- scenarios ----------------------------------------------------------------------------

    def scenarios(self) -> list[dict[str, Any]]:
        if self.scenarios_dir is None or not self.scenarios_dir.is_dir():
            return []
        out: list[dict[str, Any]] = []
        for path in sorted(self.scenarios_dir.glob("*.yaml")):
            try:
                sc = load_scenario(path)
            except ScenarioError as exc:
                out.append({"file": path.name, "problems": exc.problems})
                continue
            out.append({"file": path.name, "name": sc.scenario.name, "description": sc.scenario.description,
                        "rover": sc.rover, "steps": len(sc.steps), "time_scale": sc.time_scale,
                        "duration_s": sc.duration_s, "start": describe_start(sc.start)})
        return out

    def play(self, file: str) -> str | None:
        """Start a scenario; the reason it cannot start, or None."""
        if self.scenario is not None and self.scenario.running:
            return f"a scenario is already playing ({self.scenario_file}): stop it first"
        if self.scenarios_dir is None or not NAME.match(file) or not (self.scenarios_dir / file).is_file():
            return f"no scenario {file!r}"
        try:
            scenario: Scenario = load_scenario(self.scenarios_dir / file)
        except ScenarioError as exc:
            return f"{file} cannot be played: {'; '.join(exc.problems)}"
        if self.session is None:
            return "the console is not connected to the twin yet: a scenario plays once it is"
        live = self.live_rovers()
        if scenario.rover not in live:
            return (f"{file} is for {scenario.rover}, which is not in this session (rovers: "
                    f"{', '.join(live) or 'none'})")
        self.scenario = _Play(Runner(self.session, scenario))
        self.scenario_file = file
        return None

    def scenario_status(self) -> dict[str, Any]:
        play = self.scenario
        if play is None:
            return {"file": None}
        status = msgspec.to_builtins(play.runner.status())
        status["finished"] = status["state"] == "ended"
        return {"file": self.scenario_file, "running": play.running,
                "exit": None if play.running else play.code, "lines": list(play.lines),
                "status": status, "started": play.started}

    # -- recordings ---------------------------------------------------------------------------

    def recordings(self) -> list[dict[str, Any]]:
        folder = self.recordings_dir
        if folder is None or not folder.is_dir():
            return []
        out = []
        for path in sorted(folder.glob("*.mcap"), key=lambda p: p.stat().st_mtime, reverse=True):
            st = path.stat()
            quoted = urllib.parse.quote(path.name)
            out.append({"name": path.name, "bytes": st.st_size, "modified": st.st_mtime,
                        "report": path.with_suffix(".html").is_file(), "sessions": _kept_sessions(path),
                        "download": f"/recordings/{quoted}", "report_url": f"/recordings/{quoted}/report",
                        "sessions_url": f"/api/recordings/{quoted}/sessions"})
        return out

    def _being_recorded(self, path: Path) -> bool:
        return (self.recording is not None and self.recording.running
                and self.recording_file is not None and self.recording_file.name == path.name)

    def mcap(self, name: str) -> tuple[Path | None, int, str]:
        """The recording ``name`` to download: (its path, 200, "") or (None, the status, why).
        Only a ``.mcap`` file right inside the recordings folder (a link that leads out of it
        is not one), and not while it is being written (it is whole once stopped)."""
        folder = self.recordings_dir
        if folder is None:
            return None, 404, "this console has no folder for recordings (lunaris console --recordings DIR)"
        stem = name.removesuffix(".mcap")
        if stem == name or not NAME.match(stem):
            return None, 404, f"no recording {name!r}: a recording is NAME.mcap, its name {NAME_WORDS}"
        path = folder / name
        if self._being_recorded(path):  # written as NAME.mcap.part until then
            return None, 409, (f"{name} is still being recorded: stop the recording first (the file "
                               "is whole, and opens in Foxglove, once stopped)")
        try:
            inside = path.resolve(strict=True).parent == folder.resolve(strict=True)
        except OSError:
            inside = False
        if not inside or not path.is_file():
            return None, 404, f"no recording {name!r} in {folder}"
        return path, 200, ""

    def record(self, name: str) -> tuple[int, str] | None:
        """Start recording to ``name``; None, or why not: (422, a name that cannot be one) or
        (409, what stands in the way: a recording running, a file of that name)."""
        stem = name.removesuffix(".mcap")
        if not NAME.match(stem):
            return 422, f"not recorded: bad name {name!r}: {NAME_WORDS}"
        if self.recording is not None and self.recording.running:
            return 409, f"already recording to {self.recording_file}: stop it first"
        if self.recordings_dir is None:
            return 409, "this console has no folder for recordings (lunaris console --recordings DIR)"
        path = self.recordings_dir / f"{stem}.mcap"
        if path.exists():
            return 409, f"{path.name} exists: choose another name"
        self.recordings_dir.mkdir(parents=True, exist_ok=True)
        self.recording = _Job(["record", str(path), *self.connection], "record")
        self.recording_file = path
        return None

    def recording_status(self) -> dict[str, Any]:
        job = self.recording
        if job is None:
            return {"file": None}
        return {"file": self.recording_file.name if self.recording_file else None,
                "running": job.running, "started": job.started, "lines": list(job.lines)[-3:]}

    async def sessions(self, name: str) -> tuple[list[dict[str, Any]] | None, int, str]:
        """The trainee sessions of recording ``name``, each ``{id, trainee, rover, start_t_s,
        end_t_s, faults}`` in the order they began (what ``lunaris report --json`` reads), kept
        beside the recording as NAME.sessions.json and read again when the recording is newer:
        (them, 200, "") or (None, the status, why)."""
        path, status, why = self.mcap(name)
        if path is None:
            return None, status, why
        kept = path.with_suffix(".sessions.json")
        if not kept.is_file() or kept.stat().st_mtime < path.stat().st_mtime:
            done = await asyncio.to_thread(subprocess.run, [sys.executable, "-m", "lunaris.cli", "report",
                                                            str(path), "--json"],
                                           capture_output=True, text=True, timeout=300)
            if done.returncode not in (0, 1):  # 1: no session in it (an empty list)
                return None, 500, (done.stderr or done.stdout).strip()
            try:
                scores = json.loads(done.stdout or "[]")
            except ValueError:
                return None, 500, f"lunaris report said what is not JSON: {done.stdout[:200]!r}"
            listed = [{"id": s.get("session", ""), "trainee": s.get("trainee"), "rover": s.get("rover", ""),
                       "start_t_s": s.get("start_t_s"), "end_t_s": s.get("end_t_s"),
                       "faults": len(s.get("faults") or [])} for s in scores if isinstance(s, dict)]
            kept.write_text(json.dumps(listed))
        try:
            return json.loads(kept.read_text()), 200, ""
        except ValueError:
            kept.unlink(missing_ok=True)
            return None, 500, f"{kept.name} was damaged: it is read again on the next ask"

    async def report(self, name: str, session: str | None = None) -> tuple[Path | None, int, str]:
        """The debrief report of recording ``name``, of its last session or of ``session``
        (each trainee's: the report links the recording's others), drawn once, again when the
        recording is newer: (its path, 200, "") or (None, the status, why)."""
        path, status, why = self.mcap(name)
        if path is None:
            return None, status, why
        if session is not None and not SESSION_ID.match(session):
            return None, 422, f"{session!r} is no session id (the UTC time it began, YYYYMMDD-HHMMSS)"
        out = path.with_suffix(".html" if session is None else f".{session}.html")
        picked = [] if session is None else ["--session", session]
        if not out.is_file() or out.stat().st_mtime < path.stat().st_mtime:
            done = await asyncio.to_thread(subprocess.run, [sys.executable, "-m", "lunaris.cli", "report",
                                                            str(path), "-o", str(out), *picked],
                                           capture_output=True, text=True, timeout=300)
            if done.returncode != 0:  # 2: what was asked is not in the recording (a session)
                return None, 404 if done.returncode == 2 else 500, (done.stderr or done.stdout).strip()
        return out, 200, ""


def _kept_sessions(path: Path) -> list[dict[str, Any]] | None:
    """The sessions of a recording as read the last time (NAME.sessions.json), or None while
    they are not read (or the recording is newer)."""
    kept = path.with_suffix(".sessions.json")
    try:
        if kept.stat().st_mtime < path.stat().st_mtime:
            return None
        listed = json.loads(kept.read_text())
    except (OSError, ValueError):
        return None
    return listed if isinstance(listed, list) else None


def _forbidden(user: User) -> JSONResponse:
    return JSONResponse({"verdict": "forbidden", "message": f"{user.name} is an observer: observers "
                         "see everything and change nothing"}, status_code=403)


async def _body(request: Request) -> dict[str, Any]:
    try:
        data = json.loads(await request.body() or b"{}")
    except ValueError:
        return {}
    return data if isinstance(data, dict) else {}


async def _scenarios(request: Request) -> Response:
    ex: Extras = request.app.state.extras
    if request.method == "GET":
        return JSONResponse({"scenarios": await asyncio.to_thread(ex.scenarios),
                             "playing": ex.scenario_status()})
    user: User = request.scope["state"]["user"]
    if not user.may_act:
        return _forbidden(user)
    body = await _body(request)
    if body.get("action") == "stop":
        if ex.scenario is None or not ex.scenario.running:
            return JSONResponse({"verdict": "rejected", "message": "no scenario is playing"}, status_code=409)
        ex.scenario.stop()
        return JSONResponse({"verdict": "accepted", "message": "stopping the scenario"})
    why = ex.play(str(body.get("file", "")))
    if why:
        return JSONResponse({"verdict": "rejected", "message": why}, status_code=409)
    return JSONResponse({"verdict": "accepted", "message": f"playing {body.get('file')}"})


async def _recordings(request: Request) -> Response:
    ex: Extras = request.app.state.extras
    if request.method == "GET":
        listed = await asyncio.to_thread(ex.recordings)
        for x in listed:
            if x["sessions"] is not None:
                x["sessions"] = _noted(request, x["sessions"])
        return JSONResponse({"recordings": listed,
                             "recording": ex.recording_status(),
                             "folder": str(ex.recordings_dir) if ex.recordings_dir else None})
    user: User = request.scope["state"]["user"]
    if not user.may_act:
        return _forbidden(user)
    body = await _body(request)
    if body.get("action") == "stop":
        if ex.recording is None or not ex.recording.running:
            return JSONResponse({"verdict": "rejected", "message": "nothing is being recorded"},
                                status_code=409)
        ex.recording.stop()
        return JSONResponse({"verdict": "accepted", "message": "recording stopped"})
    refused = ex.record(str(body.get("name", "")))
    if refused:
        status, why = refused
        return JSONResponse({"verdict": "invalid" if status == 422 else "rejected", "message": why},
                            status_code=status)
    return JSONResponse({"verdict": "accepted", "message": f"recording to {ex.recording_file}"})


async def _report(request: Request) -> Response:
    out, status, why = await request.app.state.extras.report(request.path_params["name"],
                                                              request.query_params.get("session"))
    if out is None:
        return JSONResponse({"message": why}, status_code=status)
    return FileResponse(out, media_type="text/html", headers={"Content-Security-Policy": REPORT_POLICY})


async def _recording_sessions(request: Request) -> Response:
    """The trainee sessions a recording holds (observers too: it is reading)."""
    listed, status, why = await request.app.state.extras.sessions(request.path_params["name"])
    if listed is None:
        return JSONResponse({"message": why}, status_code=status)
    return JSONResponse({"sessions": _noted(request, listed)})


def _noted(request: Request, listed: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A recording's sessions with the console's notes laid over (void, renamed), rover by rover."""
    notes = request.app.state.session_notes
    return [notes.apply(s.get("rover", ""), [s])[0] for s in listed]


async def _download(request: Request) -> Response:
    """A recording as a file to save (observers too: it is reading)."""
    name = request.path_params["name"]
    path, status, why = request.app.state.extras.mcap(name)
    if path is None:
        return JSONResponse({"message": why}, status_code=status)
    return FileResponse(path, media_type=MCAP_TYPE, filename=path.name,
                        headers={"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff"})


def routes() -> list[Route]:
    return [
        Route("/api/scenarios", _scenarios, methods=["GET", "POST"]),
        Route("/api/recordings", _recordings, methods=["GET", "POST"]),
        Route("/api/recordings/{name}/sessions", _recording_sessions),
        Route("/recordings/{name}/report", _report),
        Route("/recordings/{name}", _download),
    ]
