"""The dashboard's side of a deployment: its keys in the router's rules, and the
configurations of its bridges (``zenoh-bridge-ros2dds`` per rover, a session for rmw_zenoh).

A deployment serves a *fleet* (the rovers of docker-compose.yml, in order): each rover's
dashboard has its own ROS 2 domain and sees the plain topic names, so its keys carry the
rover's namespace (ros2dds, json) or domain (rmw_zenoh).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from common.config import load_rover
from services.bridge.bindings import Binding, RoverNames, open_keyexpr, rover_names, zenoh_key
from services.bridge.mapping import MappingFile, ros_name

__all__ = ["FLEET_FILES", "bridge_hears", "dashboard_files", "dashboard_keys", "fleet_names",
           "inbound_regexes",
           "ros2dds_config", "rmw_zenoh_config"]

REPO = Path(__file__).resolve().parent.parent
# The rovers docker-compose.yml serves (in this order: the fleet, so rover i has ROS 2 domain i).
FLEET_FILES = ("config/rovers/mapp.yaml", "config/rovers/ltv.yaml")


def _topic_key(topic: str) -> str:
    """A mapping topic template as a key chunk sequence: placeholders become ``$*``."""
    return re.sub(r"\{[a-z_]*\}", "$*", topic.strip("/"))


def fleet_names(files: list[str] | tuple[str, ...] = FLEET_FILES) -> list[RoverNames]:
    return [rover_names(load_rover(REPO / f if not Path(f).is_absolute() else f)) for f in files]


def _dashboard_keys(mf: MappingFile, fleet: list[RoverNames]) -> list[tuple[int, str, str, str]]:
    """(mapping index, flavour, direction, key) of every dashboard topic of every rover of the
    fleet in every enabled Zenoh flavour: its own namespace (ros2dds, json) and ROS 2 domain
    (rmw_zenoh), component names as ``$*``; an inbound rmw_zenoh key with any type hash (a
    Humble node's as well as a Jazzy one's)."""
    out = mf.bridge.outputs
    several = len(fleet) > 1
    prefix = mf.bridge.fleet_topic_prefix if several else mf.bridge.topic_prefix
    flavours = [f for f in ("ros2dds", "json", "rmw_zenoh") if getattr(out, f).enabled]
    got: list[tuple[int, str, str, str]] = []
    for place, rover in enumerate(fleet):
        for i, m in enumerate(mf.mappings):
            topic = "/" + _topic_key((prefix + m.topic).replace("{rover}", ros_name(rover.id)))
            b = Binding(i, m, rover.id, None, "", topic, place, several)
            for f in flavours:
                key = zenoh_key(b, mf.bridge, f)
                if m.direction == "in" and f == "rmw_zenoh":
                    key = key.rsplit("/", 1)[0] + "/*"
                got.append((i, f, m.direction, key))
    return got


def dashboard_keys(mf: MappingFile, fleet: list[RoverNames]) -> tuple[list[str], list[str]]:
    """(keys the dashboard reads, keys it writes) in every enabled Zenoh flavour of a mapping,
    for each rover of the fleet. Exact to the chunk, so the one inbound topic's rule matches
    no other key (not ``json/curr_to_receiving_radio_m`` when json is off)."""
    keys = _dashboard_keys(mf, fleet)
    return (sorted({k for _, _, d, k in keys if d == "out"}),
            sorted({k for _, _, d, k in keys if d == "in"}))


def bridge_hears(mf: MappingFile, fleet: list[RoverNames]) -> list[str]:
    """The key expressions a bridge may hear the dashboard's inbound topics on: one for all
    the rovers of each topic and flavour, as a bridge serving several of them subscribes
    (:func:`~services.bridge.bindings.open_keyexpr`; a shard's is within the fleet's)."""
    groups: dict[tuple[int, str], list[str]] = {}
    for i, f, direction, key in _dashboard_keys(mf, fleet):
        if direction == "in":
            groups.setdefault((i, f), []).append(key)
    out: set[str] = set()
    for ks in groups.values():
        shared = open_keyexpr(ks)
        out |= {shared} if shared is not None else set(ks)
    return sorted(out)


def ros2dds_config(password: str, ca_pem: bytes | None, rover: str, domain: int,
                   inbound: list[str], namespace: str | None,
                   connect: str = "tls/127.0.0.1:7447") -> dict[str, Any]:
    """zenoh-bridge-ros2dds for the dashboard of one rover on DDS (the compose profile
    ``ros2dds``, one container per rover): the ``dashboard`` identity, host networking, so it
    reaches the router on the host's port (``connect``). In a fleet its namespace is the rover's
    (``/mapp_1``, the mapping's ``fleet_namespace``): the bridge's ``mapp_1/battery_state``
    is ``/battery_state`` in the rover's DDS domain, the dashboard's plain name; a fleet of
    one rover has no namespace (the bridge's keys are the plain names). Zenoh -> DDS: every
    topic of the rover; DDS -> Zenoh: only the inbound topics (the router's access control
    enforces the same limit)."""
    conf = _client("dashboard", password, ca_pem, connect)
    plugin: dict[str, Any] = {"id": f"lunaris-{ros_name(rover)}", "domain": domain,
                              "allow": {"publishers": inbound, "subscribers": [".*"]}}
    if namespace is not None:
        plugin["namespace"] = namespace
    conf["plugins"] = {"ros2dds": plugin}
    return conf


def rmw_zenoh_config(password: str, ca_pem: bytes | None, connect: str) -> dict[str, Any]:
    """The Zenoh session of a dashboard on rmw_zenoh (``ZENOH_SESSION_CONFIG_URI``): a client of
    the deployment's router as ``dashboard``, timestamping on as rmw_zenoh's own sessions."""
    conf = _client("dashboard", password, ca_pem, connect)
    conf["timestamping"] = {"enabled": {"router": True, "peer": True, "client": True}}
    return conf


def dashboard_files(password: str, ca_pem: bytes | None, mf: MappingFile,
                    fleet: list[RoverNames], connect: str,
                    local: str = "tls/127.0.0.1:7447") -> dict[str, dict[str, Any]]:
    """The dashboards' configurations, by file name: a ``zenoh-bridge-ros2dds`` per rover of
    the fleet (reaching the router at ``local``, its host's port) and the rmw_zenoh session
    (at ``connect``)."""
    base = mf.bridge.outputs.ros2.domain_id or 0
    several = len(fleet) > 1
    files = {f"zenoh-bridge-ros2dds-{r.id}.json5": ros2dds_config(
        password, ca_pem, r.id, mf.bridge.rover_domains.get(r.id, base + place),
        inbound_regexes(mf),
        mf.bridge.fleet_namespace.replace("{rover}", ros_name(r.id)) if several else None, local)
        for place, r in enumerate(fleet)}
    files["rmw-zenoh-dashboard.json5"] = rmw_zenoh_config(password, ca_pem, connect)
    return files


def inbound_regexes(mf: MappingFile) -> list[str]:
    return sorted({re.sub(r"\{[a-z_]*\}", "[^/]*", m.topic) for m in mf.mappings
                   if m.direction == "in"})




def _client(user: str, password: str, ca_pem: bytes | None, connect: str) -> dict[str, Any]:
    from lunaris.deploy_secrets import client_config  # one definition of a client's configuration

    return client_config(user, password, ca_pem, connect)
