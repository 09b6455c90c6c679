"""Bridge service: the twin's keys on the dashboard's ROS 2 topics, both ways (SPEC §7).

The mapping file (``config/bridge/default.yaml`` unless ``--bridge-config``) is validated at
start-up; with a problem the service prints every one and exits with status 2. Then a
:class:`Bridge` serves it, a node whose ports are declared in one place (:meth:`Bridge.start`):

- every outbound topic follows its twin key (:mod:`services.bridge.outlets`): each sample
  (folded per batch of samples), or with the mapping's ``rate_hz`` the newest at that rate,
  a change of a discrete field (a rail's state, the pack's faults) at once; in each enabled
  flavour: ``ros2dds`` (CDR on the topic name), ``rmw_zenoh`` (CDR on the rmw_zenoh key with
  its attachment; the node, publisher and subscription liveliness tokens are held for the
  life of the service), ``json`` and ``ros2``;
- the DiagnosticArray follows the faults in effect (each owning service's
  ``faults/active/<service>``, replayed from its cache when the bridge joins late) and each
  component's telemetry (STALE when it stops), published on every change of the active
  faults, of what the telemetry shows, and every ``diagnostics_period_s``; in the crew's view
  (``crew_view: symptoms``, the default) only the twin's own alarms and what its telemetry
  shows (:mod:`services.bridge.crew`), never an instructor's fault; a pack whose telemetry
  stopped is republished with the health UNKNOWN;
- an inbound topic (any flavour) becomes a twin input or command, written by the crew (its
  events say ``actor: crew``); a message that cannot be decoded or carries a bad value is
  refused with a rejection event, like any bad input;
- a service (``kind: service``, the crew's controls) is served in every flavour and answered
  with the twin's answer (:mod:`services.bridge.controls`).
"""

from __future__ import annotations

import heapq
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import msgspec
import msgspec.inspect
import zenoh

from common import keys
from common.config import ConfigError, Rover
from common.connection import write
from common.datafile import field_kind, struct_fields
from common.messages import MAX_INPUT_BYTES, ActiveFault, ActiveFaults, BadInput, decode
from common.runtime import Runtime, Sample
from services.bridge.bindings import Binding, expand, open_keyexpr, rover_names, zenoh_key
from services.bridge.cdr import decode_cdr, encode_cdr, restamp
from services.bridge.controls import Controls
from services.bridge.convert import (
    components,
    data_key,
    diagnostic_array_message,
    diagnostic_statuses,
    in_payload,
    topic_message,
)
from services.bridge.crew import READS, crew_statuses, seen
from services.bridge.mapping import MappingFile, load_mapping, resolve_mapping
from services.bridge.outlets import Feed, Outlet, Shared
from services.bridge.rmw_zenoh import entity_token, node_token, qos_keyexpr
from services.bridge.ros2_node import Ros2Graph, Ros2Unavailable
from services.bridge.watch import DELIVERY_S, DeliveryWatch

__all__ = ["Bridge", "serve"]

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


@dataclass
class RoverDiagnostics:
    """One rover's ``/diagnostics``: its outlets, its components and the telemetry that says
    each is alive, and the faults in effect by owning service (a view of the owners' records)."""

    rover: str
    components: list[str]
    data_keys: list[tuple[str, str]]  # (component, the telemetry key that shows it alive)
    outlets: list[Outlet] = field(default_factory=list)
    in_effect: dict[str, list[ActiveFault]] = field(default_factory=dict)
    telemetry: dict[str, Any] = field(default_factory=dict)  # component -> what the crew's view reads
    battery_stale: bool = False  # the pack's telemetry stopped: its BatteryState says UNKNOWN

    def active(self) -> list[ActiveFault]:
        return sorted((f for fs in self.in_effect.values() for f in fs),
                      key=lambda f: (f.since_t_s, f.key))


class Bridge:
    """The bridge of some rovers of a fleet: one node, its ports declared in :meth:`start`.

    Inputs: the twin's telemetry (:meth:`on_twin`, one subscription per key family), the
    faults in effect (:meth:`on_faults`), the dashboard's inbound topics in every enabled
    flavour (:meth:`on_inbound`) and its service calls (:attr:`controls`, which hears the
    twin's answers on the services' event keys). Outputs: the outbound topics (an
    :class:`Outlet` each), the DiagnosticArray of each rover, the crew's writes (the inputs
    and commands the inbound topics and the services carry) and rejection events. Timers:
    :meth:`flush` after each batch of samples, :meth:`flush_due` for the topics with a rate,
    :meth:`periodic_diagnostics`. Everything runs on the runtime's worker thread but the
    Zenoh and rclpy callbacks, which hand their samples to it, and a service call, which is
    sent and answered from the thread that has it (no wait behind a fleet's telemetry)."""

    def __init__(self, rt: Runtime, rovers: list[Rover], mf: MappingFile, bindings: list[Binding],
                 fleet_size: int, graph: Ros2Graph | None,
                 clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time):
        self.rt, self.opts, self.bindings, self.graph = rt, mf.bridge, bindings, graph
        self.rovers = {r.id: r for r in rovers}
        self.whole_fleet = len(rovers) == fleet_size  # else a shard: its own rovers only
        self.shared = Shared(rt, self.opts, str(rt.zenoh_session.info.zid()), graph, clock, wall)
        self.controls = Controls(rt, self.shared, sorted(self.rovers), self.whole_fleet)
        self.feeds: dict[str, Feed] = {}  # twin key -> its feed
        self.diagnostics: dict[str, RoverDiagnostics] = {}  # rover -> its /diagnostics
        self.dirty: set[str] = set()  # twin keys whose newest sample some outlet sends now
        self.diag_dirty: set[str] = set()  # rovers whose /diagnostics goes out after the batch
        self.started = time.monotonic()
        self.last_seen: dict[str, float] = {}  # component data key -> monotonic time
        self.alive_of: dict[str, str] = {}  # component data key -> its rover
        # the data keys whose payload the crew's view reads -> (rover, component, payload type)
        self.watched: dict[str, tuple[str, str, type[msgspec.Struct]]] = {}
        self._diag_next = 0  # the next rover of the periodic diagnostics
        self._per_slot = 1
        # inbound: (flavour, mapping, component) -> {key: binding}, one subscription each
        self.heard: dict[tuple[str, int, str | None], dict[str, Binding]] = {}

    # -- ports --------------------------------------------------------------------------------

    def start(self) -> None:
        """Declare every port: the outlets, the subscriptions, the timers, the tokens."""
        rt, rmw = self.rt, self.opts.outputs.rmw_zenoh
        if rmw.enabled:
            for domain in sorted({self.shared.rmw_domain(b) for b in self.bindings}):
                rt.keep(rt.zenoh_session.liveliness().declare_token(
                    node_token(domain, self.shared.zid, 0, rmw.namespace, rmw.node)))
        # rmw_zenoh entity ids: the node is 0, each binding its position in the list from 1
        for entity_id, b in enumerate(self.bindings, start=1):
            if b.mapping.kind == "service":
                self.controls.declare(entity_id, b)
            elif b.mapping.direction == "in":
                self._declare_inbound(entity_id, b)
            else:
                self._declare_outlet(entity_id, b)
        self.controls.start()
        for (flavour, _, _), by_key in self.heard.items():
            shared_key = open_keyexpr(list(by_key))
            for keyexpr in [shared_key] if shared_key is not None else list(by_key):
                self._listen(flavour, by_key, keyexpr)

        # One subscription per family of keys (lunaris/*/rail/*/state ...), samples told apart
        # by their exact key. A bridge that serves part of the fleet (a shard) subscribes for
        # its own rovers only: the other shards' samples never reach it. Plain subscribers,
        # not advanced ones replaying the publishers' caches: every one of these keys is
        # published each tick (the radio link each second), so a bridge that joins late has
        # them within a tick anyway, and an advanced subscriber costs ~10 us more per sample
        # (at 100 rovers a bridge shard receives ~10,000 a second).
        fams = {_family(o.binding.mapping.key) for feed in self.feeds.values() for o in feed.outlets}
        fams |= {_family(data_key("{rover}", c)) for d in self.diagnostics.values()
                 for c in d.components}
        served = ["*"] if self.whole_fleet else sorted(self.rovers)
        for pattern in sorted({f.pattern(r) for f in fams for r in served}):
            rt.subscribe(pattern, self.on_twin, telemetry=True)
        if self.diagnostics:
            # rare, and a subscription with a callback is a thread: one for the whole fleet (a
            # shard drops the other shards' rovers)
            rt.subscribe(keys.faults_active("*", "*"), self.on_faults, history=True, urgent=True)
            # The periodic DiagnosticArrays are spread over the period (a fleet's rovers one
            # after the other, a timer every 20 ms or more), not sent all at once: no burst
            # every second.
            slots = max(1, min(len(self.diagnostics),
                               int(self.opts.diagnostics_period_s / DIAG_SLOT_S)))
            self._per_slot = -(-len(self.diagnostics) // slots)
            rt.every(self.opts.diagnostics_period_s / slots, self.periodic_diagnostics)
        if any(o.period_s for feed in self.feeds.values() for o in feed.outlets):
            rt.every(RATE_TIMER_S, self.flush_due)
        if self.shared.outlets_of:  # what reaches the crew's dashboard (SPEC §13d)
            rt.every(DELIVERY_S, DeliveryWatch(rt, self.shared).report)
        rt.after_batch(self.flush)
        self.diag_dirty |= set(self.diagnostics)

    def _declare_outlet(self, entity_id: int, b: Binding) -> None:
        if b.mapping.convert == "diagnostics":
            d = self.diagnostics.get(b.rover)
            if d is None:
                comps = components(self.rovers[b.rover])
                d = self.diagnostics[b.rover] = RoverDiagnostics(
                    b.rover, comps, [(c, data_key(b.rover, c)) for c in comps])
                for comp, key in d.data_keys:
                    self.alive_of[key] = b.rover
                    typ = _family(data_key("{rover}", comp)).payload
                    if self.opts.crew_view == "symptoms" and typ in READS:
                        self.watched[key] = (b.rover, comp, typ)
            d.outlets.append(Outlet(self.shared, b, entity_id, None))
            return
        feed = self.feeds.get(b.key)
        if feed is None:
            typ = _family(b.mapping.key).payload
            feed = self.feeds[b.key] = Feed(typ, _discrete_fields(typ))
        outlet = Outlet(self.shared, b, entity_id, feed)
        feed.outlets.append(outlet)
        feed.unrated |= outlet.period_s == 0.0
        feed.idle |= outlet.idle

    def _declare_inbound(self, entity_id: int, b: Binding) -> None:
        """Hear an inbound topic in every enabled flavour. One subscription per inbound topic
        and flavour for all the rovers served: their keys differ only in a rover's namespace
        or domain, which the subscription leaves open, and a sample is told apart by its
        exact key (another shard's rover: not heard here). A subscription with a Python
        callback has a thread of its own: one per rover and topic was ~550 threads in a
        bridge shard of 50 rovers."""
        opts, rmw = self.opts, self.opts.outputs.rmw_zenoh
        if opts.outputs.ros2dds.enabled:
            self._hear(b, "ros2dds", zenoh_key(b, opts, "ros2dds"))
        if opts.outputs.json.enabled:
            self._hear(b, "json", zenoh_key(b, opts, "json"))
        if rmw.enabled:
            # Any type hash (the key's last chunk): a Humble node (TypeHashNotSupported) is
            # heard as well as a Jazzy one.
            self._hear(b, "rmw_zenoh", zenoh_key(b, opts, "rmw_zenoh").rsplit("/", 1)[0])
            self.rt.keep(self.rt.zenoh_session.liveliness().declare_token(entity_token(
                self.shared.rmw_domain(b), self.shared.zid, 0, entity_id, "MS", rmw.namespace,
                rmw.node, b.topic, b.mapping.type, qos_keyexpr(False, SUBSCRIPTION_DEPTH),
                opts.ros_distro)))
        if self.graph is not None:
            def on_ros2(raw: bytes, b: Binding = b) -> None:
                self.rt.call_soon(self.on_inbound, b, "ros2", b.topic, bytes(raw))
            self.graph.subscribe(self.shared.ros2_domain(b), b.topic, b.mapping.type, on_ros2)

    def _hear(self, b: Binding, flavour: str, key: str) -> None:
        self.heard.setdefault((flavour, b.position, b.item), {})[key] = b

    def _listen(self, flavour: str, by_key: dict[str, Binding], keyexpr: str) -> None:
        any_hash = flavour == "rmw_zenoh"

        def on_sample(s: zenoh.Sample) -> None:
            key = str(s.key_expr)
            b = by_key.get(key.rsplit("/", 1)[0] if any_hash else key)
            if b is not None and s.kind == zenoh.SampleKind.PUT:
                self.rt.call_soon(self.on_inbound, b, flavour, key, s.payload.to_bytes())
        self.rt.keep(self.rt.zenoh_session.declare_subscriber(
            keyexpr + ("/*" if any_hash else ""), on_sample))

    # -- outbound -----------------------------------------------------------------------------

    def stamp_ns(self, t_s: float) -> int:
        return time.time_ns() if self.opts.stamp == "wall" else int(round(t_s * 1e9))

    def message(self, outlet: Outlet, payload: Any) -> dict | None:
        """The message an outlet publishes for a twin payload."""
        b = outlet.binding
        d = self.diagnostics.get(b.rover)
        return topic_message(b.mapping, payload, self.rovers[b.rover].battery,
                             self.stamp_ns(payload.t_s), self.opts.ros_distro,
                             stale=d is not None and d.battery_stale)

    def on_twin(self, s: Sample) -> None:
        rover = self.alive_of.get(s.key)
        if rover is not None:
            now = time.monotonic()
            if now - self.last_seen.get(s.key, self.started) > self.opts.stale_after_s:
                self.diag_dirty.add(rover)  # back from STALE
            self.last_seen[s.key] = now
            if s.key == keys.battery_state(rover):
                self.diagnostics[rover].battery_stale = False
        if s.deleted:
            return
        feed = self.feeds.get(s.key)
        payload = None
        if feed is not None:
            feed.payload = payload = decode(s.payload, feed.type)
            feed.seq += 1
            if feed.unrated or feed.idle or feed.discrete_of(payload) != feed.discrete:
                self.dirty.add(s.key)
        watched = self.watched.get(s.key)
        if watched is not None:  # what the crew's view reads: a change is news at once
            rover, comp, typ = watched
            payload = payload if payload is not None else decode(s.payload, typ)
            d = self.diagnostics[rover]
            if seen(comp, d.telemetry.get(comp)) != seen(comp, payload):
                self.diag_dirty.add(rover)
            d.telemetry[comp] = payload

    def flush(self) -> None:
        """The samples some outlet sends at once: every one for an outlet without a rate, the
        first after an outlet's idle spell, and a change of a discrete field for all."""
        now = self.shared.clock()
        for key in sorted(self.dirty):
            self.rt.urgent_first()  # a fleet's tick is thousands of samples
            feed = self.feeds[key]
            discrete = feed.discrete_of(feed.payload)
            changed, feed.discrete, feed.idle = discrete != feed.discrete, discrete, False
            for outlet in feed.outlets:
                if outlet.idle:
                    outlet.idle = False
                    outlet.send(self.message)
                    outlet.schedule(now)
                elif changed or outlet.period_s == 0.0:
                    outlet.send(self.message)
        self.dirty.clear()
        for rover in sorted(self.diag_dirty):
            self.publish_diagnostics(rover)
        self.diag_dirty.clear()

    def flush_due(self) -> None:
        """The outlets whose rate allows the newest sample: sent, or idle when none came."""
        now = self.shared.clock()
        due = self.shared.due
        while due and due[0][0] <= now:
            self.rt.urgent_first()
            _, _, outlet = heapq.heappop(due)
            feed = outlet.feed
            assert feed is not None, "an outlet with a rate has a feed"
            if outlet.sent_seq == feed.seq:
                outlet.idle = feed.idle = True
            else:
                outlet.send(self.message)
                outlet.schedule(now)

    # -- diagnostics: the faults in effect and each component's last telemetry ------------------

    def ages(self, d: RoverDiagnostics) -> dict[str, float | None]:
        now = time.monotonic()
        return {c: now - self.last_seen.get(key, self.started) for c, key in d.data_keys}

    def publish_diagnostics(self, rover: str) -> None:
        """The rover's DiagnosticArray, in the mapping's view (the crew's symptoms, or every
        fault in effect); statuses unchanged since the last one (the periodic republishing of
        a quiet rover) are not encoded again, only stamped anew."""
        d = self.diagnostics[rover]
        ages = self.ages(d)
        if self.opts.crew_view == "full":
            statuses = diagnostic_statuses(rover, d.components, d.active(), ages,
                                           self.opts.stale_after_s)
        else:
            statuses = crew_statuses(rover, d.components, d.active(), d.telemetry, ages,
                                     self.opts.stale_after_s)
        self._battery_silence(d, ages.get("battery"))
        t_ns = self.stamp_ns(self.rt.t_s.get(rover, 0.0))
        for outlet in d.outlets:
            msg = diagnostic_array_message(statuses, t_ns, outlet.binding.mapping.frame_id)
            cdr = None
            if outlet.encodes:
                if outlet.last is not None and outlet.last[0] == statuses:
                    cdr = restamp(outlet.last[1], t_ns)
                else:
                    cdr = encode_cdr(outlet.type, msg, self.opts.ros_distro)
                    outlet.last = (statuses, cdr)
            outlet.publish(msg, cdr)

    def _battery_silence(self, d: RoverDiagnostics, age_s: float | None) -> None:
        """A pack whose telemetry stopped: its last BatteryState once more, health UNKNOWN
        (the next sample, when it comes, is published as it is)."""
        if d.battery_stale or age_s is None or age_s <= self.opts.stale_after_s:
            return
        d.battery_stale = True
        feed = self.feeds.get(keys.battery_state(d.rover))
        if feed is not None and feed.payload is not None:
            for outlet in feed.outlets:
                if outlet.binding.mapping.convert == "battery_state":
                    outlet.send(self.message)

    def on_faults(self, s: Sample) -> None:
        d = self.diagnostics.get(s.rover)
        if d is None or s.deleted:
            return
        answer = decode(s.payload, ActiveFaults)
        if d.in_effect.get(answer.service) != answer.faults:
            d.in_effect[answer.service] = answer.faults
            # at once, not after the batch: the telemetry a fault sets off (a rail tripping,
            # the PDM re-solving) arrives in the same moment and must not go first
            self.diag_dirty.discard(s.rover)
            self.publish_diagnostics(s.rover)

    def periodic_diagnostics(self) -> None:
        rovers = list(self.diagnostics)
        for _ in range(self._per_slot):
            self.rt.urgent_first()
            self.publish_diagnostics(rovers[self._diag_next % len(rovers)])
            self._diag_next += 1

    # -- inbound ------------------------------------------------------------------------------

    def on_inbound(self, b: Binding, flavour: str, key: str, payload: bytes) -> None:
        """A dashboard's message on an inbound topic: the twin input or command it carries,
        or a rejection event naming the key and what is wrong."""
        try:
            if len(payload) > MAX_INPUT_BYTES:
                raise BadInput(f"{len(payload)} bytes: more than an input ever holds "
                               f"({MAX_INPUT_BYTES})")
            if flavour == "json":
                try:
                    msg = msgspec.json.decode(payload)
                except msgspec.DecodeError as exc:
                    raise BadInput(f"malformed JSON: {exc}") from None
                if not isinstance(msg, dict):
                    raise BadInput(f"expected a JSON object of {b.mapping.type} fields")
            else:
                msg = decode_cdr(b.mapping.type, payload, self.opts.ros_distro)
            value = in_payload(b.mapping, msg)
        except BadInput as exc:
            self.rt.reject(b.rover, key, str(exc), "crew")  # the crew's refused action
            return
        # the crew's dashboard wrote it: its owner's events say so (actor crew)
        write(self.rt.zenoh_session, b.key, msgspec.json.encode(value), actor="crew")


def serve(rt: Runtime, rovers: list[Rover], seed: int | None = None,
          mapping_file: str | None = None, fleet: list[str] | None = None,
          clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time) -> None:
    """Serve ``rovers``, members of ``fleet`` (the ids of every rover of the deployment, in
    order, whichever bridge serves each; default: these rovers). ``clock`` times the rates,
    ``wall`` stamps the delivery records."""
    path = resolve_mapping(mapping_file)
    try:
        mf = load_mapping(path)
        bindings = expand(mf, [rover_names(r) for r in rovers], source=str(path), fleet=fleet)
    except ConfigError as exc:
        print(exc, file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    graph: Ros2Graph | None = None
    if mf.bridge.outputs.ros2.enabled:
        try:
            graph = Ros2Graph(mf.bridge.outputs.ros2.node, mf.bridge.outputs.ros2.namespace)
            for b in bindings:  # every message type there, before anything is declared
                graph.message_class(b.mapping.type)
        except Ros2Unavailable as exc:
            print(f"{path}: bridge.outputs.ros2: {exc}", file=sys.stderr, flush=True)
            raise SystemExit(2) from None
        rt.on_exit(graph.close)
    Bridge(rt, rovers, mf, bindings, len(fleet) if fleet is not None else len(rovers), graph,
           clock, wall).start()
