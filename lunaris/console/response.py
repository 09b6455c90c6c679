"""``GET /api/rovers/<rover>/response``: the crew's response in the rover's running session,
live (SPEC 12d) - each fault injected in it with the time since its injection (while in effect),
when the crew could first see it, whether and how the crew has acted, when it was resolved; and
the scenario's expectations as they are met or missed.

The console's mirror tells :class:`Responses` every telemetry sample and event it takes; one
:class:`common.response.Response` per rover measures them, as ``lunaris report`` does from a
recording. The mirror holds back the events of a session whose first tick it has not heard yet
(they can come first: each key is its own stream) and tells the session when the tick comes:
they are taken from the mirror then, each event once by ``(source_id, seq)``. The answer is
:class:`common.response.LiveResponse` as JSON (``version`` grows with every change of it);
404 in words for a rover the console has not heard.
"""

from __future__ import annotations

import threading

import msgspec
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from common import keys
from common.response import LiveResponse
from common.response import Response as CrewResponse
from lunaris.client.events import EventWindow, event_identity
from lunaris.client.mirror import Mirror
from lunaris.client.records import Change

__all__ = ["Responses", "routes"]

_encode = msgspec.json.Encoder().encode


class Responses:
    """The crew's response of every rover the mirror holds, fed by its changes (on Zenoh's
    threads); a rover the mirror forgets is forgotten here too."""

    def __init__(self, mirror: Mirror) -> None:
        self.mirror = mirror
        self._lock = threading.Lock()
        self._rovers: dict[str, CrewResponse] = {}
        self._window = EventWindow()

    def on_change(self, c: Change) -> None:
        if c.kind == "forget":
            with self._lock:
                self._rovers.pop(c.rover, None)
            return
        held = []
        if c.kind == "session":  # the events it held back for the session now running
            held = [ev for _, ev, _ in self.mirror.events(c.rover) if ev.session == c.value.id]
        elif c.kind not in ("value", "event"):
            return
        with self._lock:
            r = self._rovers.get(c.rover)
            if r is None:
                r = self._rovers[c.rover] = CrewResponse(c.rover)
            if c.kind == "value":
                r.value(keys.split(c.key)[1], c.value)
            for ev in held if c.kind == "session" else [c.value]:
                if self._window.first(event_identity(c.rover, ev)):
                    r.event(ev)

    def live(self, rover: str) -> LiveResponse | None:
        with self._lock:
            r = self._rovers.get(rover)
            return None if r is None else r.live()


async def _response(request: Request) -> Response:
    rover = request.path_params["rover"]
    live = request.app.state.responses.live(rover)
    if live is None:
        return JSONResponse({"message": f"no rover {rover!r} heard by the console"}, status_code=404)
    return Response(_encode(live), media_type="application/json")


def routes() -> list[Route]:
    return [Route("/api/rovers/{rover}/response", _response)]
