"""The dashboard's side of a deployment: its keys in the router's rules (the configurations
of its bridges, ``zenoh-bridge-ros2dds`` per rover and a session for rmw_zenoh, are client
files, made with the others by :mod:`lunaris.deploy_secrets`).

A deployment serves a *fleet* (the rovers of docker-compose.yml, in order): each rover's
dashboard has its own ROS 2 domain and sees the plain topic names, so its keys carry the
rover's namespace (ros2dds, json) or domain (rmw_zenoh).
"""

from __future__ import annotations

import re
from pathlib import Path

from common.config import load_rover
from services.bridge import Binding, MappingFile, RoverNames, open_keyexpr, ros_name, rover_names, zenoh_key

__all__ = ["FLEET_FILES", "bridge_answers", "bridge_hears", "crew_writes", "dashboard_calls",
           "dashboard_keys", "fleet_names", "inbound_regexes"]

REPO = Path(__file__).resolve().parent.parent
# The rovers docker-compose.yml serves (in this order: the fleet, so rover i has ROS 2 domain i).
FLEET_FILES = ("config/rovers/mapp.yaml", "config/rovers/ltv.yaml")


def _topic_key(topic: str) -> str:
    """A mapping topic template as a key chunk sequence: placeholders become ``$*``."""
    return re.sub(r"\{[a-z_]*\}", "$*", topic.strip("/"))


def fleet_names(files: list[str] | tuple[str, ...] = FLEET_FILES) -> list[RoverNames]:
    return [rover_names(load_rover(REPO / f if not Path(f).is_absolute() else f)) for f in files]


def _dashboard_keys(mf: MappingFile, fleet: list[RoverNames]) -> list[tuple[int, str, str, str]]:
    """(mapping index, flavour, role, key) of every dashboard topic and service of every rover
    of the fleet in every enabled Zenoh flavour: its own namespace (ros2dds, json) and ROS 2
    domain (rmw_zenoh), component names as ``$*``; an inbound rmw_zenoh key with any type
    hash (a Humble node's as well as a Jazzy one's). The role: ``out`` (the dashboard reads
    it), ``in`` (it writes it) or ``call`` (a service: it queries it, the bridge answers)."""
    out = mf.bridge.outputs
    several = len(fleet) > 1
    prefix = mf.bridge.fleet_topic_prefix if several else mf.bridge.topic_prefix
    flavours = [f for f in ("ros2dds", "json", "rmw_zenoh") if getattr(out, f).enabled]
    got: list[tuple[int, str, str, str]] = []
    for place, rover in enumerate(fleet):
        for i, m in enumerate(mf.mappings):
            topic = "/" + _topic_key((prefix + m.topic).replace("{rover}", ros_name(rover.id)))
            b = Binding(i, m, rover.id, None, "", topic, place, several)
            role = "call" if m.kind == "service" else m.direction
            for f in flavours:
                key = zenoh_key(b, mf.bridge, f)
                if role == "in" and f == "rmw_zenoh":
                    key = key.rsplit("/", 1)[0] + "/*"
                got.append((i, f, role, key))
    return got


def dashboard_keys(mf: MappingFile, fleet: list[RoverNames]) -> tuple[list[str], list[str]]:
    """(keys the dashboard reads, keys it writes) in every enabled Zenoh flavour of a mapping,
    for each rover of the fleet. Exact to the chunk, so the one inbound topic's rule matches
    no other key (not ``json/curr_to_receiving_radio_m`` when json is off)."""
    keys = _dashboard_keys(mf, fleet)
    return (sorted({k for _, _, d, k in keys if d == "out"}),
            sorted({k for _, _, d, k in keys if d == "in"}))


def dashboard_calls(mf: MappingFile, fleet: list[RoverNames]) -> list[str]:
    """The keys of the services the dashboard may call (the crew's controls, SPEC §12a), in
    every enabled Zenoh flavour, for each rover of the fleet."""
    return sorted({k for _, _, role, k in _dashboard_keys(mf, fleet) if role == "call"})


def _open(mf: MappingFile, fleet: list[RoverNames], role: str) -> list[str]:
    """The key expressions a bridge declares for the dashboard's keys of ``role``: one for
    all the rovers of each mapping and flavour, as a bridge serving several of them does
    (:func:`~services.bridge.bindings.open_keyexpr`; a shard's is within the fleet's)."""
    groups: dict[tuple[int, str], list[str]] = {}
    for i, f, got, key in _dashboard_keys(mf, fleet):
        if got == role:
            groups.setdefault((i, f), []).append(key)
    out: set[str] = set()
    for ks in groups.values():
        shared = open_keyexpr(ks)
        out |= {shared} if shared is not None else set(ks)
    return sorted(out)


def bridge_hears(mf: MappingFile, fleet: list[RoverNames]) -> list[str]:
    """The key expressions a bridge may hear the dashboard's inbound topics on."""
    return _open(mf, fleet, "in")


def bridge_answers(mf: MappingFile, fleet: list[RoverNames]) -> list[str]:
    """The key expressions a bridge may declare its services' queryables on."""
    return _open(mf, fleet, "call")


def crew_writes(mf: MappingFile, op: str = "put") -> list[str]:
    """The twin keys the bridge writes for the crew with ``op`` (put or delete): those of the
    inbound topics and of the services (components as ``*``). A service that deletes its key
    (the rover's stop) is its only delete: the bridge may not drive the rover."""
    return sorted({re.sub(r"\{[a-z_]*\}", "*", m.key.replace("{rover}", "*"))
                   for m in mf.mappings if (m.kind == "service" or m.direction == "in")
                   and (m.write if m.kind == "service" else "put") == op})


def inbound_regexes(mf: MappingFile) -> list[str]:
    return sorted({re.sub(r"\{[a-z_]*\}", "[^/]*", m.topic) for m in mf.mappings
                   if m.direction == "in"})
