"""An independent ROS 2 CDR codec for the bridge tests.

The bridge serialises with ``rosbags``; the tests read its output back with
``mcap-ros2-support`` built from the ``.msg`` definitions kept in
``tests/msgdefs/`` (copied from the ROS 2 interface packages), so a mistake in
the bridge's messages cannot be hidden by the same library reading back what it
wrote. Nothing here imports the bridge.
"""

from __future__ import annotations

import re
import struct
from functools import cache
from pathlib import Path
from types import SimpleNamespace
from typing import Any, NamedTuple

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

__all__ = ["RmwAttachment", "decode", "decode_service", "encode", "encode_service",
           "parse_attachment", "schema"]

MSGDEFS = Path(__file__).resolve().parent / "msgdefs"
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def _path(typename: str) -> Path:
    pkg, _, name = typename.partition("/")
    return MSGDEFS / pkg / "msg" / f"{name.split('/')[-1]}.msg"


def _dependencies(typename: str) -> list[str]:
    """``pkg/Name`` of every message type a definition uses (bare names: the same package)."""
    pkg = typename.split("/")[0]
    out = []
    for line in _path(typename).read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or "=" in line:  # blank, comment or constant
            continue
        ftype = re.sub(r"\[.*\]$", "", line.split()[0])
        if ftype in _PRIMITIVES or ftype.startswith("string<="):
            continue
        out.append(ftype if "/" in ftype else f"{pkg}/{ftype}")
    return out


@cache
def schema(typename: str) -> str:
    """The concatenated definition (``pkg/msg/Name`` and every type it uses) that MCAP's
    ``ros2msg`` schemas hold."""
    short = typename.replace("/msg/", "/")
    parts = [_path(short).read_text()]
    seen = {short}
    todo = _dependencies(short)
    while todo:
        dep = todo.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{_path(dep).read_text()}")
        todo += _dependencies(dep)
    return "\n".join(parts)


@cache
def _decoder(typename: str):
    short = typename.replace("/msg/", "/")
    return generate_dynamic(short, schema(typename))[short]


@cache
def _encoder(typename: str):
    short = typename.replace("/msg/", "/")
    return serialize_dynamic(short, schema(typename))[short]


def decode(typename: str, payload: bytes) -> SimpleNamespace:
    """A CDR payload (with its encapsulation header) as a namespace of fields."""
    return _decoder(typename)(bytes(payload))


def encode(typename: str, msg: dict[str, Any]) -> bytes:
    """CDR (little endian, with the encapsulation header) of a dict of fields."""
    return bytes(_encoder(typename)(msg))


def _service_part(srv: str, part: str) -> tuple[str, str]:
    """(``pkg/Name_Request``, its definition) of a service's ``.srv`` file in tests/msgdefs."""
    pkg, _, name = srv.split("/")
    request, _, response = (MSGDEFS / pkg / "srv" / f"{name}.srv").read_text().partition("---")
    text = request if part == "Request" else response
    # a structure without fields carries one dummy byte, as rosidl generates it
    fields = [ln for ln in text.splitlines() if ln.split("#", 1)[0].strip()]
    return f"{pkg}/{name}_{part}", text if fields else "uint8 structure_needs_at_least_one_member"


@cache
def _service_codec(srv: str, part: str):
    name, text = _service_part(srv, part)
    return generate_dynamic(name, text)[name], serialize_dynamic(name, text)[name]


def decode_service(srv: str, part: str, payload: bytes) -> SimpleNamespace:
    """A service's ``Request`` or ``Response`` (CDR with its header) as a namespace."""
    return _service_codec(srv, part)[0](bytes(payload))


def encode_service(srv: str, part: str, fields: dict[str, Any]) -> bytes:
    """CDR (with its header) of a service's ``Request`` or ``Response``."""
    return bytes(_service_codec(srv, part)[1](fields))


class RmwAttachment(NamedTuple):
    sequence: int
    timestamp_ns: int
    gid: bytes


def parse_attachment(raw: bytes) -> RmwAttachment:
    """rmw_zenoh's attachment: int64 LE sequence, int64 LE timestamp, a length byte, the GID."""
    assert len(raw) == 33, f"attachment of {len(raw)} bytes, expected 33"
    sequence, timestamp_ns, gid_len = struct.unpack_from("<qqB", raw)
    assert gid_len == 16, f"GID length byte {gid_len}, expected 16"
    return RmwAttachment(sequence, timestamp_ns, raw[17:])
