"""``lunaris report FILE.mcap [--session ID] [-o OUT.png|OUT.html] [--json]``: a recorded session,
for the debrief.

A recording covers the sessions it saw (SPEC §12c): each trainee's, begun by the clock on
``control/session``, named by the clock's session id (its ticks' ``session``, each event's
``session``; a reset or a restore within a session goes on in it; a recording of a twin older
than sessions is one session, ``""``). The report is of one session - the last, or the
one ``--session`` names - and never holds anything of another: its events, its plots and its
**score sheet**, the crew's response (SPEC §12d, :mod:`common.response`): for each fault
injected in the session, when it was injected, when the crew could first see a symptom, the
crew's actions after it and when it was resolved; and the scenario's expectations, met (when)
or missed.

- ``-o OUT.png`` / ``OUT.html`` (default: FILE with .png) draws it (:mod:`lunaris.report_draw`):
  the timeline, the score sheet under it, the battery, loads, generation, radio links and path;
  the HTML page adds the score sheet's tables and every event.
- ``--json`` prints, per session of the recording (or the one asked), what the score sheet
  shows: ``[{session, trainee, faults: [{key, injected_t_s, first_symptom_t_s,
  first_crew_action_t_s, resolved_t_s, crew_actions: [{t_s, action, target, accepted}]}],
  expectations: [{label, met, at_t_s, within_s}]}]`` (each with a few more fields:
  :class:`common.response.SessionResponse`). Times are the rover's simulated time [s]. It reads
  only what the response needs, with :func:`lunaris.record.read_messages`: an hour of session
  in a few seconds (``bench/report_json.py``).
"""

from __future__ import annotations

import argparse
import io
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from common import keys
from common.response import Response, SessionResponse
from lunaris.client.events import EventWindow, event_identity
from lunaris.record import read_messages
from lunaris.report_draw import draw, moved, place_labels
from lunaris.report_page import html_page
from lunaris.report_session import Session

__all__ = ["Recording", "Session", "add_arguments", "add_thresholds", "draw", "load_recording",
           "load_session", "main", "place_labels"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap", help="a recording made by lunaris record")
    p.add_argument("-o", "--output", metavar="OUT", default=None,
                   help="OUT.png or OUT.html (default: FILE with .png)")
    p.add_argument("--rover", metavar="ID", help="the rover to draw (needed when several were recorded)")
    p.add_argument("--session", metavar="ID",
                   help="the session to report (default: the last of the recording)")
    p.add_argument("--json", action="store_true",
                   help="print the crew's response per session as JSON (every session, or --session)")
    p.add_argument("--rover-file", metavar="FILE",
                   help="the rover's definition, for its alarm thresholds (default: config/rovers by id)")


@dataclass
class Recording:
    """One rover of a recording: its response (every session) and, when drawn, each session's
    series (by session id, in order)."""

    rover: str
    response: Response
    sessions: dict[str, Session] = field(default_factory=dict)

    def scores(self, session: str | None = None) -> list[SessionResponse]:
        """The score of every session the recording saw (ticked in), or of the one named."""
        out = self.response.sessions(recorded_only=True)
        return [s for s in out if session is None or s.session == session]


# What the response reads, decoded into small Structs (msgspec skips the other fields): an hour
# of telemetry is read in seconds. The plots read everything, as JSON objects.
class _Clock(msgspec.Struct):
    t_s: float | None = None
    epoch: int = 0
    session: str = ""


class _Battery(msgspec.Struct):
    t_s: float | None = None
    capacity_j: float | None = None
    voltage_v: float | None = None
    temperature_c: float | None = None
    operational: bool | None = None


class _Load(msgspec.Struct):
    t_s: float | None = None
    power_w: float | None = None
    rail: str = ""


class _Rail(msgspec.Struct):
    t_s: float | None = None
    state: str | None = None


class _Power(msgspec.Struct):
    t_s: float | None = None
    power_w: float | None = None


class _Link(msgspec.Struct):
    t_s: float | None = None
    in_range: bool | None = None


_FAST = {"clock": _Clock, "battery/state": _Battery, "load/*/power": _Load, "rail/*/state": _Rail,
         "solar/*/power": _Power, "umbilical/state": _Power, "radio/*/link": _Link,
         "scenario/progress": dict, "event": dict}


class _Channel:
    """How one channel is read: its rover's record, its key's chunks, its family, its decoder."""

    __slots__ = ("decode", "family", "parts", "rec")

    def __init__(self, rec: Recording, parts: list[str], family: str, decode: Any):
        self.rec, self.parts, self.family, self.decode = rec, parts, family, decode


def _channel(topic: str, plots: bool, out: dict[str, Recording],
             load_rails: dict[str, dict[str, str]]) -> _Channel | None:
    """How to read a channel; None to skip it."""
    try:
        rover, parts = keys.split(topic)
    except ValueError:
        return None
    fam = keys.telemetry_family(parts)
    family = "event" if parts[:1] == ["event"] and len(parts) <= 2 else (
        fam.name if fam is not None else None)  # events: the journal's key and each service's
    if family is None or (not plots and family not in _FAST):
        return None
    rec = out.get(rover)
    if rec is None:
        rec = out[rover] = Recording(rover, Response(rover))
        rec.response.know_rails(load_rails.get(rover, {}))
    typ = dict if plots else _FAST[family]
    return _Channel(rec, parts, family, msgspec.json.Decoder(typ).decode)


def _load_rails(path: Path) -> dict[str, dict[str, str]]:
    """Each rover's ``{load: rail}`` from the first tick of its loads' telemetry: read ahead,
    until a load of every rover heard so far has been heard twice (a tick's loads all come
    before the next tick's), since a recording begins with the journal's history, before it."""
    rails: dict[str, dict[str, str]] = {}
    twice: set[str] = set()
    for topic, data in read_messages(path):
        parts = topic.split("/")
        if len(parts) != 5 or parts[2] != "load" or parts[4] != "power":
            continue
        rover, load = parts[1], parts[3]
        known = rails.setdefault(rover, {})
        if load in known:
            twice.add(rover)
            if twice >= rails.keys():
                break
            continue
        try:
            rail = msgspec.json.decode(data).get("rail")
        except (msgspec.DecodeError, AttributeError):
            continue
        if isinstance(rail, str) and rail:
            known[load] = rail
    return rails


def load_recording(path: Path, plots: bool = True) -> dict[str, Recording]:
    """Every rover of a recording: its response per session and (``plots``) each session's
    series. Raises ValueError if the file is not a readable MCAP file."""
    out: dict[str, Recording] = {}
    seen_events = EventWindow()
    channels: dict[str, _Channel | None] = {}
    errors = (msgspec.DecodeError, msgspec.ValidationError)
    try:
        load_rails = _load_rails(path)
    except (ValueError, EOFError) as exc:
        raise ValueError(f"{path} is not a readable MCAP file: {exc}") from None
    try:
        for topic, data in read_messages(path):
            if topic in channels:
                ch = channels[topic]
            else:
                ch = channels[topic] = _channel(topic, plots, out, load_rails)
            if ch is None:
                continue
            try:
                v = ch.decode(data)
            except errors:
                continue
            rec = ch.rec
            if ch.family == "event":
                if isinstance(v, dict) and v.get("op") == "put" and isinstance(v.get("value"), dict):
                    v = v["value"]  # an event/<service> key recorded as a write (before it was known)
                if not isinstance(v, dict) or not seen_events.first(event_identity(rec.rover, v)):
                    continue  # once: the journal's key, the service's, replays
                sid = rec.response.event(v)
                if plots:
                    _session(rec, sid).add_event(v)
            elif plots:
                if isinstance(v, dict):
                    _session(rec, rec.response.value(ch.parts, v)).add_value(ch.family, ch.parts, v)
            else:
                rec.response.value(ch.parts, v)
    except (ValueError, EOFError) as exc:
        raise ValueError(f"{path} is not a readable MCAP file: {exc}") from None
    for rec in out.values():
        rec.sessions = dict(sorted(rec.sessions.items()))  # by id: the order they began
        scores = {s.session: s for s in rec.response.sessions()}
        for sid, s in rec.sessions.items():
            s.score = scores.get(sid)
            s.events.sort(key=lambda e: (e["at_s"] is not None, e["at_s"] or 0.0, e.get("t_s", 0.0)))
    return out


def _session(rec: Recording, sid: str) -> Session:
    s = rec.sessions.get(sid)
    if s is None:
        s = rec.sessions.pop("", None) if sid else None  # what came before the first id is its
        if s is None:
            s = Session(rec.rover, sid)
        s.id = sid
        rec.sessions[sid] = s
    return s


def load_session(path: Path, session: str | None = None) -> dict[str, Session]:
    """Each rover's session to draw: the one named, else its last with telemetry."""
    out = {}
    for rover, rec in load_recording(path).items():
        drawn = [s for s in rec.sessions.values() if s.telemetry]
        chosen = [s for s in drawn if s.id == session] if session is not None else drawn[-1:]
        if chosen:
            out[rover] = chosen[0]
    return out


def add_thresholds(s: Session, rover_file: str | None) -> str:
    """The rover file's alarm thresholds on the plots; a note of where they came from."""
    from lunaris.client import ToolError
    from lunaris.scenario import find_rover

    try:
        rover, note = find_rover(s.rover, rover_file)
    except ToolError as exc:
        return f"thresholds not drawn: {exc}"
    if rover is None:
        return f"thresholds not drawn: {note}"
    th = rover.battery.thermal
    s.thresholds["temperature"] = [(th.max_c, f"alarm {th.max_c:g} C"),
                                   (th.cutoff_c, f"cut-off {th.cutoff_c:g} C")]
    soc = [(r.shed_below_soc * 100, f"{r.name} shed") for r in rover.rails if r.shed_below_soc is not None]
    if rover.battery.depleted_soc > 0:
        soc.append((rover.battery.depleted_soc * 100, "depleted"))
    s.thresholds["soc"] = soc
    return "thresholds " + note.replace("names checked against", "from")


# -- the command ---------------------------------------------------------------------------------


class _Refused(Exception):
    def __init__(self, message: str, code: int = 2):
        super().__init__(message)
        self.code = code


def main(args: argparse.Namespace) -> int:
    try:
        return _json(args) if args.json else _draw(args)
    except _Refused as exc:
        print(f"lunaris report: {exc}", file=sys.stderr)
        return exc.code


def _load(args: argparse.Namespace, plots: bool) -> dict[str, Recording]:
    path = Path(args.file)
    if not path.is_file():
        raise _Refused(f"{path} does not exist")
    try:
        recs = load_recording(path, plots)
    except ValueError as exc:
        raise _Refused(str(exc)) from None
    if args.rover is not None:
        if args.rover not in recs:
            raise _Refused(f"no rover {args.rover!r} in {path} (rovers: {', '.join(sorted(recs)) or 'none'})")
        recs = {args.rover: recs[args.rover]}
    return recs


def _sessions_named(recs: dict[str, Recording]) -> str:
    return "; ".join(f"{r}: {', '.join(s.session for s in rec.scores()) or 'none'}"
                     for r, rec in sorted(recs.items()))


def _tidy(value: Any) -> Any:
    """Numbers to the microsecond (sim times add a tenth of a second at a time: 30.100000000000158
    is 30.1), the rest as it is."""
    if isinstance(value, float):
        return round(value, 6)
    if isinstance(value, list):
        return [_tidy(v) for v in value]
    if isinstance(value, dict):
        return {k: _tidy(v) for k, v in value.items()}
    return value


def _json(args: argparse.Namespace) -> int:
    recs = _load(args, plots=False)
    scores = [s for rover in sorted(recs) for s in recs[rover].scores(args.session)]
    if args.session is not None and not scores:
        raise _Refused(f"no session {args.session!r} in {args.file} (sessions: {_sessions_named(recs)})")
    print(msgspec.json.format(msgspec.json.encode(_tidy(msgspec.to_builtins(scores))), indent=2).decode())
    if not scores:
        print(f"lunaris report: {args.file} holds no session of a rover (no clock tick recorded)",
              file=sys.stderr)
        return 1
    return 0


def _draw(args: argparse.Namespace) -> int:
    path = Path(args.file)
    out = Path(args.output) if args.output else path.with_suffix(".png")
    if out.suffix.lower() not in (".png", ".html"):
        raise _Refused(f"the output must end in .png or .html, got {out}")
    recs = _load(args, plots=True)
    drawn = {r: [s for s in rec.sessions.values() if s.telemetry] for r, rec in recs.items()}
    drawn = {r: ss for r, ss in drawn.items() if ss}
    if not drawn:
        raise _Refused(f"{path} holds no rover telemetry", 1)
    rover = args.rover
    if rover is None:
        if len(drawn) > 1:
            raise _Refused(f"{path} holds several rovers ({', '.join(sorted(drawn))}); "
                           "choose one with --rover")
        rover = next(iter(drawn))
    if rover not in drawn:
        raise _Refused(f"no telemetry of rover {rover!r} in {path} (rovers: {', '.join(sorted(drawn))})")
    sessions = drawn[rover]
    if args.session is not None:
        sessions = [s for s in sessions if s.id == args.session]
        if not sessions:
            names = ", ".join(s.id for s in drawn[rover])
            raise _Refused(f"no session {args.session!r} of {rover} in {path} (sessions: {names})")
    s = sessions[-1]
    note = add_thresholds(s, args.rover_file)
    t0, t1 = s.span_s
    trainee = s.score.trainee if s.score is not None else None
    whose = f"{trainee}'s session" if trainee else "a session with no trainee named"
    title = (f"Debrief of {whose} on {rover}: {t1 - t0:.0f} s of simulated time (recording {path.name}, "
             f"session {s.id or 'before sessions'})")
    fig = draw(s, title)
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=100)
    if out.suffix.lower() == ".png":
        out.write_bytes(png.getvalue())
    else:
        out.write_text(html_page(s, title, png.getvalue(), [
            (x.id, x.score.trainee if x.score is not None else None) for x in drawn[rover]]))
    drove = f", a path of {len(s.path[0])} positions" if moved(s) else ""
    before = sum(1 for e in s.events if e.get("at_s") is None)
    others = len(drawn[rover]) - 1
    score = s.score
    scored = (f"; {len(score.faults)} fault(s), {sum(1 for e in score.expectations if e.met)} of "
              f"{len(score.expectations)} expectation(s) met" if score is not None else "")
    print(f"wrote {out}: {rover}, session {s.id} ({others} other session(s) in the recording), "
          f"{t1 - t0:.0f} s of sim time, {len(s.loads)} loads{drove}, "
          f"{sum(1 for e in s.events if e.get('at_s') is not None)} event(s) marked, {len(s.events)} "
          f"event(s) in all ({before} from before the recording){scored}; {note}")
    return 0
