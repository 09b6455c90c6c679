"""What the page needs to know of each rover to offer only the forms that can work.

``GET /api/rovers`` answers, for every rover of the session (live, or named by a rover file
the console was given with ``--rover FILE``; ``lunaris up --console`` gives it its own):

- ``drives``: whether the rover drives (true, false, or null when the console cannot tell),
  and ``drives_why`` in words;
- ``radios``: each radio with ``follows_drive``: true when the radio stands at a ``site`` and
  the rover drives, so that the drive sets the rover's distance and angle to it and the twin
  refuses a position input for it (the page offers no position form for it, and says why in
  ``why``); false when the position input moves it; null when the console cannot tell. With
  the rover file, also the radio's ``site`` and its footprint (``a_m``, ``b_m``,
  ``offset_x_m``, ``offset_y_m``).
- ``rails``: with the rover file, each switchable rail with ``essential`` (never shed) and the
  loads it powers: the page asks before switching an essential rail off (the flight
  computer's: a slip of the instructor's would end the drill). Without it, none (the
  telemetry does not say which rails are essential).

How the console knows, most certain first: the radio's own telemetry (``radio/<radio>/link``
says ``follows_drive``, its ``site`` and its nominal footprint), the rover file, then the
twin's liveliness: a rover the drive service does not serve does not drive, so none of its
radios follows a drive. Before a radio's first sample, for a rover that drives and whose file
the console was not given, ``follows_drive`` is null and ``why`` says how to know.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from common import keys
from common.config import Rover, load_rover
from common.datafile import ConfigError
from lunaris.client import Mirror, ToolError

__all__ = ["RoverFiles", "describe_rovers", "routes"]


class RoverFiles:
    """The rover files the console was given, by rover id."""

    def __init__(self, paths: Iterable[Path] = ()):
        self.by_id: dict[str, Rover] = {}
        self.paths: dict[str, Path] = {}
        problems: list[str] = []
        for path in paths:
            try:
                rover = load_rover(path)
            except ConfigError as exc:
                problems.append(str(exc))
                continue
            if rover.id in self.by_id:
                problems.append(f"{path}: rover {rover.id} is also in {self.paths[rover.id]}")
                continue
            self.by_id[rover.id], self.paths[rover.id] = rover, Path(path)
        if problems:
            raise ToolError("a rover file has problems:\n" + "\n".join(problems))


def _drives(rover: str, mirror: Mirror, files: RoverFiles) -> tuple[bool | None, str]:
    spec = files.by_id.get(rover)
    if spec is not None:
        return spec.drive is not None, (
            f"its rover file ({files.paths[rover].name}) has a drive section" if spec.drive is not None
            else f"its rover file ({files.paths[rover].name}) has no drive section")
    services = mirror.services(rover)
    if "drive" in services or mirror.get(keys.drive_state(rover)) is not None:
        return True, "the twin's drive service serves it"
    if services:
        return False, "the twin's drive service does not serve it"
    return None, "none of its services is live"


def _radio(rover: str, name: str, mirror: Mirror, files: RoverFiles, drives: bool | None
           ) -> dict[str, Any]:
    out: dict[str, Any] = {"name": name}
    link = mirror.value(keys.radio_link(rover, name))
    said = getattr(link, "follows_drive", None) if link is not None else None
    spec = files.by_id.get(rover)
    radio = next((r for r in spec.radios if r.name == name), None) if spec is not None else None
    if radio is not None:
        out.update(site=None if radio.site is None else {"x_m": radio.site.x_m, "y_m": radio.site.y_m},
                   a_m=radio.a_m, b_m=radio.b_m, offset_x_m=radio.offset_x_m, offset_y_m=radio.offset_y_m)
    elif link is not None and isinstance(said, bool):  # the twin's own numbers (nominal footprint)
        site = getattr(link, "site", None)
        out.update(site=None if site is None else {"x_m": site.x_m, "y_m": site.y_m},
                   a_m=link.a_m, b_m=link.b_m, offset_x_m=link.offset_x_m, offset_y_m=link.offset_y_m)
    if isinstance(said, bool):
        follows: bool | None = said
        why = "the radio's telemetry says so"
    elif radio is not None:
        follows = radio.site is not None and bool(drives)
        why = ("it stands at a site and the rover drives" if follows else
               "it has no site in the rover file" if radio.site is None else "the rover does not drive")
    elif drives is False:
        follows, why = False, "the rover does not drive"
    else:
        follows = None
        why = (f"unknown: the twin does not say which radios stand at a site; give the console "
               f"{rover}'s rover file (lunaris console --rover FILE) to know")
    out["follows_drive"] = follows
    out["why"] = (f"the drive sets the rover's distance and angle to {name} ({why}): move the rover "
                  "with a traverse instead" if follows else why)
    return out


def describe_rovers(mirror: Mirror, files: RoverFiles) -> list[dict[str, Any]]:
    """Every rover of the session (live, or with a rover file given), as ``GET /api/rovers``
    answers it."""
    out = []
    for rover in sorted({*(r for r in mirror.rovers() if mirror.services(r)), *files.by_id}):
        drives, drives_why = _drives(rover, mirror, files)
        spec = files.by_id.get(rover)
        names = {p[1] for k in mirror.latest(rover)
                 if len(p := keys.split(k)[1]) == 3 and p[0] == "radio" and p[2] == "link"}
        if spec is not None:
            names |= {r.name for r in spec.radios}
        out.append({"id": rover, "live": bool(mirror.services(rover)),
                    "services": sorted(mirror.services(rover)),
                    "rover_file": str(files.paths[rover]) if rover in files.paths else None,
                    "drives": drives, "drives_why": drives_why,
                    "radios": [_radio(rover, n, mirror, files, drives) for n in sorted(names)],
                    "rails": [] if spec is None else [
                        {"name": r.name, "essential": r.essential,
                         "loads": [ld.name for ld in spec.loads if ld.rail == r.name]}
                        for r in spec.rails]})
    return out


async def _rovers(request: Request) -> Response:
    hub = request.app.state.hub
    return JSONResponse({"rovers": describe_rovers(hub.mirror, request.app.state.rover_files)})


def routes() -> list[Route]:
    return [Route("/api/rovers", _rovers)]
