"""The console's HTTP API: the twin's key space over HTTP, for the page and for users' tools.

- ``GET /api/live``: server-sent events, a snapshot then batches (:mod:`lunaris.console.live`).
- ``PUT`` / ``DELETE /api/rovers/<rover>/keys/<key>``: a write on ``lunaris/<rover>/<key>``
  (``fault/...``, ``cmd/rail/<rail>``, ``clock/control``, ``input/...``, ``control/...``),
  the body being the payload the key takes. The write is checked with the twin's own
  Structs first (:func:`common.writes.check_write`: 422 and the reason, nothing sent), then
  sent, and the answer is the twin's: 200 with the accepting event, 409 with the rejection's
  reason, 504 when nothing answered. An observer gets 403 and nothing is sent.
- ``GET /api/rovers/<rover>/snapshots``, ``/faults``, ``/journal``, ``/prediction``: the
  twin's queries; ``GET /api/catalogue``: the fault catalogue the forms are built from;
  ``GET /api/me``: who is signed in and what they may do.
"""

from __future__ import annotations

import asyncio
import json
import re
from typing import Any

import msgspec.inspect as mi
import zenoh
from starlette.requests import Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from common import keys
from common.connection import write
from common.faults import CATALOGUE, DERIVED, NAMED_COMPONENTS, NoParams
from common.messages import MAX_INPUT_BYTES, BadInput
from common.writes import check_write
from lunaris.console.auth import User
from lunaris.console.live import Hub

__all__ = ["catalogue", "humane", "routes"]

ANSWER_S = 3.0  # how long a write waits for the twin's answer
ROVER = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def humane(message: str) -> str:
    """A validation message in plain words: ``Expected `float` <= 1.0 - at `$.fraction```
    becomes ``fraction must be at most 1.0``."""
    words = {"<=": "at most", ">=": "at least", "<": "below", ">": "above"}
    m = re.fullmatch(r"Expected `\w+` (<=|>=|<|>) (\S+) - at `\$\.(\w+)`", message)
    if m:
        return f"{m.group(3)} must be {words[m.group(1)]} {m.group(2)}"
    m = re.fullmatch(r"Expected `(\w+)`, got `(\w+)` - at `\$\.(\w+)`", message)
    if m:
        kind = {"float": "a number", "int": "a whole number", "bool": "true or false",
                "str": "text"}.get(m.group(1), m.group(1))
        return f"{m.group(3)} must be {kind}, not {m.group(2)}"
    m = re.fullmatch(r"Object missing required field `(\w+)`(?: - at `\$(.*)`)?", message)
    if m:
        return f"{m.group(1)} is missing"
    m = re.fullmatch(r"Object contains unknown field `(\w+)`(?: - at `\$(.*)`)?", message)
    if m:
        return f"{m.group(1)} is not a field of this input"
    return message


def _params(struct: type) -> list[dict[str, Any]]:
    if issubclass(struct, NoParams):
        return []
    info = mi.type_info(struct)
    assert isinstance(info, mi.StructType)
    out = []
    for f in info.fields:
        t = f.type
        limits = {k: getattr(t, k) for k in ("ge", "le", "gt", "lt") if getattr(t, k, None) is not None}
        out.append({"name": f.name, "type": "number", **limits,
                    "default": None if f.default is mi.NODEFAULT else f.default})
    return out


def catalogue() -> dict[str, Any]:
    """The fault catalogue as the page builds its forms from it."""
    return {
        "components": {c: {"named": c in NAMED_COMPONENTS, "kinds": {
            k: {"description": spec.description, "params": _params(spec.params)}
            for k, spec in kinds.items()}} for c, kinds in CATALOGUE.items()},
        "derived": DERIVED,
    }


def _user(request: Request) -> User:
    return request.scope["state"]["user"]


def _answer(status: int, verdict: str, message: str, event: dict | None = None) -> JSONResponse:
    return JSONResponse({"verdict": verdict, "message": message, "event": event}, status_code=status)


async def _write(request: Request) -> Response:
    user: User = _user(request)
    hub: Hub = request.app.state.hub
    rover, tail = request.path_params["rover"], request.path_params["key"]
    if not user.may_act:
        return _answer(403, "forbidden", f"{user.name} is an observer: observers see everything "
                                         "and change nothing")
    if not ROVER.match(rover):
        return _answer(404, "invalid", f"bad rover id {rover!r}")
    body = await request.body()
    if len(body) > MAX_INPUT_BYTES:
        return _answer(413, "invalid", "the payload is too large for an input")
    deleting = request.method == "DELETE"
    try:
        checked = check_write([p for p in tail.split("/") if p], None if deleting else body)
    except BadInput as exc:
        return _answer(422, "invalid", f"not sent: {humane(str(exc))}")
    if rover not in hub.services:
        known = ", ".join(sorted(hub.services)) or "none"
        return _answer(404, "invalid", f"unknown rover {rover!r} (rovers: {known})")
    key = keys.under(rover, "/".join(p for p in tail.split("/") if p))
    answer = hub.expect(key, {checked.accepted, "rejected"})
    try:
        await asyncio.to_thread(write, request.app.state.session, key, checked.payload)
        event = await asyncio.wait_for(answer, ANSWER_S)
    except TimeoutError:
        return _answer(504, "no answer", f"no answer from the twin within {ANSWER_S:g} s to {key}: "
                                         "is the service that owns it running?")
    finally:
        hub.forget(answer)
    if event["kind"] == "rejected":
        return _answer(409, "rejected", event["message"].removeprefix("rejected: "), event)
    return _answer(200, "accepted", event["message"], event)


def _get(session: zenoh.Session, selector: str, timeout_s: float) -> tuple[list[Any], list[str]]:
    ok, errors = [], []
    for reply in session.get(selector, timeout=timeout_s):
        if reply.ok is not None:
            ok.append(json.loads(reply.ok.payload.to_bytes()))
        elif reply.err is not None:
            errors.append(reply.err.payload.to_string())
    return ok, errors


async def _query(request: Request) -> Response:
    rover, what = request.path_params["rover"], request.path_params["what"]
    if not ROVER.match(rover):
        return JSONResponse({"message": f"bad rover id {rover!r}"}, status_code=404)
    q = request.query_params
    if what == "snapshots":
        selector, timeout = keys.snapshots(rover), 5.0
    elif what == "faults":
        selector, timeout = keys.faults(rover), 5.0
    elif what == "journal":
        last = q.get("last", "200")
        if not last.isdigit():
            return JSONResponse({"message": "last: give a whole number"}, status_code=422)
        selector, timeout = f"{keys.faults_journal(rover)}?last={last}", 5.0
    elif what == "prediction":
        try:
            hours, samples = float(q.get("hours", "8")), int(q.get("samples", "1000"))
        except ValueError:
            return JSONResponse({"message": "hours and samples must be numbers"}, status_code=422)
        selector, timeout = f"lunaris/{rover}/prediction?hours={hours:g};samples={samples}", 60.0
    else:
        return JSONResponse({"message": f"no such query {what!r}"}, status_code=404)
    ok, errors = await asyncio.to_thread(_get, request.app.state.session, selector, timeout)
    if not ok:
        which = ", in a version with the prediction" if what == "prediction" else ""
        why = "; ".join(errors) or (f"nobody answered {selector} (is the service that answers it "
                                    f"running{which}?)")
        return JSONResponse({"message": why}, status_code=502 if errors else 504)
    return JSONResponse(ok[0])


async def _live(request: Request) -> Response:
    hub: Hub = request.app.state.hub
    return StreamingResponse(hub.stream(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})


async def _me(request: Request) -> Response:
    user = _user(request)
    return JSONResponse({"name": user.name, "role": user.role, "local": user.local,
                         "may_act": user.may_act, "accounts": request.app.state.accounts is not None})


async def _catalogue(request: Request) -> Response:
    return JSONResponse(request.app.state.catalogue)


def routes() -> list[Route]:
    return [
        Route("/api/me", _me),
        Route("/api/catalogue", _catalogue),
        Route("/api/live", _live),
        Route("/api/rovers/{rover}/keys/{key:path}", _write, methods=["PUT", "DELETE"]),
        Route("/api/rovers/{rover}/{what}", _query),
    ]
