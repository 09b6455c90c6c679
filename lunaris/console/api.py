"""The console's HTTP API: the twin's key space over HTTP, for the page and for users' tools.

- ``GET /api/live``: server-sent events, a snapshot then batches (:mod:`lunaris.console.live`).
- ``PUT`` / ``DELETE /api/rovers/<rover>/keys/<key>``: a write on ``lunaris/<rover>/<key>``
  (``fault/...``, ``cmd/rail/<rail>``, ``clock/control``, ``input/...``, ``control/...``),
  the body being the payload the key takes. The write is planned and checked with the twin's
  own Structs first (:func:`common.writes.plan_write`: 422 and the reason in words, nothing
  sent; a wildcard key, a huge number or a lone surrogate included), then sent by the client's
  writer (:class:`lunaris.client.Writer`), and the answer is the twin's: 200 with the accepting
  event, 409 with the rejection's reason, 503 "not applied: ..." when the service that owns the
  key is known to be out of reach (its liveliness gone, the rover's link lost), 504 "no answer
  within 3 s: not applied ..." when nothing answered. An observer gets 403 and nothing is sent.
  Every answer is ``{"verdict", "message", "event"}``; a bad request is always a 4xx in words.
- ``GET /api/rovers/<rover>/snapshots``, ``/faults``, ``/journal`` (``?last=N``,
  ``?session=<id>|all``: the running session's by default), ``/sessions`` (the trainee
  sessions, SPEC §12c), ``/prediction``: the twin's queries (``faults`` with an owner that did
  not answer: 502, the faults listed and ``missing``, the owners' absence in words);
  ``GET /api/catalogue``: the fault catalogue the forms are built from; ``GET /api/me``: who
  is signed in and what they may do.
- ``GET /api/rovers/<rover>/crew``: what the crew's dashboard shows of the rover now (SPEC
  §12b), rendered from the twin's values as the bridge renders them
  (:func:`services.bridge.crew_view`): its ``/diagnostics`` statuses, every topic's message
  and the crew's controls; 404 for a rover the console has not heard of.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import time
from typing import Any

import zenoh
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from common import keys
from common.faults import CATALOGUE, DERIVED, NAMED_COMPONENTS, parameters
from common.messages import MAX_INPUT_BYTES, SESSION_ID, BadInput
from common.writes import Write, plan_write, stand_in
from lunaris.client import Accepted, NotApplied, Rejected, describe, humane
from lunaris.console.auth import User
from lunaris.console.live import Hub
from services.bridge import crew_view

__all__ = ["TooLarge", "answer", "catalogue", "read_body", "refused", "routes", "send"]

ROVER = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
LAST_MAX = 100_000  # the journal's latest events asked for at most


class TooLarge(Exception):
    """A request body larger than the route takes."""


async def read_body(request: Request, limit: int) -> bytes:
    """The body, read no further than ``limit`` bytes (:class:`TooLarge` beyond)."""
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        raise TooLarge
    data = bytearray()
    async for chunk in request.stream():
        data += chunk
        if len(data) > limit:
            raise TooLarge
    return bytes(data)


def catalogue() -> dict[str, Any]:
    """The fault catalogue as the page builds its forms from it: per kind its plain ``name``
    and ``effect`` (and the model's own ``description``), per parameter its ``label``,
    ``unit`` and ``hint`` beside its limits (:func:`common.faults.parameters`)."""
    return {
        "components": {c: {"named": c in NAMED_COMPONENTS, "kinds": {
            k: {"name": spec.name, "effect": spec.effect, "description": spec.description,
                "params": [{"name": p.name, "type": "number", **p.limits, "default": p.default,
                            "label": p.label, "unit": p.unit, "hint": p.hint}
                           for p in parameters(spec.params)]}
            for k, spec in kinds.items()}} for c, kinds in CATALOGUE.items()},
        "derived": DERIVED,
    }


def _user(request: Request) -> User:
    return request.scope["state"]["user"]


def answer(status: int, verdict: str, message: str, event: dict | None = None) -> JSONResponse:
    """A write's answer: ``{"verdict", "message", "event"}``."""
    return JSONResponse({"verdict": verdict, "message": message, "event": event}, status_code=status)


def refused(request: Request, rover: str) -> Response | None:
    """The answer to a write nobody may send (an observer's: 403; a bad rover id: 404), or None."""
    user: User = _user(request)
    if not user.may_act:
        return answer(403, "forbidden", f"{user.name} is an observer: observers see everything "
                                         "and change nothing")
    if not ROVER.match(rover):
        return answer(404, "invalid", f"bad rover id {rover!r}")
    return None


async def send(request: Request, planned: Write) -> Response:
    """Send a planned write through the hub's writer and answer with the twin's answer: 200
    accepted, 409 rejected, 503/504 not applied; 404 for a rover no service serves."""
    hub: Hub = request.app.state.hub
    rover = planned.rover
    if (why := hub.not_connected()) is not None:
        return answer(503, "not applied", why)
    if rover not in hub.mirror.rovers() or not hub.mirror.services(rover) and hub.mirror.token(
            rover, planned.owner) is None:
        known = ", ".join(r for r in hub.mirror.rovers() if hub.mirror.services(r)) or "none"
        return answer(404, "invalid", f"unknown rover {rover!r} (rovers: {known})")
    assert hub.writer is not None
    reply = await hub.writer.awrite(planned)
    got = describe(reply)
    if isinstance(reply, Accepted):
        return answer(200, "accepted", reply.message, got["event"])
    if isinstance(reply, Rejected):
        return answer(409, "rejected", reply.message, got["event"])
    assert isinstance(reply, NotApplied)
    return answer(503 if reply.unreachable else 504, "not applied", reply.message)


async def _write(request: Request) -> Response:
    rover, tail = request.path_params["rover"], request.path_params["key"]
    if (no := refused(request, rover)) is not None:
        return no
    try:
        body = await read_body(request, MAX_INPUT_BYTES)
    except TooLarge:
        return answer(413, "invalid", f"not sent: the payload is too large for an input (at most "
                                       f"{MAX_INPUT_BYTES} bytes)")
    except ClientDisconnect:
        return Response(status_code=400)
    try:
        planned = plan_write(rover, tail, None if request.method == "DELETE" else body)
        if request.query_params.get("as") == "crew":  # the instructor standing in for the crew
            planned = stand_in(planned)
        elif "as" in request.query_params:
            raise BadInput(f"as={request.query_params['as']!r}: the console writes as the crew "
                           "(as=crew) or as the instructor (no as)")
    except BadInput as exc:
        return answer(422, "invalid", f"not sent: {humane(str(exc))}")
    return await send(request, planned)


def _get(session: zenoh.Session, selector: str, timeout_s: float) -> tuple[list[Any], list[str]]:
    """The JSON answers to ``selector`` and the errors replied, in words."""
    ok, errors = [], []
    for reply in session.get(selector, timeout=timeout_s, consolidation=zenoh.ConsolidationMode.NONE):
        if reply.ok is not None:
            try:
                ok.append(json.loads(reply.ok.payload.to_bytes()))
            except ValueError:
                errors.append(f"an answer on {reply.ok.key_expr} that is not JSON")
        elif reply.err is not None:
            errors.append(humane(reply.err.payload.to_bytes().decode("utf-8", "replace")))
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
        if not last.isdigit() or len(last) > 6 or int(last) > LAST_MAX:
            return JSONResponse({"message": f"last: give a whole number up to {LAST_MAX}"},
                                status_code=422)
        session = q.get("session")
        if session is not None and session != "all" and not SESSION_ID.match(session):
            return JSONResponse({"message": "session: give a session's id as the sessions list it "
                                            "(e.g. 20250114-195312), or all"}, status_code=422)
        which = "" if session is None else f";session={session}"
        selector, timeout = f"{keys.faults_journal(rover)}?last={int(last)}{which}", 5.0
    elif what == "sessions":
        selector, timeout = keys.sessions(rover), 5.0
    elif what == "prediction":
        try:
            hours, samples = float(q.get("hours", "8")), int(q.get("samples", "1000"))
        except ValueError:
            return JSONResponse({"message": "hours and samples must be numbers"}, status_code=422)
        if not math.isfinite(hours) or hours <= 0 or not 0 < samples <= 1_000_000:
            return JSONResponse({"message": "hours must be a number above 0, samples a whole "
                                            "number from 1 to 1000000"}, status_code=422)
        selector, timeout = f"{keys.prediction(rover)}?hours={hours:g};samples={samples}", 60.0
    else:
        return JSONResponse({"message": f"no such query {what!r}"}, status_code=404)
    hub: Hub = request.app.state.hub
    if (why := hub.not_connected()) is not None:
        return JSONResponse({"message": why.removeprefix("not applied: ")}, status_code=503)
    ok, errors = await asyncio.to_thread(_get, request.app.state.session, selector, timeout)
    if what == "faults" and ok and errors:  # never fewer faults without saying so
        return JSONResponse({"message": "not every owner answered: " + "; ".join(errors),
                             "faults": [f for answer in ok for f in answer], "missing": errors},
                            status_code=502)
    if not ok:
        which = ", in a version with the prediction" if what == "prediction" else ""
        why = "; ".join(errors) or (f"nobody answered {selector} (is the service that answers it "
                                    f"running{which}?)")
        return JSONResponse({"message": why}, status_code=502 if errors else 504)
    if what == "sessions" and isinstance(ok[0], list):  # the console's notes laid over: void, renamed
        return JSONResponse(request.app.state.session_notes.apply(rover, ok[0]))
    return JSONResponse(ok[0])


async def _crew(request: Request) -> Response:
    rover = request.path_params["rover"]
    if not ROVER.match(rover):
        return JSONResponse({"message": f"bad rover id {rover!r}"}, status_code=404)
    hub: Hub = request.app.state.hub
    latest = hub.mirror.latest(rover)
    if not latest:
        known = ", ".join(hub.mirror.rovers()) or "none"
        return JSONResponse({"message": f"unknown rover {rover!r} (rovers: {known})"}, status_code=404)
    now = time.time()
    view = crew_view(rover, {k: v.value for k, v in latest.items()},
                     {k: now - v.at for k, v in latest.items()},
                     config=request.app.state.rover_files.by_id.get(rover), stamp_ns=time.time_ns())
    return JSONResponse(view)


async def _live(request: Request) -> Response:
    hub: Hub = request.app.state.hub
    sign_ins = request.app.state.sign_ins
    token = request.scope["state"].get("token")
    alive = None if sign_ins is None else (lambda: sign_ins.user(token) is not None)
    return StreamingResponse(hub.stream(alive), media_type="text/event-stream",
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
        Route("/api/rovers/{rover}/crew", _crew),
        Route("/api/rovers/{rover}/{what}", _query),
    ]
