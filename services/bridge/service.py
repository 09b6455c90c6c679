"""Bridge service: the twin's keys on the dashboard's ROS 2 topics, both ways (SPEC §7).

The mapping file (``config/bridge/default.yaml`` unless ``--bridge-config``) is validated at
start-up; with a problem the service prints every one and exits with status 2. Then:

- every outbound topic is republished as soon as its twin key is published (folded per batch
  of samples, never on a timer), in each enabled flavour: ``ros2dds`` (CDR on the topic name),
  ``rmw_zenoh`` (CDR on the rmw_zenoh key with its attachment; the node, publisher and
  subscription liveliness tokens are held for the life of the service) and ``json``;
- the DiagnosticArray follows the faults in effect (each owning service's
  ``faults/active/<service>``, replayed from its cache when the bridge joins late) and each
  component's telemetry (STALE when it stops), published on every change of the active
  faults and every ``diagnostics_period_s``;
- an inbound topic (any flavour) becomes a twin input; a message that cannot be decoded or
  carries a bad value is refused with a rejection event, like any bad input.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from common import keys
from common.config import ConfigError, Rover
from common.connection import write
from common.messages import ActiveFault, ActiveFaults, BadInput, decode
from common.runtime import Runtime, Sample
from services.bridge.bindings import Binding, expand, rover_names
from services.bridge.cdr import decode_cdr, encode_cdr
from services.bridge.convert import (
    battery_state_message,
    components,
    data_key,
    diagnostic_array_message,
    diagnostic_statuses,
    in_payload,
    odometry_message,
    out_message,
)
from services.bridge.mapping import MappingFile, load_mapping
from services.bridge.rmw_zenoh import (
    attachment,
    entity_token,
    gid_of,
    node_token,
    qos_keyexpr,
    rmw_topic_key,
)

__all__ = ["DEFAULT_MAPPING", "resolve_mapping", "serve"]

REPO = Path(__file__).resolve().parents[2]
DEFAULT_MAPPING = REPO / "config" / "bridge" / "default.yaml"
PUBLISHER_DEPTH = 1  # the last-value cache: TRANSIENT_LOCAL, KEEP_LAST 1
SUBSCRIPTION_DEPTH = 10
CDR = zenoh.Encoding.APPLICATION_CDR
JSON = zenoh.Encoding.APPLICATION_JSON


def resolve_mapping(mapping_file: str | None) -> Path:
    """The mapping file: the default one (``config/bridge/default.yaml`` of the working
    directory, as in the container image, else of the source tree), or a path as given
    (relative to the working directory) or, failing that, relative to the repository."""
    if mapping_file is None:
        local = Path("config/bridge/default.yaml")
        return local.resolve() if local.is_file() else DEFAULT_MAPPING
    path = Path(mapping_file)
    if not path.is_absolute() and not path.exists() and (REPO / path).exists():
        return REPO / path
    return path


class _Outlet:
    """One outbound topic of one binding in every enabled flavour."""

    def __init__(self, rt: Runtime, b: Binding, mf: MappingFile, zid: str, entity_id: int):
        out = mf.bridge.outputs
        self.rt, self.binding, self.distro = rt, b, mf.bridge.ros_distro
        self.type = b.mapping.type
        bare = b.topic.strip("/")
        self.dds_key = bare if out.ros2dds.enabled else None
        self.json_key = f"{out.json.prefix}/{bare}" if out.json.enabled else None
        self.rmw_key: str | None = None
        if out.rmw_zenoh.enabled:
            r = out.rmw_zenoh
            self.rmw_key = rmw_topic_key(r.domain_id, b.topic, self.type, self.distro)
            token = entity_token(r.domain_id, zid, 0, entity_id, "MP", r.namespace, r.node,
                                 b.topic, self.type, qos_keyexpr(True, PUBLISHER_DEPTH), self.distro)
            rt.keep(rt.zenoh_session.liveliness().declare_token(token))
            self.gid = gid_of(token)
            self.sequence = 0

    def publish(self, msg: dict) -> None:
        if self.dds_key or self.rmw_key:
            cdr = encode_cdr(self.type, msg, self.distro)
            if self.dds_key:
                self.rt.publish_bytes(self.dds_key, cdr, CDR)
            if self.rmw_key:
                self.sequence += 1
                self.rt.publish_bytes(self.rmw_key, cdr, CDR,
                                      attachment(self.sequence, time.time_ns(), self.gid))
        if self.json_key:
            self.rt.publish_bytes(self.json_key, msgspec.json.encode(msg), JSON)


def _family(key_template: str) -> keys.Family:
    found = keys.family_of_template(key_template)
    assert found is not None, "the mapping was validated"
    return found[0]


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None,
          mapping_file: str | None = None) -> None:
    path = resolve_mapping(mapping_file)
    try:
        mf = load_mapping(path)
        bindings = expand(mf, [rover_names(r) for r in rovers], source=str(path))
    except ConfigError as exc:
        print(exc, file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    opts = mf.bridge
    rover_cfg = {r.id: r for r in rovers}
    zid = str(rt.zenoh_session.info.zid())
    rmw = opts.outputs.rmw_zenoh
    if rmw.enabled:
        rt.keep(rt.zenoh_session.liveliness().declare_token(
            node_token(rmw.domain_id, zid, 0, rmw.namespace, rmw.node)))

    # -- outbound -----------------------------------------------------------------------------
    by_key: dict[str, list[_Outlet]] = {}  # twin key -> its outlets
    payload_type: dict[str, type[msgspec.Struct]] = {}
    diag_outlets: dict[str, list[_Outlet]] = {}  # rover -> DiagnosticArray outlets
    # rmw_zenoh entity ids: the node is 0, each binding its position in the list from 1
    for entity_id, b in enumerate(bindings, start=1):
        if b.mapping.direction == "in":
            continue
        outlet = _Outlet(rt, b, mf, zid, entity_id)
        if b.mapping.convert == "diagnostics":
            diag_outlets.setdefault(b.rover, []).append(outlet)
        else:
            by_key.setdefault(b.key, []).append(outlet)
            payload_type[b.key] = _family(b.mapping.key).payload

    latest: dict[str, msgspec.Struct] = {}
    dirty: set[str] = set()

    def stamp_ns(t_s: float) -> int:
        return time.time_ns() if opts.stamp == "wall" else int(round(t_s * 1e9))

    def message(outlet: _Outlet, payload: Any) -> dict | None:
        m = outlet.binding.mapping
        if m.convert == "battery_state":
            return battery_state_message(payload, rover_cfg[outlet.binding.rover].battery,
                                         stamp_ns(payload.t_s), m.frame_id, m.options,
                                         opts.ros_distro)
        if m.convert == "odometry":
            return odometry_message(payload, stamp_ns(payload.t_s), m.frame_id, m.options)
        return out_message(m, payload)

    # -- diagnostics: the faults in effect and each component's last telemetry -----------------
    # rover -> owning service -> its faults in effect (a view of the owners' records)
    in_effect: dict[str, dict[str, list[ActiveFault]]] = {r: {} for r in diag_outlets}
    comps = {rid: components(rover_cfg[rid]) for rid in in_effect}
    started = time.monotonic()
    last_seen: dict[str, float] = {}  # component data key -> monotonic time
    alive_of = {data_key(rid, c): (rid, c) for rid, cs in comps.items() for c in cs}
    diag_dirty: set[str] = set()

    def ages(rover: str) -> dict[str, float | None]:
        now = time.monotonic()
        return {c: now - last_seen.get(data_key(rover, c), started) for c in comps[rover]}

    def publish_diagnostics(rover: str) -> None:
        active = sorted((f for fs in in_effect[rover].values() for f in fs),
                        key=lambda f: (f.since_t_s, f.key))
        statuses = diagnostic_statuses(rover, comps[rover], active, ages(rover), opts.stale_after_s)
        msg = None
        for outlet in diag_outlets[rover]:
            msg = msg or diagnostic_array_message(statuses, stamp_ns(rt.t_s.get(rover, 0.0)),
                                                  outlet.binding.mapping.frame_id)
            outlet.publish(msg)

    def on_twin(s: Sample) -> None:
        alive = alive_of.get(s.key)
        if alive is not None:
            now = time.monotonic()
            if now - last_seen.get(s.key, started) > opts.stale_after_s:
                diag_dirty.add(alive[0])  # back from STALE
            last_seen[s.key] = now
        if s.key in by_key and not s.deleted:
            latest[s.key] = decode(s.payload, payload_type[s.key])
            dirty.add(s.key)

    def on_faults(s: Sample) -> None:
        if s.rover not in in_effect or s.deleted:
            return
        answer = decode(s.payload, ActiveFaults)
        in_effect[s.rover][answer.service] = answer.faults
        diag_dirty.add(s.rover)

    def flush() -> None:
        for key in sorted(dirty):
            payload = latest[key]
            for outlet in by_key[key]:
                msg = message(outlet, payload)
                if msg is not None:
                    outlet.publish(msg)
        dirty.clear()
        for rover in sorted(diag_dirty):
            publish_diagnostics(rover)
        diag_dirty.clear()

    def periodic_diagnostics() -> None:
        for rover in diag_outlets:
            publish_diagnostics(rover)

    # One subscription per family of keys (lunaris/*/rail/*/state ...); samples are told apart
    # by their exact key above.
    patterns = {_family(o.binding.mapping.key).pattern() for ol in by_key.values() for o in ol}
    patterns |= {_family(data_key("{rover}", c)).pattern() for cs in comps.values() for c in cs}
    for pattern in sorted(patterns):
        rt.subscribe(pattern, on_twin, history=True)
    if diag_outlets:
        rt.subscribe(keys.faults_active("*", "*"), on_faults, history=True)
        rt.every(opts.diagnostics_period_s, periodic_diagnostics)
    rt.after_batch(flush)

    # -- inbound ------------------------------------------------------------------------------

    def on_inbound(b: Binding, flavour: str, key: str, payload: bytes) -> None:
        try:
            if flavour == "json":
                try:
                    msg = msgspec.json.decode(payload)
                except msgspec.DecodeError as exc:
                    raise BadInput(f"malformed JSON: {exc}") from None
                if not isinstance(msg, dict):
                    raise BadInput(f"expected a JSON object of {b.mapping.type} fields")
            else:
                msg = decode_cdr(b.mapping.type, payload, opts.ros_distro)
            value = in_payload(b.mapping, msg)
        except BadInput as exc:
            rt.reject(b.rover, key, str(exc))
            return
        write(rt.zenoh_session, b.key, msgspec.json.encode(value))

    def listen(b: Binding, flavour: str, keyexpr: str) -> None:
        def on_sample(s: zenoh.Sample) -> None:
            if s.kind == zenoh.SampleKind.PUT:
                rt.call_soon(on_inbound, b, flavour, str(s.key_expr), s.payload.to_bytes())
        rt.keep(rt.zenoh_session.declare_subscriber(keyexpr, on_sample))

    for entity_id, b in enumerate(bindings, start=1):
        if b.mapping.direction != "in":
            continue
        bare = b.topic.strip("/")
        if opts.outputs.ros2dds.enabled:
            listen(b, "ros2dds", bare)
        if opts.outputs.json.enabled:
            listen(b, "json", f"{opts.outputs.json.prefix}/{bare}")
        if rmw.enabled:
            # Any type hash: a Humble node (TypeHashNotSupported) is heard as well as a Jazzy one.
            key = rmw_topic_key(rmw.domain_id, b.topic, b.mapping.type, opts.ros_distro)
            listen(b, "rmw_zenoh", key.rsplit("/", 1)[0] + "/*")
            rt.keep(rt.zenoh_session.liveliness().declare_token(entity_token(
                rmw.domain_id, zid, 0, entity_id, "MS", rmw.namespace, rmw.node, b.topic,
                b.mapping.type, qos_keyexpr(False, SUBSCRIPTION_DEPTH), opts.ros_distro)))

    for rover in diag_outlets:
        diag_dirty.add(rover)

