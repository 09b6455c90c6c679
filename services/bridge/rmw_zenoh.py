"""rmw_zenoh's names for a ROS 2 graph on Zenoh (ros2/rmw_zenoh ``docs/design.md``).

The topic key ``<domain>/<topic>/<pkg>::msg::dds_::<Name>_/<RIHS01 hash>`` (a service's:
``<domain>/<name>/<pkg>::srv::dds_::<Name>_/<the service type's hash>``), the liveliness
tokens of a node (``NN``), its publishers (``MP``), subscriptions (``MS``) and service servers
(``SS``), the GID of an entity and the 33-byte attachment every sample carries (a service's
request and reply carry the same layout: the client's sequence number and GID).
"""

from __future__ import annotations

import struct

import xxhash

from services.bridge.cdr import typestore
from services.bridge.srv import service_type_hash

__all__ = [
    "ATTACHMENT_LEN",
    "GID_LEN",
    "HEARTBEAT_S",
    "attachment",
    "dds_type_name",
    "entity_token",
    "gid_of",
    "mangle",
    "node_token",
    "qos_keyexpr",
    "rmw_topic_key",
    "type_hash",
]

ATTACHMENT_LEN = 33
GID_LEN = 16
# rmw_zenoh's SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD (500 ms): a RELIABLE + TRANSIENT_LOCAL
# publisher sends a sporadic heartbeat, so a subscriber that lost the last sample gets it back
# from the publisher's cache (rmw_publisher_data.cpp, jazzy 0.2.x and kilted 0.6.x).
HEARTBEAT_S = 0.5


def dds_type_name(typename: str) -> str:
    """``std_msgs/msg/Bool`` -> ``std_msgs::msg::dds_::Bool_`` (the DDS name rmw_zenoh uses)."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def type_hash(typename: str, distro: str = "jazzy") -> str:
    """REP-2016 type hash (``RIHS01_<sha256>``) as Jazzy and later advertise it; Humble's
    rmw_zenoh has none and writes ``TypeHashNotSupported``. A service (``pkg/srv/Name``):
    the hash of the service type, which rmw_zenoh puts in a service's key and tokens
    (:func:`services.bridge.srv.service_type_hash`)."""
    if distro == "humble":
        return "TypeHashNotSupported"
    if "/srv/" in typename:
        return service_type_hash(typename, distro)
    return typestore(distro).hash_rihs01(typename)


def rmw_topic_key(domain_id: int, topic: str, typename: str, distro: str = "jazzy") -> str:
    """``<domain>/<topic without its outer '/'>/<dds type>/<type hash>``; a service's key is
    made the same way from its name and service type (``std_srvs::srv::dds_::SetBool_``)."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(typename)}/{type_hash(typename, distro)}"


def mangle(name: str) -> str:
    """A ROS name as one key chunk: every ``/`` becomes ``%`` (``/`` alone becomes ``%``)."""
    return name.replace("/", "%") or "%"


def qos_keyexpr(transient_local: bool, depth: int) -> str:
    """rmw_zenoh's compact QoS chunk: ``rel:dur:hist,depth:dl_s,dl_ns:ls_s,ls_ns:liv,lease_s,
    lease_ns`` where a field equal to rmw_zenoh's default (RELIABLE, VOLATILE, KEEP_LAST, 42,
    infinite durations, AUTOMATIC) is left empty. TRANSIENT_LOCAL is durability 1."""
    durability = "1" if transient_local else ""
    depth_s = "" if depth == 42 else str(depth)
    return f":{durability}:,{depth_s}:,:,:,,"


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, node: str,
               enclave: str = "/") -> str:
    """``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>``."""
    return "/".join(["@ros2_lv", str(domain_id), zid, str(node_id), str(node_id), "NN",
                     mangle(enclave), mangle(namespace), node])


def entity_token(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str,
                 namespace: str, node: str, topic: str, typename: str, qos: str,
                 distro: str = "jazzy", enclave: str = "/") -> str:
    """A publisher (``MP``), subscription (``MS``) or service server (``SS``) token: the node's
    chunks, then the mangled topic (or service name), the DDS type name, the type hash and the
    QoS chunk."""
    assert kind in ("MP", "MS", "SS", "SC")
    return "/".join(["@ros2_lv", str(domain_id), zid, str(node_id), str(entity_id), kind,
                     mangle(enclave), mangle(namespace), node, mangle(topic),
                     dds_type_name(typename), type_hash(typename, distro), qos])


def gid_of(token: str) -> bytes:
    """The 16-byte GID of an entity, as rmw_zenoh computes it (``liveliness_utils.cpp``): the
    XXH3-128 hash (seed 0) of the entity's whole liveliness token, its low 64 bits then its
    high 64 bits, each little endian (a ``memcpy`` on a little-endian host): the 128-bit value
    in little-endian order. It is what ``ros2 topic info -v`` reports as the GID."""
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_LEN, "little")


def attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    """The 33 bytes rmw_zenoh attaches to every sample: sequence number (int64, little
    endian, from 1, one per publisher), source timestamp [ns since the epoch] (int64, little
    endian), the GID length (one byte, 16) and the GID."""
    if len(gid) != GID_LEN:
        raise ValueError(f"gid must be {GID_LEN} bytes, got {len(gid)}")
    return struct.pack("<qqB", sequence, timestamp_ns, GID_LEN) + gid
