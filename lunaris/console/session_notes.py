"""The console's own notes on trainee sessions: a session voided (a retry, a false start) or
renamed (a trainee's name mistyped), for the day's list and the debrief's choice of trainee.

The twin's journal is the record of what happened and is never changed: a session voided or
renamed here is still in the journal, in the recordings and in ``lunaris session list``, under
the name it began with. The console keeps its notes in one file beside its recordings
(``<recordings>/session-notes.json``: ``{rover: {session id: {"void": bool, "trainee": name,
"by": user, "at": wall time}}}``), written whole each time (a temporary file renamed over it),
and lays them over what it lists: the sessions of a rover (``GET
/api/rovers/<rover>/sessions``) and of a recording (``GET /api/recordings/<name>/sessions``),
each with ``void``, and ``trainee`` as renamed beside ``journal_trainee`` as it began. The
debrief report itself (``lunaris report``) names the trainee as the journal does.

``POST /api/rovers/<rover>/sessions/<id>`` ``{"action": "void" | "restore" | "rename",
"trainee": "<name>"}``: instructors only.
"""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path
from typing import Any

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from common.messages import SESSION_ID, trainee_problem
from lunaris.console.api import ROVER
from lunaris.console.auth import User

__all__ = ["FILE", "SessionNotes", "routes"]

FILE = "session-notes.json"
ACTIONS = ("void", "restore", "rename")


class SessionNotes:
    """The notes of a console, in ``folder`` (None: the console has no folder, and takes none)."""

    def __init__(self, folder: Path | None):
        self.path = None if folder is None else folder / FILE
        self._lock = threading.Lock()

    def read(self) -> dict[str, dict[str, dict[str, Any]]]:
        if self.path is None:
            return {}
        try:
            notes = json.loads(self.path.read_text())
        except FileNotFoundError:
            return {}
        except ValueError as exc:
            raise ValueError(f"{self.path} is damaged ({exc}): move it away to start the notes "
                             "again") from None
        return notes if isinstance(notes, dict) else {}

    def note(self, rover: str, session: str, action: str, trainee: str | None, by: str) -> dict[str, Any]:
        """Void, restore or rename a session; its note as it is now. ValueError: what is wrong."""
        if self.path is None:
            raise ValueError("this console has no folder to keep notes in (lunaris console --recordings DIR)")
        if not SESSION_ID.match(session):
            raise ValueError(f"{session!r} is no session id (the UTC time it began, YYYYMMDD-HHMMSS)")
        if action not in ACTIONS:
            raise ValueError(f"action: one of {', '.join(ACTIONS)}, not {action!r}")
        if action == "rename":
            why = trainee_problem(trainee or "")
            if why:
                raise ValueError(f"not renamed: {why}")
        with self._lock:
            notes = self.read()
            note = notes.setdefault(rover, {}).setdefault(session, {})
            if action == "rename":
                note["trainee"] = trainee
            else:
                note["void"] = action == "void"
            note.update(by=by, at=time.time())
            self.path.parent.mkdir(parents=True, exist_ok=True)
            part = self.path.with_suffix(".part")
            part.write_text(json.dumps(notes, indent=1, ensure_ascii=False))
            os.replace(part, self.path)
            return dict(note)

    def apply(self, rover: str, sessions: list[dict[str, Any]], key: str = "id") -> list[dict[str, Any]]:
        """``sessions`` (each with its id under ``key`` and its ``trainee``) with the notes laid
        over: ``void`` on each, ``trainee`` as renamed and ``journal_trainee`` as it began."""
        try:
            notes = self.read().get(rover, {})
        except ValueError:
            notes = {}
        out = []
        for s in sessions:
            note = notes.get(str(s.get(key, "")), {})
            s = {**s, "void": bool(note.get("void", False)), "journal_trainee": s.get("trainee")}
            if note.get("trainee"):
                s["trainee"] = note["trainee"]
            out.append(s)
        return out


async def _note(request: Request) -> Response:
    user: User = request.scope["state"]["user"]
    if not user.may_act:
        return JSONResponse({"verdict": "forbidden", "message": f"{user.name} is an observer: observers "
                             "see everything and change nothing"}, status_code=403)
    try:
        body = json.loads(await request.body() or b"{}")
    except ValueError:
        body = None
    if not isinstance(body, dict):
        return JSONResponse({"verdict": "invalid", "message": "give a JSON object: {\"action\": ...}"},
                            status_code=422)
    rover, session = request.path_params["rover"], request.path_params["session"]
    if not ROVER.match(rover):
        return JSONResponse({"verdict": "invalid", "message": f"bad rover id {rover!r}"}, status_code=404)
    action, trainee = str(body.get("action", "")), body.get("trainee")
    notes: SessionNotes = request.app.state.session_notes
    try:
        note = notes.note(rover, session, action, trainee if isinstance(trainee, str) else None, user.name)
    except ValueError as exc:
        return JSONResponse({"verdict": "invalid", "message": str(exc)}, status_code=422)
    said = {"void": f"session {session} of {rover} voided: left out of the day's list and the debrief's "
                    "choice (still in the journal and the recordings)",
            "restore": f"session {session} of {rover} back in the day's list",
            "rename": f"session {session} of {rover} renamed {trainee} (the journal keeps the name it "
                      "began with)"}
    return JSONResponse({"verdict": "accepted", "message": said[action], "note": note})


def routes() -> list[Route]:
    return [Route("/api/rovers/{rover}/sessions/{session}", _note, methods=["POST"])]
