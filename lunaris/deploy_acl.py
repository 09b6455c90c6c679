"""The routers' configurations of a Lunaris deployment and their access control
(``lunaris deploy acl``).

The access control is derived from the code's own table of key families
(:data:`common.keys.FAMILIES`: which service publishes which key) and from the bridge
mapping (which topics the dashboard reads and writes). Each service kind has its own
identity and may publish, answer and announce only its own keys, so no client can forge
another's telemetry, ticks, events, tokens or queryables; the crew's identities read effects,
never the instructor's faults. The generated file's header says how Zenoh 1.10 matches
each rule (and, for a site of several routers, each link).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from common import keys
from common.connection import TX_QUEUE_SIZE
from lunaris.deploy_dashboard import (
    bridge_answers,
    bridge_hears,
    crew_writes,
    dashboard_calls,
    dashboard_keys,
    fleet_names,
)
from lunaris.deploy_site import DEFAULT_SITE, IDENTITIES, PEOPLE, SERVICES, Site, router_identity
from services.bridge import MappingFile, RoverNames

__all__ = ["REPO", "ROUTER_FILE", "ROUTER_SECRETS", "acl", "render_router_config", "router_config"]

LINK_LEASE_MS = 3000  # a site's routers: a cut link closed within 3 s
RETRY_MS = 1000  # ... and opened again within 1 s of the cable's return
ACCEPT_TIMEOUT_MS = 3000  # a client that has not finished TLS and its password by then is closed
ACCEPT_PENDING = 1000  # connections in that state at once (Zenoh: 100)
ROUTER_SECRETS = "/etc/zenoh/secrets"  # where the router container finds the secrets
REPO = Path(__file__).resolve().parent.parent
ROUTER_FILE = REPO / "deploy" / "zenohd.json5"

_TWIN = ["lunaris/**", "lunaris/**/@adv/**"]
# Every key expression a subscriber may be declared on: `**` includes every one without a
# verbatim chunk; those with one ('@adv', ROS 2 discovery, rmw_zenoh's caches) are listed.
_EVERY_KEY = ["**", "**/@adv/**", "@ros2_lv/**", "@/*/@ros2_pub_cache/**", "@/*/@ros2_lv/**"]
# ROS 2 discovery: rmw_zenoh's tokens, zenoh-bridge-ros2dds' caches and its tokens (a service
# server announced on Zenoh: the bridge's SS tokens of the crew's controls)
_ROS = ["@ros2_lv/**", "@/*/@ros2_pub_cache/**", "@/*/@ros2_lv/**"]
_ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
_READ_IN = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
_READ_OUT = ["put", "delete", "reply", "liveliness_token", "declare_queryable"]
_WRITABLE = ["lunaris/*/fault/**", "lunaris/*/cmd/**", "lunaris/*/input/**",
             "lunaris/*/clock/control", "lunaris/*/control/**",
             keys.ARMED_FAULT.pattern()]  # an instructor arms a fault (SPEC 13b)
# A scenario's progress: put by the scenario runner of the instructor's tools and of the
# console (keys.FAMILIES: scenario/progress), with an advanced publisher: its cache answers a
# late joiner (a queryable on its '@adv' key, replies on the key itself) and its token says it
# is there.
_PROGRESS = [keys.under("*", "scenario/progress"), keys.under("*", "scenario/progress/@adv/**")]
# What the crew must discover from effects, not read: the instructor's puts, the journal,
# the faults in effect, the events that name them (the journal's stream and each
# service's own), the session's snapshots, the trainee sessions (the journal's segments,
# with the trainees' names), and a scenario's progress (what the drill does next).
_CREW_HIDDEN = ["lunaris/*/fault/**", "lunaris/*/event", "lunaris/*/event/**",
                "lunaris/*/event/@adv/**", "lunaris/*/event/*/@adv/**",
                "lunaris/*/faults", "lunaris/*/faults/**", "lunaris/*/control/**",
                "lunaris/*/snapshots", "lunaris/*/snapshots/**", "lunaris/*/sessions",
                *_PROGRESS]


def _pattern(chunks: tuple[str, ...]) -> str:
    return "/".join(["lunaris", "*", *("*" if c.startswith("{") else c for c in chunks)])


def _published(service: str) -> list[str]:
    """The keys one service kind publishes: its families, its faults in effect and its
    events on its own key ``event/<service>`` (events are authenticated by their key: no
    identity but the service's may put there). The faults service, the journal, also
    relays every event it journals on the rover's ``event``: no one else may."""
    own = [_pattern(f.chunks) for f in keys.FAMILIES if f.owner == service and f.direction == "out"]
    own += [f"lunaris/*/event/{service}", f"lunaris/*/faults/active/{service}"]
    return own + (["lunaris/*/event"] if service == "faults" else [])


def _answered(service: str) -> list[str]:
    """The queries one service kind answers."""
    out = [f"lunaris/*/faults/active/{service}", f"lunaris/*/snapshots/{service}"]
    if service == "faults":
        out += ["lunaris/*/faults", "lunaris/*/faults/journal", "lunaris/*/snapshots",
                "lunaris/*/sessions", "lunaris/*/faults/armed"]
    if service == "battery":
        out += ["lunaris/*/prediction"]
    return out


def _rule(rule_id: str, permission: str, flows: list[str], messages: list[str],
          key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": permission, "flows": flows, "messages": messages,
            "key_exprs": list(dict.fromkeys(key_exprs))}


def acl(mf: MappingFile, fleet: list[RoverNames], clients: tuple[str, ...] = IDENTITIES,
        routers_in: tuple[str, ...] = (), routers_out: tuple[str, ...] = ()) -> dict[str, Any]:
    """The router's ``access_control`` section: subjects and policies for ``clients`` (the
    identities that connect to this router), and for the routers linked with it: those
    that open a link to it (``routers_in``: their user name and their certificate, mutual
    TLS) and those it opens a link to (``routers_out``: their certificate, the server's
    side of TLS; a link's opener has no user name to show).

    Three verbs per identity: what it may *ask for* (ingress subscriber, query, liveliness
    subscriber and query: wildcards included), what may *reach* it (egress put, delete,
    reply, token, queryable: decided sample by sample), and what it may *send* (ingress
    put, delete, reply, token, queryable). Every identity that sends is told of every
    subscriber (``learn-subscribers``): Zenoh's clients send a declared publisher's samples
    only to a router that told them of a subscriber, and the router tells them of it by the
    subscriber's own key expression, which an allow rule must include (the header of the
    generated file says how Zenoh matches)."""
    reads, writes = dashboard_keys(mf, fleet)
    hears = bridge_hears(mf, fleet)
    # the crew's controls: the dashboard calls them, the bridge answers (its queryables open
    # across the rovers it serves, as it hears the inbound topics)
    calls, answers = dashboard_calls(mf, fleet), bridge_answers(mf, fleet)
    # what the bridge writes for the crew: inputs and commands (puts), the rover's stop (a delete)
    crew_puts, crew_deletes = crew_writes(mf, "put"), crew_writes(mf, "delete")
    dash_adv = [f"{k}/@adv/**" for k in reads]
    rules = [
        _rule("read-twin", "allow", ["ingress"], _READ_IN, _TWIN),
        _rule("deliver-twin", "allow", ["egress"], _READ_OUT, _TWIN),
        # a writer learns of every subscriber, whatever its key expression (wildcards): what
        # reaches the subscriber is still decided by the subscriber's own egress rules
        _rule("learn-subscribers", "allow", ["egress"], ["declare_subscriber"], _EVERY_KEY),
        _rule("crew-hidden-deliver", "deny", ["egress"], ["put", "delete", "reply"], _CREW_HIDDEN),
        _rule("crew-hidden-ask", "deny", ["ingress"], ["query", "declare_subscriber"], _CREW_HIDDEN),
        _rule("instructor-write", "allow", ["ingress"], ["put", "delete"], _WRITABLE),
        _rule("scenario-progress-publish", "allow", ["ingress"],
              ["put", "delete", "declare_queryable", "reply", "liveliness_token"], _PROGRESS),
        # a late joiner's question reaches the publisher's cache
        _rule("scenario-progress-asked", "allow", ["egress"], ["query"], _PROGRESS),
        # the dashboard may subscribe on any key expression (its topics of one rover, of
        # several, under a wildcard): only the bridge's topics reach it (dashboard-deliver)
        _rule("dashboard-listen", "allow", ["ingress"],
              ["declare_subscriber", "declare_liveliness_subscriber"], _EVERY_KEY),
        _rule("dashboard-read", "allow", ["ingress"], ["query", "liveliness_query"],
              reads + dash_adv + _ROS),
        _rule("dashboard-deliver", "allow", ["egress"], _READ_OUT, reads + dash_adv + _ROS),
        _rule("dashboard-write", "allow", ["ingress"], ["put", "liveliness_token"],
              writes + _ROS[:1]),
        # the crew's controls (SPEC §12a): the dashboard calls exactly these services, and
        # learns of the bridge's queryables (a ROS 2 client waits for its server)
        _rule("dashboard-call", "allow", ["ingress"], ["query"], calls),
        _rule("dashboard-answered", "allow", ["egress"], ["reply"], calls),
        _rule("dashboard-servers", "allow", ["egress"], ["declare_queryable"], calls + answers),
    ]
    subjects = [{"id": person, "usernames": [person]} for person in PEOPLE]
    policies = [
        {"id": "instructor", "subjects": ["instructor", "console"],
         "rules": ["read-twin", "deliver-twin", "learn-subscribers", "instructor-write",
                   "scenario-progress-publish", "scenario-progress-asked"]},
        {"id": "debrief", "subjects": ["debrief"], "rules": ["read-twin", "deliver-twin"]},
        {"id": "observer", "subjects": ["observer"],
         "rules": ["read-twin", "deliver-twin", "crew-hidden-deliver", "crew-hidden-ask"]},
        {"id": "dashboard", "subjects": ["dashboard"],
         "rules": ["dashboard-listen", "dashboard-read", "dashboard-deliver", "dashboard-write",
                   "dashboard-call", "dashboard-answered", "dashboard-servers",
                   "learn-subscribers"]},
    ]
    if routers_in or routers_out:
        # Another router is trusted as a router only: it carries what its own clients may
        # send and receive, which it has checked (each router enforces its own clients'
        # rules), in both directions, on every key.
        rules.append(_rule("route", "allow", ["ingress", "egress"], _ALL_MESSAGES, _EVERY_KEY))
        for name in routers_in:
            subjects.append({"id": router_identity(name), "usernames": [router_identity(name)],
                             "cert_common_names": [router_identity(name)]})
        for name in routers_out:
            subjects.append({"id": router_identity(name),
                             "cert_common_names": [router_identity(name)]})
        policies.append({"id": "routers", "rules": ["route"], "subjects": [
            router_identity(n) for n in (*routers_in, *routers_out)]})
    for service in SERVICES:
        pub = _published(service)
        answered = _answered(service)
        adv = [f"{k}/@adv/**" for k in pub]
        extra_pub: list[str] = []
        crew_rules: list[dict[str, Any]] = []
        if service == "bridge":  # the dashboard's topics; the crew's writes are rules of their own
            extra_pub = reads + dash_adv + ["@ros2_lv/**"]
            crew_rules = [_rule(f"svc-bridge-crew-{op}", "allow", ["ingress"], [op], writes_)
                          for op, writes_ in (("put", crew_puts), ("delete", crew_deletes)) if writes_]
            rules += crew_rules
        if service == "faults":  # an armed fault fired: a put on fault/..., as an instructor's
            extra_pub = ["lunaris/*/fault/**"]
        r = f"svc-{service}"
        rules += [
            _rule(f"{r}-publish", "allow", ["ingress"], ["put", "delete"], pub + extra_pub),
            # A cache answers a late joiner with the samples themselves: replies on pub too.
            _rule(f"{r}-answer", "allow", ["ingress"], ["declare_queryable", "reply"],
                  answered + pub + adv
                  + (reads + dash_adv + calls + answers if service == "bridge" else [])),
            # The faults service gathers with one query for every owner (a wildcard): each
            # owner may be asked it, and may reply only on its own key.
            _rule(f"{r}-asked", "allow", ["egress"], ["query"],
                  answered + pub + adv + ["lunaris/*/faults/active/*", "lunaris/*/snapshots/*"]
                  + (reads + dash_adv + calls if service == "bridge" else [])),
            _rule(f"{r}-announce", "allow", ["ingress"], ["liveliness_token"],
                  # its token, and its claims while it starts (Runtime.claim: claim/<zid>, owner/<zid>)
                  [f"lunaris/*/service/{service}", f"lunaris/*/service/{service}/*/*"] + adv
                  + (dash_adv + ["@ros2_lv/**", "@/*/@ros2_lv/**"] if service == "bridge" else [])),
        ]
        if service == "bridge":  # it hears the dashboard's inbound topics and ROS 2 discovery
            # (a bridge serving several rovers hears a topic of them all on one key expression)
            rules += [_rule("svc-bridge-hear", "allow", ["ingress"], _READ_IN, hears + _ROS),
                      _rule("svc-bridge-heard", "allow", ["egress"], _READ_OUT, writes + _ROS)]
        subjects.append({"id": f"lunaris-{service}", "usernames": [f"lunaris-{service}"]})
        policies.append({
            "id": f"service-{service}", "subjects": [f"lunaris-{service}"],
            "rules": ["read-twin", "deliver-twin", "learn-subscribers", f"{r}-publish",
                      f"{r}-answer", f"{r}-asked", f"{r}-announce"]
            + (["svc-bridge-hear", "svc-bridge-heard", *(c["id"] for c in crew_rules)]
               if service == "bridge" else []),
        })
    known = set(clients) | {router_identity(n) for n in (*routers_in, *routers_out)}
    subjects = [sub for sub in subjects if sub["id"] in known]
    policies = [{**pol, "subjects": [i for i in pol["subjects"] if i in known]}
                for pol in policies]
    policies = [pol for pol in policies if pol["subjects"]]
    used = {r for pol in policies for r in pol["rules"]}
    return {"enabled": True, "default_permission": "deny",
            "rules": [r for r in rules if r["id"] in used], "subjects": subjects,
            "policies": policies}


def router_config(mf: MappingFile, fleet: list[RoverNames], secrets_dir: str = ROUTER_SECRETS,
                  site: Site = DEFAULT_SITE, name: str | None = None,
                  link_password: str | None = None) -> dict[str, Any]:
    """The configuration of one router of a site (default: the one router of
    docker-compose.yml). ``secrets_dir`` is where it finds its secrets: the container's
    ``/etc/zenoh/secrets``, or a folder of the machine it runs on.

    Its clients reach it on the client port (TLS, user and password). A router linked with
    others also listens on the router port with mutual TLS (each router shows its own
    certificate, signed by the deployment's CA), opens its own links with its certificate,
    user and password (``link_password``: its configuration is then a secret), and trusts
    its neighbours only as routers (:func:`acl`)."""
    spec = site.routers[0] if name is None else site.router(name)
    linked_from = site.linked_from(spec.name)
    d = secrets_dir
    listen = [f"tls/0.0.0.0:{spec.client_port}"]
    if linked_from:
        listen.append(f"tls/0.0.0.0:{spec.router_port}#enable_mtls=true")
    # A cut link is tried again every second at most, and caught up within one of the cable
    # coming back (Zenoh's default backs off to 4 s).
    connect = [f"tls/{site.router(t).hosts[0]}:{site.router(t).router_port}#enable_mtls=true;"
               f"retry_period_init_ms={RETRY_MS // 2};retry_period_max_ms={RETRY_MS}"
               for t in spec.connect]
    tls = {"listen_certificate": f"{d}/tls/router.crt", "listen_private_key": f"{d}/tls/router.key"}
    auth: dict[str, Any] = {"dictionary_file": f"{d}/credentials.txt"}
    if linked_from or spec.connect:
        tls["root_ca_certificate"] = f"{d}/tls/ca.crt"
    if spec.connect:
        if link_password is None:
            raise ValueError(f"the router {spec.name} opens links: its password is needed")
        tls |= {"connect_certificate": f"{d}/tls/router.crt",
                "connect_private_key": f"{d}/tls/router.key"}
        auth |= {"user": spec.identity, "password": link_password}
    link: dict[str, Any] = {"tls": tls,
                            # what each Lunaris session queues: a fleet's tick, not dropped
                            "tx": {"queue": {"size": TX_QUEUE_SIZE}}}
    if linked_from or spec.connect:
        # A link between machines can be cut: the routers close it within LINK_LEASE_MS (and
        # the liveliness tokens of the machine behind it go), instead of Zenoh's 10 s, in
        # which TCP's backoff holds everything sent meanwhile and may deliver it late.
        link["tx"]["lease"] = LINK_LEASE_MS
    return {
        "mode": "router",
        # Inside the container; docker-compose.yml decides which host address publishes it.
        "listen": {"endpoints": listen},
        "connect": {"endpoints": connect},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        # Samples stamped, as rmw_zenoh's router and sessions do (and the writes' age is
        # judged by). Zenoh 1.10 forwards between a router's clients (the dashboard's
        # rmw_zenoh session is one) but never from one of its peers to another: deploy/README
        # §5b says what that means for ROS 2 nodes.
        "timestamping": {"enabled": {"router": True, "peer": True, "client": True}},
        "transport": {
            # A connection that has not shown who it is within ACCEPT_TIMEOUT_MS is closed, and
            # ACCEPT_PENDING of them may wait at once: with Zenoh's 10 s and 100, a hundred TLS
            # handshakes with nothing after them held every new session back 12 s (a client
            # with no password, on a router reachable from the network).
            "unicast": {"accept_timeout": ACCEPT_TIMEOUT_MS, "accept_pending": ACCEPT_PENDING},
            "auth": {"usrpwd": auth},
            "link": link,
        },
        "access_control": acl(mf, fleet, spec.clients, linked_from, spec.connect),
    }


_HEADER = """\
// Zenoh router (zenohd, image eclipse/zenoh) of a Lunaris deployment.
// GENERATED by `lunaris deploy acl` from the code's table of key families and the bridge
// mapping: edit those, then regenerate; tests/deploy fails when this file is stale.
//
// Identities (users of secrets/credentials.txt, made by `lunaris deploy secrets`):
{identities}//
// How zenoh 1.10 applies these rules (its source: zenoh/src/net/routing/interceptor/
// access_control.rs and authorization.rs; checked with the embedded router in tests/deploy):
// - Every message is checked as it arrives from a client ("ingress", for its sender) and as
//   the router sends it on to a client ("egress", for its receiver): a put from A to B needs
//   ingress "put" for A and egress "put" for B, a subscriber of B reaches A's router only
//   with ingress "declare_subscriber" for B and egress "declare_subscriber" for A.
// - A rule applies to a message when one of its key expressions INCLUDES the message's key
//   expression, for every kind of message: a rule on lunaris/*/faults/active/battery does
//   not cover a subscriber declared on lunaris/*/faults/active/* (they only intersect).
// - Anything no rule allows is denied (default_permission "deny"); a deny rule that includes
//   the key wins over an allow rule. A deny covers only what it includes: the observer may
//   subscribe to lunaris/**, and what it must not see is refused sample by sample (egress).
// - A client sends a declared publisher's samples only once its router told it of a matching
//   subscriber, by the subscriber's own key expression (egress "declare_subscriber"): every
//   identity that writes may learn of every subscriber ("learn-subscribers"), or a wildcard
//   subscriber gets the first sample and then nothing. (A plain put is always sent.)
// - Wildcards never match a chunk starting with '@': the advanced publishers' caches and
//   tokens ("<key>/@adv/...") and ROS 2 discovery ("@ros2_lv/...") are listed explicitly.
"""


_LINKS = """\
// - A link between two routers is checked on both sides like a client's session. A subject
//   matches it by what the link shows (authorization.rs; zenoh 1.10 offers usernames,
//   cert_common_names, interfaces, link_protocols and zids; a property left out matches
//   anything): the side that listens learns the other's user name and, with mutual TLS
//   (the router port's "enable_mtls"), its certificate's common name; the side that opens
//   the link learns only the listener's certificate. So a router that opens a link to this
//   one is matched by its user name AND its certificate, one this one opens a link to by its
//   certificate: router-<name>, signed by the deployment's CA. Neither a password alone (no
//   certificate on the clients' port) nor a certificate alone is a router.
// - Linked routers trust each other as routers only ("routers" policy): each carries what
//   its own clients may send and read, having checked them itself.
"""


def _compact(text: str) -> str:
    """JSON with every list of strings on one line: a rule reads as one block."""
    return re.sub(r"\[\s*((?:\"[^\"]*\",?\s*)+)\]",
                  lambda m: "[" + ", ".join(re.findall(r'"[^"]*"', m.group(1))) + "]", text)


def render_router_config(mf: MappingFile, fleet: list[RoverNames] | None = None,
                         secrets_dir: str = ROUTER_SECRETS, site: Site = DEFAULT_SITE,
                         name: str | None = None, link_password: str | None = None) -> str:
    fleet = fleet if fleet is not None else fleet_names()
    spec = site.routers[0] if name is None else site.router(name)
    what = {i: PEOPLE.get(i, f"the {i.removeprefix('lunaris-')} service: its own keys only")
            for i in spec.clients}
    what |= {router_identity(n): f"the router {n}: it opens a link to this one"
             for n in site.linked_from(spec.name)}
    what |= {router_identity(n): f"the router {n}: this one opens a link to it"
             for n in spec.connect}
    lines = "".join(f"//   {i:<18} {w}\n" for i, w in what.items())
    header = _HEADER if site.single else _HEADER.replace(
        "// Zenoh router (zenohd, image eclipse/zenoh) of a Lunaris deployment.",
        f"// Zenoh router {spec.name} (zenohd, image eclipse/zenoh) of the Lunaris site "
        f"{site.label}.\n// A SECRET when it opens links (its password): keep it with the "
        "router's other secrets.") + _LINKS

    body = _compact(json.dumps(router_config(mf, fleet, secrets_dir, site, spec.name,
                                             link_password), indent=2))
    return header.format(identities=lines) + body + "\n"
