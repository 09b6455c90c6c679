"""The crew's controls: the mapping's services (``kind: service``, SPEC §12a) in every flavour.

A call from the dashboard becomes one write on the twin, by the crew (the ``actor=crew``
attachment: the events that answer it say ``actor: crew``), and is answered with the twin's
own answer (:mod:`common.answers`, the waiting every writer shares): ``accepted`` and the
owner's event in words, or the refusal and its reason, or, when the owner is known to be gone
or nothing answered within :data:`~common.answers.ANSWER_S`, "not applied: ...". A caller is
never left hanging (neither zenoh-bridge-ros2dds nor rmw_zenoh turns an error reply into a ROS
response: it would wait forever), and never answered with ``reply_err``.

The flavours (keys as :func:`~services.bridge.bindings.zenoh_key` makes them):

- ``ros2dds``: a queryable on the service's name, what ``zenoh-bridge-ros2dds`` queries for
  a DDS client (on Cyclone DDS: the bridge reads the request identity Cyclone puts in the
  payload), CDR with its header both ways and no request id; the bridge's ``SS`` liveliness
  token (``@/<zid>/@ros2_lv/SS/<key>/<type>``, ``/`` as ``§``) makes the service exist on the
  DDS side before any client does;
- ``rmw_zenoh``: a *complete* queryable on ``<domain>/<name>/<pkg>::srv::dds_::<Name>_/<the
  service type's hash>`` (rmw_zenoh clients query with target ``ALL_COMPLETE``), the reply's
  attachment echoing the request's sequence number and client GID with a new timestamp, and
  the service server's ``SS`` token so that ``wait_for_service`` sees it;
- ``json``: a queryable on ``<prefix>/<name>``: the request's fields as a JSON object, the
  response's as one;
- ``ros2``: an rclpy service (:meth:`~services.bridge.ros2_node.Ros2Graph.serve`).

One queryable per service mapping and flavour for every rover and component served (a
fleet's 100 rovers and their rails: still one), open in the chunks where their keys differ
(the namespace or domain, the rail), told apart by the exact key; a call of a key no service
here has (another shard's rover) is dropped unanswered, for the bridge that has it to answer.
The answers and the owners' liveliness are heard on one subscription each for the whole
fleet, whatever the rovers served: a bridge's threads do not grow with its rovers.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import zenoh

from common import keys
from common.answers import ANSWER_S, Accepted, Answer, Awaiting, NotApplied, Pending
from common.connection import write
from common.messages import MAX_INPUT_BYTES, BadInput, Event
from common.runtime import Runtime
from common.writes import Write, plan_write, unreachable_words
from services.bridge.bindings import Binding, open_keyexpr, zenoh_key
from services.bridge.mapping import service_response
from services.bridge.outlets import Shared
from services.bridge.rmw_zenoh import ATTACHMENT_LEN, GID_LEN, attachment, entity_token, qos_keyexpr
from services.bridge.srv import decode_request, encode_response, request_fields

__all__ = ["Controls", "ros2dds_token"]

SERVICE_DEPTH = 10  # rclpy's qos_profile_services_default: reliable, volatile, keep-last 10
EXPIRE_S = 0.1  # how often the calls past their time are answered "not applied"
CDR = zenoh.Encoding.APPLICATION_CDR
JSON = zenoh.Encoding.APPLICATION_JSON
Respond = Callable[[dict[str, Any]], None]  # sends a response's fields to the caller


def ros2dds_token(zid: str, key: str, typename: str) -> str:
    """The liveliness token zenoh-bridge-ros2dds reads as a service server announced on Zenoh:
    ``@/<zid>/@ros2_lv/SS/<key>/<type>``, each ``/`` in key and type written ``§``."""
    return f"@/{zid}/@ros2_lv/SS/{key.replace('/', '§')}/{typename.replace('/', '§')}"


class Controls:
    """The services of a bridge process: their ports, the calls in flight, the answers."""

    def __init__(self, rt: Runtime, shared: Shared, rovers: list[str], whole_fleet: bool):
        self.rt, self.shared, self.opts = rt, shared, shared.opts
        self.rovers, self.whole_fleet = rovers, whole_fleet
        self.declared = False
        self.awaiting = Awaiting()
        self.by_key: dict[tuple[str, int], dict[str, Binding]] = {}  # (flavour, mapping) -> keys
        self.live: dict[str, set[str]] = {}  # rover -> its live services (liveliness tokens)
        self.gone: dict[tuple[str, str], float] = {}  # (rover, service) -> wall time it went
        self._lock = threading.Lock()
        self._decoder = msgspec.json.Decoder(Event)

    # -- ports ----------------------------------------------------------------------------------

    def declare(self, entity_id: int, b: Binding) -> None:
        """A service of one rover in every enabled flavour (queryables after :meth:`start`)."""
        self.declared = True
        out, zid = self.opts.outputs, self.shared.zid
        liveliness = self.rt.zenoh_session.liveliness()
        if out.ros2dds.enabled:
            key = zenoh_key(b, self.opts, "ros2dds")
            self._group("ros2dds", b)[key] = b
            self.rt.keep(liveliness.declare_token(ros2dds_token(zid, key, b.mapping.type)))
        if out.json.enabled:
            self._group("json", b)[zenoh_key(b, self.opts, "json")] = b
        if out.rmw_zenoh.enabled:
            rmw = out.rmw_zenoh
            self._group("rmw_zenoh", b)[zenoh_key(b, self.opts, "rmw_zenoh")] = b
            self.rt.keep(liveliness.declare_token(entity_token(
                self.shared.rmw_domain(b), zid, 0, entity_id, "SS", rmw.namespace, rmw.node,
                b.topic, b.mapping.type, qos_keyexpr(False, SERVICE_DEPTH), self.opts.ros_distro)))
        graph = self.shared.graph
        if graph is not None:
            def ros2_call(fields: dict[str, Any], respond: Respond, b: Binding = b) -> None:
                self.call(b, fields, respond)
            graph.serve(self.shared.ros2_domain(b), b.topic, b.mapping.type, ros2_call)

    def _group(self, flavour: str, b: Binding) -> dict[str, Binding]:
        return self.by_key.setdefault((flavour, b.position), {})

    def start(self) -> None:
        """The queryables, the answers' subscription, the services' liveliness, the timer."""
        if not self.declared:
            return
        session = self.rt.zenoh_session
        for (flavour, _), by_key in self.by_key.items():
            shared_key = open_keyexpr(list(by_key))
            for keyexpr in [shared_key] if shared_key is not None else list(by_key):
                def on_query(q: zenoh.Query, f: str = flavour, bk: dict[str, Binding] = by_key) -> None:
                    self._on_query(f, bk, q)
                self.rt.keep(session.declare_queryable(keyexpr, on_query,
                                                       complete=flavour == "rmw_zenoh"))
        # live events only: an answer is news, not a cache replayed; another shard's rovers'
        # are heard too, and match no call waiting here
        self.rt.keep(session.declare_subscriber(keys.under("*", "event/*"), self._on_event))
        self.rt.keep(session.liveliness().declare_subscriber(
            keys.service("*", "*"), self._on_token, history=True))
        self.rt.every(EXPIRE_S, self.expire)

    # -- a call -----------------------------------------------------------------------------------

    def call(self, b: Binding, fields: dict[str, Any], respond: Respond) -> None:
        """A call of ``b`` with its request's ``fields``: the write sent, and ``respond`` called
        once, from whichever thread has the answer, with the response's fields."""
        m = b.mapping
        shape = service_response(m)

        def answer(accepted: bool, reason: str) -> None:
            values = {"accepted": accepted, "reason": reason}
            respond({f: values[what] for f, what in shape.items()})

        try:
            planned = self.plan(b, fields)
        except BadInput as exc:
            answer(False, f"refused: {exc}; nothing was sent")
            return
        why = self.unreachable(b.rover, planned.owner)
        if why is not None:
            answer(False, f"not applied: {why}; nothing changed")
            return

        def settled(got: Answer) -> None:
            answer(isinstance(got, Accepted), got.message)

        p = self.awaiting.add(Pending(planned, time.monotonic() + ANSWER_S, settled))
        try:
            write(self.rt.zenoh_session, planned.key, planned.payload, actor="crew")
        except zenoh.ZError as exc:
            self.awaiting.settle(p, NotApplied(planned, f"not applied: the write could not be "
                                               f"sent ({exc})", True, False))

    def plan(self, b: Binding, fields: dict[str, Any]) -> Write:
        """The write a call of ``b`` makes, checked as the twin will check it."""
        m = b.mapping
        _, parts = keys.split(b.key)
        if m.write == "delete":
            return plan_write(b.rover, parts, None)
        payload: dict[str, Any] = dict(m.payload)
        for payload_field, request_field in m.request.items():
            if request_field not in fields:
                raise BadInput(f"the request has no field {request_field!r}")
            payload[payload_field] = fields[request_field]
        return plan_write(b.rover, parts, msgspec.json.encode(payload))

    def unreachable(self, rover: str, owner: str) -> str | None:
        """Why the owner cannot be reached, when its liveliness says so; None otherwise
        (never heard of: the write goes, and the waiting says what came of it)."""
        with self._lock:
            live = self.live.get(rover)
            gone = self.gone.get((rover, owner))
        if live is None or owner in live:
            return None
        return unreachable_words(rover, owner, None if gone is None else
                                 time.strftime("%H:%M:%S", time.localtime(gone)))

    def expire(self) -> None:
        """Answer the calls whose answer did not come in time: not applied."""
        for p in self.awaiting.overdue(time.monotonic()):
            rover, owner = p.write.rover, p.write.owner
            why = self.unreachable(rover, owner)
            reason = (f"not applied: {why}; the twin refuses the write if it arrives later"
                      if why is not None else
                      f"not applied: no answer from {rover}'s {owner} service within "
                      f"{ANSWER_S:g} s; the twin refuses the write if it arrives later")
            self.awaiting.settle(p, NotApplied(p.write, reason, why is not None, True))

    # -- Zenoh ----------------------------------------------------------------------------------

    def _on_event(self, s: zenoh.Sample) -> None:
        if not len(self.awaiting):
            return
        try:
            rover, parts = keys.split(str(s.key_expr))
            ev = self._decoder.decode(s.payload.to_bytes())
        except (ValueError, msgspec.DecodeError, msgspec.ValidationError):
            return  # not an event of the twin's: no answer
        self.awaiting.hear(rover, parts, ev)

    def _on_token(self, s: zenoh.Sample) -> None:
        try:
            rover, parts = keys.split(str(s.key_expr))
        except ValueError:
            return
        if len(parts) != 2:
            return
        with self._lock:
            live = self.live.setdefault(rover, set())
            if s.kind == zenoh.SampleKind.PUT:
                live.add(parts[1])
                self.gone.pop((rover, parts[1]), None)
            else:
                live.discard(parts[1])
                self.gone[(rover, parts[1])] = time.time()

    def _on_query(self, flavour: str, by_key: dict[str, Binding], q: zenoh.Query) -> None:
        key = str(q.key_expr)
        b = by_key.get(key)
        if b is None:
            q.drop()
            return  # another rover's (a shard's), or a key no service of ours has
        srv = b.mapping.type
        raw = q.payload.to_bytes() if q.payload is not None else b""
        request_att = q.attachment.to_bytes() if q.attachment is not None else b""

        def respond(values: dict[str, Any]) -> None:
            try:
                if flavour == "json":
                    q.reply(key, msgspec.json.encode(values), encoding=JSON)
                else:
                    cdr = encode_response(srv, values, self.opts.ros_distro)
                    att = _reply_attachment(request_att) if flavour == "rmw_zenoh" else None
                    q.reply(key, cdr, encoding=CDR, attachment=att)
            except zenoh.ZError:
                pass  # the caller gave up (its query timed out): nobody to answer
            finally:
                q.drop()

        try:
            if len(raw) > MAX_INPUT_BYTES:
                raise BadInput(f"{len(raw)} bytes: more than a request ever holds ({MAX_INPUT_BYTES})")
            fields = _json_request(srv, raw) if flavour == "json" else decode_request(
                srv, raw, self.opts.ros_distro)
        except BadInput as exc:
            self.rt.call_soon(self.rt.reject, b.rover, key, str(exc), "crew")
            response = service_response(b.mapping)
            values = {"accepted": False, "reason": f"refused: {exc}; nothing was sent"}
            respond({f: values[what] for f, what in response.items()})
            return
        self.call(b, fields, respond)


def _json_request(srv: str, raw: bytes) -> dict[str, Any]:
    """A json flavour's request: a JSON object of the request's fields (none: empty)."""
    if not raw.strip():
        return {}
    try:
        value = msgspec.json.decode(raw)
    except msgspec.DecodeError as exc:
        raise BadInput(f"malformed JSON: {exc}") from None
    if not isinstance(value, dict):
        raise BadInput(f"expected a JSON object of the {srv} request's fields")
    for name, kind in request_fields(srv).items():
        if name in value and kind == "bool" and not isinstance(value[name], bool):
            raise BadInput(f"{name}: expected true or false, got {value[name]!r}")
    return value


def _reply_attachment(request: bytes) -> bytes:
    """rmw_zenoh's reply attachment: the request's sequence number and client GID (which the
    client matches its pending request by), a new source timestamp."""
    if len(request) >= ATTACHMENT_LEN:
        sequence = int.from_bytes(request[:8], "little", signed=True)
        gid = request[17:17 + GID_LEN]
    else:  # a client that sent none (not rmw_zenoh's): still an answer
        sequence, gid = 0, bytes(GID_LEN)
    return attachment(sequence, time.time_ns(), gid)
