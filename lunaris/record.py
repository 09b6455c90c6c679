"""``lunaris record FILE.mcap``: every ``lunaris/**`` key to an MCAP file.

One MCAP channel per key, named by the key (``lunaris/mapp-1/battery/state``),
``message_encoding`` ``json``, with a ``jsonschema`` schema per key family
derived from the family's msgspec Struct (``lunaris.BatteryState`` ...), so
Foxglove and PlotJuggler show and plot every field.

Time stamps of every message:

- ``log_time``: the wall clock when the recorder received it [ns since the Unix epoch];
- ``publish_time``: the simulated time of the rover [ns of sim time] - the payload's
  ``t_s``; for keys without one (instructor writes) the rover's last clock tick.

Telemetry payloads and events (the journal's ``event`` and each service's ``event/<service>``)
are written as published. Keys without a telemetry Struct
(instructor writes on ``fault/**``, ``input/**``, ``cmd/**``, ``clock/control``, and
anything else) are written as a :class:`KeyWrite` envelope, so a fault clearing
(a delete) and a bare-number input are recorded too.

The recorder joins late gracefully: the publishers' caches are replayed at start
(the current value of every key and the recent events). It stops on Ctrl-C,
SIGTERM or after ``--duration`` seconds, and always leaves a complete file.

:func:`read_messages` reads a recording back, every message in the order it was written (the
order the recorder received them), fast enough for ``lunaris report --json`` of an hour of
session (about a million messages) in well under its 5 s (SPEC §10): the ``mcap`` library's
reader builds a record object per message and checks each chunk's CRC, several seconds for
such a file; this reads the records' few fields with ``struct`` and nothing more. Viewers
(Foxglove, PlotJuggler) and the ``mcap`` library read the same files.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import queue
import signal
import struct
import sys
import threading
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import msgspec
import zenoh
import zenoh.ext as zext
from mcap.writer import Writer

from common import keys
from common.connection import add_connection_args
from common.worker import wait_get
from lunaris.client import ToolError, describe_endpoint, open_session

__all__ = ["KeyWrite", "Recorder", "add_arguments", "main", "read_messages", "schema_for"]

ENVELOPE = "lunaris.KeyWrite"


class KeyWrite(msgspec.Struct):
    """A sample on a key without a telemetry Struct: an instructor's put or delete."""

    t_s: float  # the rover's sim time when it was received (its last clock tick)
    op: Literal["put", "delete"]
    value: Any = None  # the payload's JSON value; null when empty, deleted or not JSON
    text: str | None = None  # the payload as text when it is not JSON


def _family(parts: list[str]) -> keys.Family | None:
    """A key's telemetry family; a service's own event key (``event/<service>``, DECISIONS D1)
    is an event too."""
    if len(parts) == 2 and parts[0] == "event":
        parts = parts[:1]
    return keys.telemetry_family(parts)


def schema_for(parts: list[str]) -> tuple[str, dict[str, Any]]:
    """The schema name and JSON schema of a key (its chunks after ``lunaris/<rover>/``)."""
    family = _family(parts)
    struct = family.payload if family is not None else KeyWrite
    name = ENVELOPE if family is None else f"lunaris.{struct.__name__}"
    return name, json_schema(struct)


def json_schema(struct: type[msgspec.Struct]) -> dict[str, Any]:
    """The JSON schema of ``struct`` with the Struct itself at the root.

    ``msgspec.json.schema`` returns ``{"$ref": "#/$defs/Name", "$defs": {...}}``; viewers
    such as Foxglove want the object at the top, so the root reference is resolved and
    any other definitions are kept in ``$defs``.
    """
    full = msgspec.json.schema(struct)
    defs = dict(full.get("$defs", {}))
    ref = full.get("$ref", "")
    if not ref.startswith("#/$defs/"):
        return full
    root = dict(defs.pop(ref.removeprefix("#/$defs/")))
    if defs:
        root["$defs"] = defs
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **root}


MAGIC = b"\x89MCAP0\r\n"
_OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_FOOTER, _OP_DATA_END = 0x04, 0x05, 0x06, 0x02, 0x0F
_RECORD = struct.Struct("<BQ")  # opcode, length
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_MESSAGE_HEAD = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time


def read_messages(path: str | Path) -> Iterator[tuple[str, memoryview]]:
    """``(topic, data)`` of every message of an MCAP file, in the order they were written (the
    data a view into the file or a chunk: copy it to keep it). A file cut short (a recorder
    killed) yields what it holds whole; one that is not MCAP, or whose chunks cannot be read,
    raises ValueError saying so."""
    with open(path, "rb") as f:
        buf = f.read()
    if not buf.startswith(MAGIC):
        raise ValueError(f"{path} is not an MCAP file (it does not begin with the MCAP magic)")
    topics: dict[int, str] = {}
    view = memoryview(buf)
    record, u16 = _RECORD.unpack_from, _U16.unpack_from
    pos, end = len(MAGIC), len(buf)
    while pos + 9 <= end:
        op, length = record(view, pos)
        body = pos + 9
        pos = body + length
        if pos > end:
            return  # cut short
        if op == _OP_CHUNK:
            yield from _messages(_chunk(view, body), topics)
        elif op == _OP_MESSAGE:
            (channel,) = u16(view, body)
            topic = topics.get(channel)
            if topic is not None:
                yield topic, view[body + _MESSAGE_HEAD:pos]
        elif op == _OP_CHANNEL:
            _channel(view, body, topics)
        elif op in (_OP_DATA_END, _OP_FOOTER):
            return


def _channel(view: memoryview, body: int, topics: dict[int, str]) -> None:
    (channel,) = _U16.unpack_from(view, body)
    (n,) = _U32.unpack_from(view, body + 4)
    topics[channel] = bytes(view[body + 8:body + 8 + n]).decode("utf-8", "replace")


def _messages(view: memoryview, topics: dict[int, str]) -> list[tuple[str, memoryview]]:
    """The messages of a chunk's records (its channels noted on the way)."""
    out: list[tuple[str, memoryview]] = []
    append, record, u16, get = out.append, _RECORD.unpack_from, _U16.unpack_from, topics.get
    pos, end = 0, len(view)
    while pos + 9 <= end:
        op, length = record(view, pos)
        body = pos + 9
        pos = body + length
        if op == _OP_MESSAGE:
            topic = get(u16(view, body)[0])
            if topic is not None:
                append((topic, view[body + _MESSAGE_HEAD:pos]))
        elif op == _OP_CHANNEL:
            _channel(view, body, topics)
    return out


def _chunk(view: memoryview, body: int) -> memoryview:
    """The records of a chunk, decompressed."""
    (size,) = _U64.unpack_from(view, body + 16)
    (n,) = _U32.unpack_from(view, body + 28)
    compression = bytes(view[body + 32:body + 32 + n]).decode("ascii", "replace")
    at = body + 32 + n
    (length,) = _U64.unpack_from(view, at)
    data = view[at + 8:at + 8 + length]
    try:
        if compression == "zstd":
            import zstandard
            return memoryview(zstandard.ZstdDecompressor().decompress(data, max_output_size=size))
        if compression == "lz4":
            import lz4.frame  # type: ignore[import-untyped]
            return memoryview(lz4.frame.decompress(data))
    except Exception as exc:  # the decompressors' own errors: a damaged chunk
        raise ValueError(f"a chunk cannot be decompressed ({compression}: {exc})") from None
    if compression:
        raise ValueError(f"a chunk is compressed with {compression!r}, which this reader does not know")
    return data


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap", help="the MCAP file to write")
    p.add_argument("--rover", metavar="ID", help="record one rover only (default: every lunaris key)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of wall time")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--no-history", action="store_true",
                   help="do not record the publishers' cached values at start")
    p.add_argument("--progress", type=float, default=None, metavar="S",
                   help="seconds between progress lines (default 1 on a terminal, 5 otherwise)")
    p.add_argument("--wait", type=float, default=10.0, metavar="S",
                   help="how long to wait for the router at start (default 10 s)")
    add_connection_args(p)


FLUSH_S = 1.0  # a recording's chunk is closed and synced to the disk this often [s]


class Recorder:
    """Writes samples to MCAP on the calling thread (``mcap.Writer`` is not thread-safe)."""

    def __init__(self, output, source: str):
        self.output = output
        self.writer = Writer(output)
        self.writer.start(profile="", library="lunaris record")
        self.writer.add_metadata("lunaris", {
            "source": source,
            "started_unix_ns": str(time.time_ns()),
            "log_time": "wall clock at reception [ns since the Unix epoch]",
            "publish_time": "simulated time of the rover [ns]: the payload's t_s, or the last clock tick",
        })
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.sequence: Counter[str] = Counter()
        self.per_family: Counter[str] = Counter()
        self.sim_t: dict[str, float] = {}  # rover -> last t_s seen
        self.messages = 0
        self.skipped = 0
        self.bytes = 0

    def flush(self) -> None:
        """Close the chunk in progress and put it on the disk (SPEC 13e): a recorder killed, or
        a power cut, loses at most the last ``FLUSH_S`` of it; the file read as far as it goes
        (its chunks of 1 MB held minutes of a rover before: a recorder killed lost them all).
        A chunk a second compresses less; a rover's second of telemetry is tens of kB."""
        self.writer.flush()
        with contextlib.suppress(OSError, AttributeError, ValueError):  # (a stream that is no file)
            os.fsync(self.output.fileno())

    def _channel(self, key: str, parts: list[str]) -> int:
        channel = self.channels.get(key)
        if channel is None:
            name, schema = schema_for(parts)
            schema_id = self.schemas.get(name)
            if schema_id is None:
                schema_id = self.writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
                self.schemas[name] = schema_id
            channel = self.writer.register_channel(key, "json", schema_id)
            self.channels[key] = channel
        return channel

    def write(self, key: str, payload: bytes, deleted: bool, log_time_ns: int) -> bool:
        """Record one sample; False when it is skipped (a telemetry payload that is not JSON)."""
        try:
            rover, parts = keys.split(key)
        except ValueError:
            self.skipped += 1
            return False
        fam = _family(parts)
        family = fam.name if fam is not None else None
        if family is not None:
            if deleted:
                self.skipped += 1
                return False
            try:
                value = msgspec.json.decode(payload)
                t_s = float(value["t_s"])
            except (msgspec.DecodeError, KeyError, TypeError, ValueError):
                self.skipped += 1
                return False
            if family == "clock" or rover not in self.sim_t:
                self.sim_t[rover] = t_s
            data = payload
        else:
            t_s = self.sim_t.get(rover, 0.0)
            text = payload.decode("utf-8", "replace")
            try:
                value, text_out = (msgspec.json.decode(payload) if payload.strip() else None), None
            except msgspec.DecodeError:
                value, text_out = None, text
            data = msgspec.json.encode(KeyWrite(t_s, "delete" if deleted else "put", value, text_out))
        channel = self._channel(key, parts)
        self.sequence[key] += 1
        self.writer.add_message(channel, log_time=log_time_ns, data=data,
                                publish_time=max(0, int(round(t_s * 1e9))),
                                sequence=self.sequence[key])
        self.messages += 1
        self.bytes += len(data)
        self.per_family[family or ENVELOPE] += 1
        return True

    def finish(self) -> None:
        self.writer.finish()


def main(args: argparse.Namespace) -> int:
    path = Path(args.file)
    try:
        if path.exists() and not args.force:
            raise ToolError(f"{path} exists; use --force to overwrite it")
        if not path.parent.is_dir():
            raise ToolError(f"folder {str(path.parent)!r} does not exist")
        return _record(args, path)
    except ToolError as exc:
        print(f"lunaris record: {exc}", file=sys.stderr)
        return exc.code


def _record(args: argparse.Namespace, path: Path) -> int:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        f"waiting for the Zenoh router at {describe_endpoint(args)} ...", file=sys.stderr, flush=True))
    samples: queue.SimpleQueue = queue.SimpleQueue()

    def on_sample(s: zenoh.Sample) -> None:
        samples.put((str(s.key_expr), s.payload.to_bytes(), s.kind == zenoh.SampleKind.DELETE,
                     time.time_ns()))

    selector = keys.under(args.rover or "*")
    tmp = path.with_name(path.name + ".part")
    out = open(tmp, "wb")  # closed in the finally below
    recorder = Recorder(out, describe_endpoint(args))
    history = None if args.no_history else zext.HistoryConfig(detect_late_publishers=True)
    sub = zext.declare_advanced_subscriber(session, selector, on_sample, history=history)
    tty = sys.stderr.isatty()
    started = time.monotonic()
    until = f"for {args.duration:g} s" if args.duration else "Ctrl-C to stop"
    print(f"recording {selector} from {describe_endpoint(args)} to {path} ({until})",
          file=sys.stderr, flush=True)
    last_progress = last_flush = started
    every_s = args.progress if args.progress is not None else (1.0 if tty else 5.0)
    try:
        while not stop.is_set():
            now = time.monotonic()
            if args.duration is not None and now - started >= args.duration:
                break
            try:
                item = wait_get(samples, 0.1)
            except queue.Empty:
                item = None
            while item is not None:
                recorder.write(*item)
                try:
                    item = samples.get_nowait()
                except queue.Empty:
                    item = None
            if now - last_flush >= FLUSH_S:
                last_flush = now
                recorder.flush()
            if now - last_progress >= every_s:
                last_progress = now
                _progress(recorder, now - started, tty)
    finally:
        sub.undeclare()
        session.close()
        while True:  # what arrived before the subscriber went away
            try:
                recorder.write(*samples.get_nowait())
            except queue.Empty:
                break
        recorder.finish()
        out.close()
        os.replace(tmp, path)
    if tty:
        print(file=sys.stderr)
    _summary(recorder, path, time.monotonic() - started)
    if not recorder.messages:
        print(f"lunaris record: nothing was recorded on {selector}: is the twin running?", file=sys.stderr)
        return 1
    return 0


def _sim_span(recorder: Recorder) -> str:
    return ", ".join(f"{r} t={t:.1f} s" for r, t in sorted(recorder.sim_t.items())) or "no clock yet"


def _progress(recorder: Recorder, wall_s: float, tty: bool) -> None:
    line = (f"recording: {recorder.messages} messages on {len(recorder.channels)} channels, "
            f"{recorder.bytes / 1e6:.1f} MB, {wall_s:.0f} s ({_sim_span(recorder)})")
    if tty:
        print(f"\r\x1b[2K{line}", end="", file=sys.stderr, flush=True)
    else:
        print(line, file=sys.stderr, flush=True)


def _summary(recorder: Recorder, path: Path, wall_s: float) -> None:
    print(f"wrote {path}: {recorder.messages} messages on {len(recorder.channels)} channels "
          f"in {wall_s:.1f} s ({_sim_span(recorder)}); {path.stat().st_size / 1e6:.2f} MB")
    for family, count in recorder.per_family.most_common():
        print(f"  {count:8d}  {family}")
    if recorder.skipped:
        print(f"  skipped {recorder.skipped} sample(s) that were not JSON telemetry")
