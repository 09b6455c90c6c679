"""Bridge service: the twin's keys on the dashboard's ROS 2 topics, both ways (SPEC §7).

The mapping file (``config/bridge/default.yaml`` unless ``--bridge-config``) is validated at
start-up; with a problem the service prints every one and exits with status 2. Then:

- every outbound topic follows its twin key (:mod:`services.bridge.outlets`): each sample
  (folded per batch of samples), or with the mapping's ``rate_hz`` the newest at that rate,
  a change of a discrete field (a rail's state, the pack's faults) at once; in each enabled
  flavour: ``ros2dds`` (CDR on the topic name), ``rmw_zenoh`` (CDR on the rmw_zenoh key with
  its attachment; the node, publisher and subscription liveliness tokens are held for the
  life of the service) and ``json``;
- the DiagnosticArray follows the faults in effect (each owning service's
  ``faults/active/<service>``, replayed from its cache when the bridge joins late) and each
  component's telemetry (STALE when it stops), published on every change of the active
  faults and every ``diagnostics_period_s``;
- an inbound topic (any flavour) becomes a twin input; a message that cannot be decoded or
  carries a bad value is refused with a rejection event, like any bad input.
"""

from __future__ import annotations

import heapq
import sys
import time
from collections.abc import Callable
from typing import Any

import msgspec
import msgspec.inspect
import zenoh

from common import keys
from common.config import ConfigError, Rover
from common.connection import write
from common.datafile import field_kind, struct_fields
from common.messages import ActiveFault, ActiveFaults, BadInput, decode
from common.runtime import Runtime, Sample
from services.bridge.bindings import Binding, expand, open_keyexpr, rover_names, zenoh_key
from services.bridge.cdr import decode_cdr, encode_cdr, restamp
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
from services.bridge.mapping import load_mapping, resolve_mapping
from services.bridge.outlets import Feed, Outlet, Shared
from services.bridge.rmw_zenoh import entity_token, node_token, qos_keyexpr
from services.bridge.ros2_node import Ros2Graph, Ros2Unavailable

__all__ = ["serve"]

SUBSCRIPTION_DEPTH = 10
RATE_TIMER_S = 0.02  # how often the samples held back by a rate are looked at
DIAG_SLOT_S = 0.02  # the shortest step of the periodic diagnostics spread over a period


def _family(key_template: str) -> keys.Family:
    found = keys.family_of_template(key_template)
    assert found is not None, "the mapping was validated"
    return found[0]


def _discrete_fields(payload: type[msgspec.Struct]) -> tuple[str, ...]:
    """The fields of a payload whose every change is news (flags, states, faults, counts):
    all but the floating-point values (alone or in lists, such as the battery's polarisation
    voltages) and the time."""
    out = []
    for f in struct_fields(payload):
        typ = f.type
        if isinstance(typ, msgspec.inspect.ListType):
            typ = typ.item_type
        kind, _ = field_kind(typ)
        if f.name != "t_s" and (kind != "number" or isinstance(typ, msgspec.inspect.IntType)):
            out.append(f.name)
    return tuple(out)


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None,
          mapping_file: str | None = None, fleet: list[str] | None = None,
          clock: Callable[[], float] = time.monotonic) -> None:
    """Serve ``rovers``, members of ``fleet`` (the ids of every rover of the deployment, in
    order, whichever bridge serves each; default: these rovers). ``clock`` times the rates."""
    path = resolve_mapping(mapping_file)
    try:
        mf = load_mapping(path)
        bindings = expand(mf, [rover_names(r) for r in rovers], source=str(path), fleet=fleet)
    except ConfigError as exc:
        print(exc, file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    opts = mf.bridge
    graph: Ros2Graph | None = None
    if opts.outputs.ros2.enabled:
        try:
            graph = Ros2Graph(opts.outputs.ros2.node, opts.outputs.ros2.namespace)
            for b in bindings:  # every message type there, before anything is declared
                graph.message_class(b.mapping.type)
        except Ros2Unavailable as exc:
            print(f"{path}: bridge.outputs.ros2: {exc}", file=sys.stderr, flush=True)
            raise SystemExit(2) from None
        rt.on_exit(graph.close)
    rover_cfg = {r.id: r for r in rovers}
    shared = Shared(rt, opts, str(rt.zenoh_session.info.zid()), graph, clock)
    rmw = opts.outputs.rmw_zenoh
    if rmw.enabled:
        for domain in sorted({shared.rmw_domain(b) for b in bindings}):
            rt.keep(rt.zenoh_session.liveliness().declare_token(
                node_token(domain, shared.zid, 0, rmw.namespace, rmw.node)))

    # -- outbound -----------------------------------------------------------------------------
    feeds: dict[str, Feed] = {}  # twin key -> its feed
    discrete_of: dict[type, tuple[str, ...]] = {}
    diag_outlets: dict[str, list[Outlet]] = {}  # rover -> DiagnosticArray outlets
    # rmw_zenoh entity ids: the node is 0, each binding its position in the list from 1
    for entity_id, b in enumerate(bindings, start=1):
        if b.mapping.direction == "in":
            continue
        if b.mapping.convert == "diagnostics":
            diag_outlets.setdefault(b.rover, []).append(Outlet(shared, b, entity_id, None))
            continue
        feed = feeds.get(b.key)
        if feed is None:
            typ = _family(b.mapping.key).payload
            feed = feeds[b.key] = Feed(typ, discrete_of.setdefault(typ, _discrete_fields(typ)))
        outlet = Outlet(shared, b, entity_id, feed)
        feed.outlets.append(outlet)
        feed.unrated |= outlet.period_s == 0.0
        feed.idle |= outlet.idle

    dirty: set[str] = set()  # twin keys whose newest sample some outlet sends now

    def stamp_ns(t_s: float) -> int:
        return time.time_ns() if opts.stamp == "wall" else int(round(t_s * 1e9))

    def message(outlet: Outlet, payload: Any) -> dict | None:
        m = outlet.binding.mapping
        if m.convert == "battery_state":
            return battery_state_message(payload, rover_cfg[outlet.binding.rover].battery,
                                         stamp_ns(payload.t_s), m.frame_id, m.options,
                                         opts.ros_distro)
        if m.convert == "odometry":
            return odometry_message(payload, stamp_ns(payload.t_s), m.frame_id, m.options)
        return out_message(m, payload, stamp_ns(payload.t_s))

    # -- diagnostics: the faults in effect and each component's last telemetry -----------------
    # rover -> owning service -> its faults in effect (a view of the owners' records)
    in_effect: dict[str, dict[str, list[ActiveFault]]] = {r: {} for r in diag_outlets}
    comps = {rid: components(rover_cfg[rid]) for rid in in_effect}
    started = time.monotonic()
    last_seen: dict[str, float] = {}  # component data key -> monotonic time
    alive_of = {data_key(rid, c): (rid, c) for rid, cs in comps.items() for c in cs}
    diag_dirty: set[str] = set()

    comp_keys = {rid: [(c, data_key(rid, c)) for c in cs] for rid, cs in comps.items()}

    def ages(rover: str) -> dict[str, float | None]:
        now = time.monotonic()
        return {c: now - last_seen.get(key, started) for c, key in comp_keys[rover]}

    def publish_diagnostics(rover: str) -> None:
        """The rover's DiagnosticArray; statuses unchanged since the last one (the periodic
        republishing of a quiet rover) are not encoded again, only stamped anew."""
        active = sorted((f for fs in in_effect[rover].values() for f in fs),
                        key=lambda f: (f.since_t_s, f.key))
        statuses = diagnostic_statuses(rover, comps[rover], active, ages(rover), opts.stale_after_s)
        t_ns = stamp_ns(rt.t_s.get(rover, 0.0))
        for outlet in diag_outlets[rover]:
            msg = diagnostic_array_message(statuses, t_ns, outlet.binding.mapping.frame_id)
            cdr = None
            if outlet.encodes:
                if outlet.last is not None and outlet.last[0] == statuses:
                    cdr = restamp(outlet.last[1], t_ns)
                else:
                    cdr = encode_cdr(outlet.type, msg, opts.ros_distro)
                    outlet.last = (statuses, cdr)
            outlet.publish(msg, cdr)

    def on_twin(s: Sample) -> None:
        alive = alive_of.get(s.key)
        if alive is not None:
            now = time.monotonic()
            if now - last_seen.get(s.key, started) > opts.stale_after_s:
                diag_dirty.add(alive[0])  # back from STALE
            last_seen[s.key] = now
        feed = feeds.get(s.key)
        if feed is not None and not s.deleted:
            feed.payload = payload = decode(s.payload, feed.type)
            feed.seq += 1
            if feed.unrated or feed.idle or feed.discrete_of(payload) != feed.discrete:
                dirty.add(s.key)

    def on_faults(s: Sample) -> None:
        if s.rover not in in_effect or s.deleted:
            return
        answer = decode(s.payload, ActiveFaults)
        if in_effect[s.rover].get(answer.service) != answer.faults:
            in_effect[s.rover][answer.service] = answer.faults
            # at once, not after the batch: the telemetry a fault sets off (a rail tripping,
            # the PDM re-solving) arrives in the same moment and must not go first
            diag_dirty.discard(s.rover)
            publish_diagnostics(s.rover)

    def flush() -> None:
        """The samples some outlet sends at once: every one for an outlet without a rate, the
        first after an outlet's idle spell, and a change of a discrete field for all."""
        now = shared.clock()
        for key in sorted(dirty):
            rt.urgent_first()  # a fleet's tick is thousands of samples
            feed = feeds[key]
            discrete = feed.discrete_of(feed.payload)
            changed, feed.discrete, feed.idle = discrete != feed.discrete, discrete, False
            for outlet in feed.outlets:
                if outlet.idle:
                    outlet.idle = False
                    outlet.send(message)
                    outlet.schedule(now)
                elif changed or outlet.period_s == 0.0:
                    outlet.send(message)
        dirty.clear()
        for rover in sorted(diag_dirty):
            publish_diagnostics(rover)
        diag_dirty.clear()

    def flush_due() -> None:
        """The outlets whose rate allows the newest sample: sent, or idle when none came."""
        now = shared.clock()
        due = shared.due
        while due and due[0][0] <= now:
            rt.urgent_first()
            _, _, outlet = heapq.heappop(due)
            feed = outlet.feed
            assert feed is not None, "an outlet with a rate has a feed"
            if outlet.sent_seq == feed.seq:
                outlet.idle = feed.idle = True
            else:
                outlet.send(message)
                outlet.schedule(now)

    # The periodic DiagnosticArrays are spread over the period (a fleet's rovers one after the
    # other, a timer every 20 ms or more), not sent all at once: no burst every second.
    diag_rovers = list(diag_outlets)
    diag_slots = max(1, min(len(diag_rovers), int(opts.diagnostics_period_s / DIAG_SLOT_S)))
    per_slot = -(-len(diag_rovers) // diag_slots)
    diag_next = [0]

    def periodic_diagnostics() -> None:
        for _ in range(per_slot):
            rt.urgent_first()
            publish_diagnostics(diag_rovers[diag_next[0] % len(diag_rovers)])
            diag_next[0] += 1

    # One subscription per family of keys (lunaris/*/rail/*/state ...), samples told apart by
    # their exact key above. A bridge that serves part of the fleet (a shard) subscribes for
    # its own rovers only: the other shards' samples never reach it. Plain subscribers, not
    # advanced ones replaying the publishers' caches: every one of these keys is published
    # each tick (the radio link each second), so a bridge that joins late has them within a
    # tick anyway, and an advanced subscriber costs ~10 us more per sample (at 100 rovers a
    # bridge shard receives ~10,000 a second).
    fams = {_family(o.binding.mapping.key) for feed in feeds.values() for o in feed.outlets}
    fams |= {_family(data_key("{rover}", c)) for cs in comps.values() for c in cs}
    fleet_size = len(fleet) if fleet is not None else len(rovers)
    served = ["*"] if len(rovers) == fleet_size else sorted(rover_cfg)
    for pattern in sorted({f.pattern(r) for f in fams for r in served}):
        rt.subscribe(pattern, on_twin, telemetry=True)
    if diag_outlets:
        # rare, and a subscription with a callback is a thread: one for the whole fleet (a
        # shard drops the other shards' rovers)
        rt.subscribe(keys.faults_active("*", "*"), on_faults, history=True, urgent=True)
        rt.every(opts.diagnostics_period_s / diag_slots, periodic_diagnostics)
    if any(o.period_s for feed in feeds.values() for o in feed.outlets):
        rt.every(RATE_TIMER_S, flush_due)
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

    # One subscription per inbound topic and flavour for all the rovers served: their keys
    # differ only in a rover's namespace or domain, which the subscription leaves open, and
    # a sample is told apart by its exact key (another shard's rover: not heard here). A
    # subscription with a Python callback has a thread of its own: one per rover and topic
    # was ~550 threads in a bridge shard of 50 rovers.
    heard: dict[tuple[str, int, str | None], dict[str, Binding]] = {}

    def hear(b: Binding, flavour: str, key: str) -> None:
        heard.setdefault((flavour, b.position, b.item), {})[key] = b

    for entity_id, b in enumerate(bindings, start=1):
        if b.mapping.direction != "in":
            continue
        if opts.outputs.ros2dds.enabled:
            hear(b, "ros2dds", zenoh_key(b, opts, "ros2dds"))
        if opts.outputs.json.enabled:
            hear(b, "json", zenoh_key(b, opts, "json"))
        if rmw.enabled:
            # Any type hash (the key's last chunk): a Humble node (TypeHashNotSupported) is
            # heard as well as a Jazzy one.
            hear(b, "rmw_zenoh", zenoh_key(b, opts, "rmw_zenoh").rsplit("/", 1)[0])
            rt.keep(rt.zenoh_session.liveliness().declare_token(entity_token(
                shared.rmw_domain(b), shared.zid, 0, entity_id, "MS", rmw.namespace, rmw.node,
                b.topic, b.mapping.type, qos_keyexpr(False, SUBSCRIPTION_DEPTH), opts.ros_distro)))
        if graph is not None:
            def on_ros2(raw: bytes, b: Binding = b) -> None:
                rt.call_soon(on_inbound, b, "ros2", b.topic, bytes(raw))
            graph.subscribe(shared.ros2_domain(b), b.topic, b.mapping.type, on_ros2)

    def listen(flavour: str, by_key: dict[str, Binding], keyexpr: str) -> None:
        any_hash = flavour == "rmw_zenoh"

        def on_sample(s: zenoh.Sample) -> None:
            key = str(s.key_expr)
            b = by_key.get(key.rsplit("/", 1)[0] if any_hash else key)
            if b is not None and s.kind == zenoh.SampleKind.PUT:
                rt.call_soon(on_inbound, b, flavour, key, s.payload.to_bytes())
        rt.keep(rt.zenoh_session.declare_subscriber(keyexpr + ("/*" if any_hash else ""), on_sample))

    for group, by_key in heard.items():
        shared_key = open_keyexpr(list(by_key))
        for keyexpr in [shared_key] if shared_key is not None else list(by_key):
            listen(group[0], by_key, keyexpr)

    for rover in diag_outlets:
        diag_dirty.add(rover)
