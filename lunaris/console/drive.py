"""Driving from the console: the traverse files it offers, and one sent to a rover.

- ``GET /api/traverses``: every traverse file of the shipped folder (``config/traverses``)
  and of the folders given with ``lunaris console --traverses DIR``, each read and checked
  with :func:`common.traverse.load_traverse` (its problems listed, in words, when it has
  some): its name, description, speed, whether it returns, its waypoints. With
  ``?rover=ID`` and the rover's file known to the console (``--rover FILE``), each also
  carries its ``plan`` from where the rover is now (:func:`common.traverse.plan` against the
  rover's drive): length, duration, and why the drive would refuse it.
- ``POST /api/rovers/<rover>/traverse`` with ``{"file": NAME}`` (and optionally
  ``speed_m_per_s``, ``return_to_start`` to change the file's): the traverse sent as every
  write is, ``input/drive/traverse`` through the client's writer, and answered as every write
  (:func:`lunaris.console.api.send`). Waypoints entered by hand go as the key's own payload:
  ``PUT /api/rovers/<rover>/keys/input/drive/traverse``.

A file is named by its name alone (``mapp-crater-rim.yaml``); the first folder that has a
name wins, and a file of a later folder with the same name is listed with that problem.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path
from typing import Annotated, Any

import msgspec
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from common import keys
from common.config import Rover
from common.messages import BadInput, DriveTraverse, decode_input
from common.traverse import TraverseError, TraverseFile, length_and_duration, load_traverse, plan
from common.writes import plan_write
from lunaris.client import humane
from lunaris.console import api

__all__ = ["SHIPPED", "SendTraverse", "Traverses", "describe", "plans", "routes"]

SHIPPED = Path(__file__).resolve().parent.parent.parent / "config" / "traverses"
FILE = re.compile(r"^[A-Za-z0-9_.-]{1,80}\.ya?ml$")
MAX_FILES = 200  # traverse files listed from all the folders at most
BODY_BYTES = 4096


class SendTraverse(msgspec.Struct, forbid_unknown_fields=True):
    """``POST /api/rovers/<rover>/traverse``: which file, and what to change of it."""

    file: str
    speed_m_per_s: Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] | None = None
    return_to_start: bool | None = None


class Traverses:
    """The traverse files of some folders, read when asked (they are small and few)."""

    def __init__(self, folders: list[Path]):
        self.folders = list(dict.fromkeys(f.resolve() for f in folders))

    def _files(self) -> list[tuple[Path, str | None]]:
        """(path, why it is not offered or None) of every traverse file, in folder order."""
        out: list[tuple[Path, str | None]] = []
        seen: dict[str, Path] = {}
        for folder in self.folders:
            if not folder.is_dir():
                continue
            for path in sorted(folder.iterdir()):
                if len(out) >= MAX_FILES:
                    return out
                if not FILE.match(path.name) or not path.is_file():
                    continue
                if path.name in seen:
                    out.append((path, f"a traverse of {seen[path.name].parent} has the same name: rename "
                                      "this one to offer it"))
                    continue
                seen[path.name] = path
                out.append((path, None))
        return out

    def listed(self) -> list[dict[str, Any]]:
        """Every traverse file as the page lists it."""
        out: list[dict[str, Any]] = []
        for path, shadowed in self._files():
            entry: dict[str, Any] = {"file": path.name, "folder": str(path.parent)}
            if shadowed:
                out.append({**entry, "problems": [shadowed]})
                continue
            try:
                tf = load_traverse(path)
            except TraverseError as exc:
                out.append({**entry, "problems": exc.problems})
                continue
            out.append({**entry, **describe(tf), "problems": []})
        return out

    def find(self, name: str) -> tuple[TraverseFile | None, str]:
        """The traverse file ``name``, checked; or None and why not, in words."""
        for path, shadowed in self._files():
            if path.name != name or shadowed:
                continue
            try:
                return load_traverse(path), ""
            except TraverseError as exc:
                return None, f"{name} cannot be driven: {'; '.join(exc.problems)}"
        offered = ", ".join(p.name for p, s in self._files() if s is None) or "none"
        return None, f"no traverse file {name!r} (traverses: {offered})"


def describe(tf: TraverseFile) -> dict[str, Any]:
    """A traverse file's fields for the page."""
    return {"name": tf.traverse.name, "description": tf.traverse.description,
            "speed_m_per_s": tf.speed_m_per_s, "return_to_start": tf.return_to_start,
            "waypoints": msgspec.to_builtins(tf.waypoints)}


def plans(listed: list[dict[str, Any]], rover: Rover, at: tuple[float, float, float], where: str,
          traverses: Traverses) -> None:
    """Add to each traverse listed without problems its ``plan`` driven by ``rover`` from
    ``at`` (``where`` says what that point is, in words)."""
    assert rover.drive is not None
    for entry in listed:
        if entry["problems"]:
            continue
        tf, _ = traverses.find(entry["file"])
        if tf is None:
            continue
        legs, problems = plan(tf.command(), rover.drive, at)
        length, duration = length_and_duration(at, legs) if legs else (None, None)
        entry["plan"] = {"rover": rover.id, "from": where, "length_m": length, "duration_s": duration,
                         "problems": problems}


async def _list(request: Request) -> Response:
    traverses: Traverses = request.app.state.traverses
    listed = await asyncio.to_thread(traverses.listed)
    answer: dict[str, Any] = {"traverses": listed, "folders": [str(f) for f in traverses.folders]}
    rover_id = request.query_params.get("rover")
    if rover_id is not None:
        spec = request.app.state.rover_files.by_id.get(rover_id)
        if spec is None or spec.drive is None:
            answer["plan_missing"] = (f"{rover_id} does not drive" if spec is not None else
                                      f"the console was not given {rover_id}'s rover file "
                                      "(lunaris console --rover FILE): no plan")
        else:
            state = request.app.state.hub.mirror.value(keys.drive_state(rover_id))
            s = spec.drive.start
            at, where = (((state.x_m, state.y_m, state.z_m), "where the rover is") if state is not None
                         else ((s.x_m, s.y_m, s.z_m), "the rover's start"))
            await asyncio.to_thread(plans, listed, spec, at, where, traverses)
    return JSONResponse(answer)


async def _send(request: Request) -> Response:
    rover = request.path_params["rover"]
    if (no := api.refused(request, rover)) is not None:
        return no
    try:
        body = await api.read_body(request, BODY_BYTES)
    except api.TooLarge:
        return api.answer(413, "invalid", "not sent: that is not a traverse to send")
    except ClientDisconnect:
        return Response(status_code=400)
    try:
        wanted = decode_input(body, SendTraverse)
    except BadInput as exc:
        return api.answer(422, "invalid", f"not sent: {humane(str(exc))} (give {{\"file\": NAME}})")
    traverses: Traverses = request.app.state.traverses
    tf, why = await asyncio.to_thread(traverses.find, wanted.file)
    if tf is None:
        return api.answer(422, "invalid", f"not sent: {why}")
    cmd = tf.command()
    cmd = DriveTraverse(cmd.waypoints,
                        wanted.speed_m_per_s if wanted.speed_m_per_s is not None else cmd.speed_m_per_s,
                        wanted.return_to_start if wanted.return_to_start is not None else cmd.return_to_start)
    try:
        planned = plan_write(rover, "input/drive/traverse", msgspec.json.encode(cmd))
    except BadInput as exc:
        return api.answer(422, "invalid", f"not sent: {humane(str(exc))}")
    return await api.send(request, planned)


def routes() -> list[Route]:
    return [
        Route("/api/traverses", _list),
        Route("/api/rovers/{rover}/traverse", _send, methods=["POST"]),
    ]
