"""What a service keeps on disk so that a restarted service resumes where it was.

One JSON file per service and kind of state, ``<state_dir>/<service>-<what>.json``. Without a
state directory nothing is kept, and nothing is read.

- **Written atomically and durably**: to a temporary file beside it, flushed to the disk
  (``fsync``), renamed over the old one, and the folder's entry flushed too. A kill or a
  power cut mid-write leaves the previous file, never half of the new one. (What is saved
  at every tick, the clock's time, is flushed once a second: ``durable=False`` in between
  still leaves a whole file after a kill, the page cache outliving the process.)
- **Read with suspicion**: a file that cannot be read (a folder in its place, no permission,
  not JSON, cut short) raises :class:`Damaged`, which names the file and what is wrong with
  it. What a service saves is then checked by its owner (types, finite numbers, ranges:
  :mod:`common.session`, :meth:`common.fault_book.FaultBook.restore`), which keeps the intact
  parts and says in a ``critical`` event what was damaged and what it did.
- **A damaged file is moved aside** (:meth:`StateStore.set_aside`) to
  ``<name>.damaged-<UTC time>``, kept for whoever wants to look at it, and the service goes
  on: it never fails over and over on the same bad file.

JSON as Python writes it (``NaN``, ``Infinity``) is read, so that a number that is not
finite is found by the owner's check, in the field that holds it, rather than losing the
whole file to a decode error.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

import msgspec

__all__ = ["Damaged", "StateStore", "kind_of", "not_finite", "quoted", "set_aside", "shape_problem",
           "write_atomically"]


class Damaged(Exception):
    """A state file that cannot be used: ``path``, what is wrong (``reason``), and where it
    was moved (``moved_to``, None while it is where it was)."""

    def __init__(self, path: Path, reason: str, moved_to: Path | None = None):
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason
        self.moved_to = moved_to

    def where(self) -> str:
        """What became of the file, in words."""
        if self.moved_to is None:
            return f"{self.path.name} left where it is"
        return f"the file was moved to {self.moved_to.name}"


def write_atomically(path: Path, data: bytes, durable: bool = True) -> None:
    """Replace ``path`` by ``data`` so that a kill or a power cut at any moment leaves either
    the old file or the new one: a temporary file, fsync, rename, fsync of the folder
    (without ``durable``, no fsync: whole after a kill, perhaps the older after a power cut)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        if durable:
            os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    if durable:
        fsync_folder(path.parent)


def fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def set_aside(path: Path, why: str = "damaged") -> Path | None:
    """Move a damaged file (or whatever is in its place) out of the way, to
    ``<name>.<why>-<UTC time>``; where it went, or None if it could not be moved."""
    if not os.path.lexists(path):
        return None
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    target = path.with_name(f"{path.name}.{why}-{stamp}")
    n = 1
    while os.path.lexists(target):
        n += 1
        target = path.with_name(f"{path.name}.{why}-{stamp}-{n}")
    try:
        os.replace(path, target)
    except OSError:
        return None
    fsync_folder(path.parent)
    return target


def not_finite(value: Any, at: str = "") -> str | None:
    """The path of the first number in ``value`` that is not finite (``energy_j``,
    ``rails.12V.trip_current_a``), or None when every number is."""
    if isinstance(value, float):
        return None if math.isfinite(value) else (at or "the value")
    if isinstance(value, dict):
        for k, v in value.items():
            found = not_finite(v, f"{at}.{k}" if at else str(k))
            if found:
                return found
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found = not_finite(v, f"{at}[{i}]")
            if found:
                return found
    return None


def _decode(raw: bytes) -> Any:
    """JSON, or Python's JSON (``NaN``, ``Infinity``); ValueError naming the problem."""
    try:
        return msgspec.json.decode(raw)
    except msgspec.DecodeError as exc:
        strict = str(exc)
    try:
        return json.loads(raw)  # NaN and Infinity: the owner's check names the field
    except (ValueError, UnicodeDecodeError):
        pass
    if not raw.strip():
        raise ValueError("empty")
    raise ValueError(f"not JSON ({strict})")


class StateStore:
    def __init__(self, state_dir: str | os.PathLike | None, service: str):
        self.dir = Path(state_dir) if state_dir else None
        self.service = service

    def path(self, what: str) -> Path | None:
        if self.dir is None:
            return None
        return self.dir / f"{self.service}-{what}.json"

    def save(self, what: str, data: Any, durable: bool = True) -> None:
        """Write ``data`` as JSON, atomically and durably (OSError when the disk refuses)."""
        path = self.path(what)
        if path is None:
            return
        write_atomically(path, msgspec.json.encode(data), durable)

    def load(self, what: str, *, set_aside: bool = True) -> Any:
        """The saved data, or None when there is none. A file that cannot be read raises
        :class:`Damaged`, after being moved aside (unless ``set_aside`` is false: a query
        that only looks)."""
        path = self.path(what)
        if path is None or not os.path.lexists(path):
            return None
        try:
            if path.is_dir():
                raise ValueError("a folder in place of the file")
            if not path.is_file():
                raise ValueError("not a regular file")
            data = _decode(path.read_bytes())
        except OSError as exc:
            reason = f"unreadable: {exc.strerror or exc}"
        except ValueError as exc:
            reason = str(exc)
        else:
            return data
        raise Damaged(path, reason, self.set_aside(what) if set_aside else None)

    def set_aside(self, what: str, why: str = "damaged") -> Path | None:
        """Move the file of ``what`` out of the way (see :func:`set_aside`)."""
        path = self.path(what)
        return None if path is None else set_aside(path, why)


def kind_of(value: Any) -> str:
    """What a JSON value is, in words (in what a check of saved state says)."""
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "text"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return "null" if value is None else type(value).__name__


def shape_problem(saved: Any, template: Any, at: str = "the state") -> str | None:
    """What is wrong with ``saved`` against ``template`` (a state as the service has it now),
    or None: a field of another type than the template's (a number where a number is, true
    or false where a flag is, ...), a number that is not finite. Fields the template does
    not have are let through (the service's ``set`` ignores them); missing ones too (it has
    defaults for what older versions did not save)."""
    if isinstance(template, bool):
        ok = isinstance(saved, bool)
    elif isinstance(template, int | float):
        ok = isinstance(saved, int | float) and not isinstance(saved, bool)
        if ok and not_finite(float(saved)):
            return f"{at} is {saved!r}, not a finite number"
    elif isinstance(template, str):
        ok = isinstance(saved, str)
    elif isinstance(template, list):
        ok = isinstance(saved, list)
        if ok and template:
            for i, item in enumerate(saved):
                problem = shape_problem(item, template[0], f"{at}[{i}]")
                if problem:
                    return problem
    elif isinstance(template, dict):
        ok = isinstance(saved, dict)
        if ok:
            for k, v in saved.items():
                if k in template:
                    problem = shape_problem(v, template[k], k if at == "the state" else f"{at}.{k}")
                    if problem:
                        return problem
                elif (path := not_finite(v)) is not None:
                    where = k if at == "the state" else f"{at}.{k}"
                    return f"{where}{'' if path == 'the value' else '.' + path} is not a finite number"
    else:
        return None
    if not ok:
        return f"{at} is {kind_of(saved)}, not {kind_of(template)} ({quoted(saved)})"
    return None


def quoted(value: Any) -> str:
    """A value as a check of saved state quotes it: its repr, cut at 40 characters."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
