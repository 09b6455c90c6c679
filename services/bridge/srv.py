"""ROS 2 services as bytes and names: the types a mapping's ``kind: service`` entry may use.

The crew's controls (SPEC §12a) are ``std_srvs`` services. Their definitions are written out
here (the ``.srv`` files of ``ros-std-srvs``, the tests read them from tests/msgdefs), because
rosbags' type stores hold messages only; each is registered, with its ``_Event`` message, in a
type store of its own (rosbags returns a new store per call: the messages' cached one is
never changed), which gives

- the request and response as CDR with the 4-byte encapsulation header, both ways
  (:func:`decode_request`, :func:`encode_response`), as rmw_zenoh and zenoh-bridge-ros2dds
  carry them (an empty request is one dummy byte, ``structure_needs_at_least_one_member``);
- the REP-2016 type hash of the *service* (:func:`service_type_hash`), which is what rmw_zenoh
  puts in a service's key and tokens. rosbags' own ``service_msgs/msg/ServiceEventInfo`` has
  ``client_gid`` as ``char[16]``; rosidl hashes it as ``uint8[16]`` (a ``.msg`` ``char`` is an
  IDL ``uint8``), so it is replaced here: the hashes are then the published ones
  (``share/std_srvs/srv/*.json``, checked by tests/services/test_bridge_model.py).
"""

from __future__ import annotations

from functools import cache
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from common.messages import BadInput

__all__ = ["SERVICE_TYPES", "decode_request", "encode_response", "request_fields",
           "response_fields", "service_type_hash"]

# name -> (request definition, response definition), as in the .srv files
SERVICE_TYPES: dict[str, tuple[str, str]] = {
    "std_srvs/srv/SetBool": ("bool data", "bool success\nstring message"),
    "std_srvs/srv/Trigger": ("", "bool success\nstring message"),
    "std_srvs/srv/Empty": ("", ""),
}
_DUMMY = "structure_needs_at_least_one_member"  # what an empty structure carries on the wire
_SERVICE_EVENT_INFO = ("uint8 event_type\nbuiltin_interfaces/Time stamp\nuint8[16] client_gid\n"
                       "int64 sequence_number\n")


def _srv_names(value: Any) -> Any:
    """rosbags files ``pkg/srv/X`` under ``pkg/srv/msg/X``; rosidl's name is ``pkg/srv/X``."""
    if isinstance(value, str):
        return value.replace("/srv/msg/", "/srv/")
    if isinstance(value, list | tuple):
        return type(value)(_srv_names(v) for v in value)
    if isinstance(value, dict):
        return {_srv_names(k): _srv_names(v) for k, v in value.items()}
    return value


@cache
def _store(distro: str = "jazzy") -> Any:
    store = get_typestore({"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}[distro])
    for table in (store.fielddefs, store.types):
        table.pop("service_msgs/msg/ServiceEventInfo", None)
    defs = dict(get_types_from_msg(_SERVICE_EVENT_INFO, "service_msgs/msg/ServiceEventInfo"))
    for srv, (request, response) in SERVICE_TYPES.items():
        defs.update(get_types_from_msg(request, f"{srv}_Request"))
        defs.update(get_types_from_msg(response, f"{srv}_Response"))
        defs.update(get_types_from_msg(f"service_msgs/msg/ServiceEventInfo info\n"
                                       f"{srv}_Request[<=1] request\n{srv}_Response[<=1] response\n",
                                       f"{srv}_Event"))
        defs.update(get_types_from_msg(f"{srv}_Request request_message\n"
                                       f"{srv}_Response response_message\n"
                                       f"{srv}_Event event_message\n", srv))
    store.register(_srv_names(defs))
    return store


def _fields(typename: str) -> dict[str, str]:
    _, fields = _store().fielddefs[typename]
    return {name: spec[0] for name, (_node, spec) in fields if name != _DUMMY}


def request_fields(srv: str) -> dict[str, str]:
    """The request's fields and their ROS types (``{"data": "bool"}``; none for Trigger)."""
    return _fields(f"{srv}_Request")


def response_fields(srv: str) -> dict[str, str]:
    """The response's fields and their ROS types (``{"success": "bool", "message": "string"}``)."""
    return _fields(f"{srv}_Response")


def service_type_hash(srv: str, distro: str = "jazzy") -> str:
    """REP-2016 hash of a service type (``RIHS01_<sha256>``), as rmw_zenoh keys a service;
    Humble's rmw_zenoh writes ``TypeHashNotSupported``."""
    if distro == "humble":
        return "TypeHashNotSupported"
    return str(_store(distro).hash_rihs01(srv))


def decode_request(srv: str, payload: bytes, distro: str = "jazzy") -> dict[str, Any]:
    """A request's fields from CDR (with its header, either endianness); :class:`BadInput`
    when the bytes are not that request. A request without fields (Trigger, Empty) is not
    read at all: whatever a client sends for it (one dummy byte, or none) is that request."""
    if not request_fields(srv):
        return {}
    try:
        msg = _store(distro).deserialize_cdr(bytes(payload), f"{srv}_Request")
    except Exception:  # rosbags raises assorted errors on truncated or foreign bytes
        raise BadInput(f"not a CDR {srv} request ({len(payload)} bytes)") from None
    return {name: getattr(msg, name) for name in request_fields(srv)}


def encode_response(srv: str, fields: dict[str, Any], distro: str = "jazzy") -> bytes:
    """A response as CDR (little endian, with its header); fields not given are zero."""
    store = _store(distro)
    kinds = response_fields(srv)
    values: dict[str, Any] = {
        name: bool(fields.get(name, False)) if kind == "bool"
        else str(fields.get(name, "")) if kind == "string" else fields.get(name, 0)
        for name, kind in kinds.items()} or {_DUMMY: 0}
    typename = f"{srv}_Response"
    return bytes(store.serialize_cdr(store.types[typename](**values), typename))
