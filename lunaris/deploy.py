"""``lunaris deploy acl|secrets|check``: who may do what in a deployment, and its secrets.

- ``acl`` writes ``deploy/zenohd.json5``: the router's configuration, its access control
  derived from the code's own table of key families (:data:`common.keys.FAMILIES`: which
  service publishes which key) and from the bridge mapping (which topics the dashboard
  reads and writes). Each service kind has its own identity and may publish, answer and
  announce only its own keys, so no client can forge another's telemetry, ticks, tokens
  or queryables. ``tests/deploy`` fails when the committed file is stale.
- ``secrets DIR`` makes what a deployment must not share with anyone: a random password
  for every identity (``credentials.txt``, the router's dictionary), one client
  configuration per identity (``client-<identity>.json5``, TLS with the CA inlined) and a
  certificate authority with the router's certificate (``tls/``, by ``openssl``).
  ``--rotate USER`` gives one identity a new password and leaves the others. It also makes
  the console's accounts file, empty (``lunaris console users add`` fills it), and never
  overwrites it.
- ``check DIR`` refuses secrets that cannot be trusted: a missing file, a shipped demo
  password, a short password, a client whose password is not the router's. The
  deployment runs it first and starts nothing when it fails.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import re
import secrets as random_secrets
import subprocess
import sys
from pathlib import Path
from typing import Any

from common import keys
from common.connection import TX_QUEUE_SIZE, is_demo_password
from lunaris.deploy_dashboard import (
    FLEET_FILES,
    bridge_hears,
    dashboard_keys,
    fleet_names,
    inbound_regexes,
    rmw_zenoh_config,
    ros2dds_config,
)
from services.bridge.bindings import RoverNames
from services.bridge.mapping import MappingFile, load_mapping, ros_name
from services.bridge.service import DEFAULT_MAPPING

__all__ = ["IDENTITIES", "SERVICES", "acl", "add_arguments", "check_secrets", "main",
           "make_secrets", "router_config"]

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
PEOPLE = {
    "instructor": "injects and clears faults, commands, inputs, time and sessions; reads all",
    "console": "the instructor console's own identity: what an instructor may do",
    "observer": "the crew's view: telemetry only (no fault puts, faults, journal or events)",
    "debrief": "reads everything an instructor reads, writes nothing (an explicit choice)",
    "dashboard": "the crew's dashboard: reads only the bridge's topics, writes its inbound ones",
}
IDENTITIES = tuple(f"lunaris-{s}" for s in SERVICES) + tuple(PEOPLE)
MIN_PASSWORD_LEN = 16
MIN_DISTINCT_CHARS = 8
ROUTER_SECRETS = "/etc/zenoh/secrets"  # where the router container finds the secrets
REPO = Path(__file__).resolve().parent.parent
ROUTER_FILE = REPO / "deploy" / "zenohd.json5"

_TWIN = ["lunaris/**", "lunaris/**/@adv/**"]
# Every key expression a subscriber may be declared on: `**` includes every one without a
# verbatim chunk; those with one ('@adv', ROS 2 discovery, rmw_zenoh's caches) are listed.
_EVERY_KEY = ["**", "**/@adv/**", "@ros2_lv/**", "@/*/@ros2_pub_cache/**"]
_ROS = ["@ros2_lv/**", "@/*/@ros2_pub_cache/**"]
_READ_IN = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
_READ_OUT = ["put", "delete", "reply", "liveliness_token", "declare_queryable"]
_WRITABLE = ["lunaris/*/fault/**", "lunaris/*/cmd/**", "lunaris/*/input/**",
             "lunaris/*/clock/control", "lunaris/*/control/**"]
# What the crew must discover from effects, not read: the instructor's puts, the journal,
# the faults in effect, the events that name them (the journal's stream and each
# service's own), the session's snapshots.
_CREW_HIDDEN = ["lunaris/*/fault/**", "lunaris/*/event", "lunaris/*/event/**",
                "lunaris/*/event/@adv/**", "lunaris/*/event/*/@adv/**",
                "lunaris/*/faults", "lunaris/*/faults/**", "lunaris/*/control/**",
                "lunaris/*/snapshots", "lunaris/*/snapshots/**"]


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
        out += ["lunaris/*/faults", "lunaris/*/faults/journal", "lunaris/*/snapshots"]
    if service == "battery":
        out += ["lunaris/*/prediction"]
    return out


def _rule(rule_id: str, permission: str, flows: list[str], messages: list[str],
          key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": permission, "flows": flows, "messages": messages,
            "key_exprs": list(dict.fromkeys(key_exprs))}


def acl(mf: MappingFile, fleet: list[RoverNames]) -> dict[str, Any]:
    """The router's ``access_control`` section.

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
    inbound = sorted({m.key.replace("{rover}", "*") for m in mf.mappings if m.direction == "in"})
    inbound = [re.sub(r"\{[a-z_]*\}", "*", k) for k in inbound]
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
        # the dashboard may subscribe on any key expression (its topics of one rover, of
        # several, under a wildcard): only the bridge's topics reach it (dashboard-deliver)
        _rule("dashboard-listen", "allow", ["ingress"],
              ["declare_subscriber", "declare_liveliness_subscriber"], _EVERY_KEY),
        _rule("dashboard-read", "allow", ["ingress"], ["query", "liveliness_query"],
              reads + dash_adv + _ROS),
        _rule("dashboard-deliver", "allow", ["egress"], _READ_OUT, reads + dash_adv + _ROS),
        _rule("dashboard-write", "allow", ["ingress"], ["put", "liveliness_token"],
              writes + _ROS[:1]),
    ]
    subjects = [{"id": person, "usernames": [person]} for person in PEOPLE]
    policies = [
        {"id": "instructor", "subjects": ["instructor", "console"],
         "rules": ["read-twin", "deliver-twin", "learn-subscribers", "instructor-write"]},
        {"id": "debrief", "subjects": ["debrief"], "rules": ["read-twin", "deliver-twin"]},
        {"id": "observer", "subjects": ["observer"],
         "rules": ["read-twin", "deliver-twin", "crew-hidden-deliver", "crew-hidden-ask"]},
        {"id": "dashboard", "subjects": ["dashboard"],
         "rules": ["dashboard-listen", "dashboard-read", "dashboard-deliver", "dashboard-write",
                   "learn-subscribers"]},
    ]
    for service in SERVICES:
        pub = _published(service)
        answered = _answered(service)
        adv = [f"{k}/@adv/**" for k in pub]
        extra_pub: list[str] = []
        if service == "bridge":  # the dashboard's topics, and the inputs they carry in
            extra_pub = reads + dash_adv + ["@ros2_lv/**"] + inbound
        r = f"svc-{service}"
        rules += [
            _rule(f"{r}-publish", "allow", ["ingress"], ["put", "delete"], pub + extra_pub),
            # A cache answers a late joiner with the samples themselves: replies on pub too.
            _rule(f"{r}-answer", "allow", ["ingress"], ["declare_queryable", "reply"],
                  answered + pub + adv + (reads + dash_adv if service == "bridge" else [])),
            # The faults service gathers with one query for every owner (a wildcard): each
            # owner may be asked it, and may reply only on its own key.
            _rule(f"{r}-asked", "allow", ["egress"], ["query"],
                  answered + pub + adv + ["lunaris/*/faults/active/*", "lunaris/*/snapshots/*"]
                  + (reads + dash_adv if service == "bridge" else [])),
            _rule(f"{r}-announce", "allow", ["ingress"], ["liveliness_token"],
                  [f"lunaris/*/service/{service}"] + adv
                  + (dash_adv + ["@ros2_lv/**"] if service == "bridge" else [])),
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
            + (["svc-bridge-hear", "svc-bridge-heard"] if service == "bridge" else []),
        })
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def router_config(mf: MappingFile, fleet: list[RoverNames],
                  secrets_dir: str = ROUTER_SECRETS) -> dict[str, Any]:
    """The router's configuration; ``secrets_dir`` is where it finds the secrets (the
    container's ``/etc/zenoh/secrets``, or a folder of the machine it runs on)."""
    return {
        "mode": "router",
        # Inside the container; docker-compose.yml decides which host address publishes it.
        "listen": {"endpoints": ["tls/0.0.0.0:7447"]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        # Samples stamped, as rmw_zenoh's router and sessions do (and the writes' age is
        # judged by). Zenoh 1.10 forwards between a router's clients (the dashboard's
        # rmw_zenoh session is one) but never from one of its peers to another: deploy/README
        # §5b says what that means for ROS 2 nodes.
        "timestamping": {"enabled": {"router": True, "peer": True, "client": True}},
        "transport": {
            "auth": {"usrpwd": {"dictionary_file": f"{secrets_dir}/credentials.txt"}},
            "link": {"tls": {"listen_certificate": f"{secrets_dir}/tls/router.crt",
                             "listen_private_key": f"{secrets_dir}/tls/router.key"},
                     # what each Lunaris session queues: a fleet's tick, not dropped
                     "tx": {"queue": {"size": TX_QUEUE_SIZE}}},
        },
        "access_control": acl(mf, fleet),
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


def _compact(text: str) -> str:
    """JSON with every list of strings on one line: a rule reads as one block."""
    return re.sub(r"\[\s*((?:\"[^\"]*\",?\s*)+)\]",
                  lambda m: "[" + ", ".join(re.findall(r'"[^"]*"', m.group(1))) + "]", text)


def render_router_config(mf: MappingFile, fleet: list[RoverNames] | None = None,
                         secrets_dir: str = ROUTER_SECRETS) -> str:
    fleet = fleet if fleet is not None else fleet_names()
    what = {i: PEOPLE.get(i, f"the {i.removeprefix('lunaris-')} service: its own keys only")
            for i in IDENTITIES}
    lines = "".join(f"//   {i:<18} {w}\n" for i, w in what.items())
    body = _compact(json.dumps(router_config(mf, fleet, secrets_dir), indent=2))
    return _HEADER.format(identities=lines) + body + "\n"


# -- secrets ---------------------------------------------------------------------------------


def _password() -> str:
    """24 random bytes, URL-safe; drawn again in the rare case the check would call it weak
    (holding ``demo`` after a dash, say)."""
    while True:
        password = random_secrets.token_urlsafe(24)
        if not password_problems("-", password):
            return password


def password_problems(user: str, password: str) -> list[str]:
    """What makes a password unfit for a deployment, in words (empty: nothing)."""
    if is_demo_password(password):
        return [f"{user} still has a shipped demo password (marked demo or CHANGE-ME)"]
    if len(password) < MIN_PASSWORD_LEN:
        return [f"the password of {user} is shorter than {MIN_PASSWORD_LEN} characters"]
    distinct = len(set(password))
    if distinct == 1:
        return [f"the password of {user} is one character repeated"]
    if distinct < MIN_DISTINCT_CHARS:
        return [f"the password of {user} uses only {distinct} different characters "
                f"(at least {MIN_DISTINCT_CHARS}): make it with `lunaris deploy secrets --rotate`"]
    return []


def _read_credentials(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        if line.strip():
            user, _, password = line.partition(":")
            out[user] = password
    return out


def client_config(user: str, password: str, ca_pem: bytes | None, connect: str) -> dict[str, Any]:
    conf: dict[str, Any] = {
        "mode": "client",
        "connect": {"endpoints": [connect]},
        "listen": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"auth": {"usrpwd": {"user": user, "password": password}}},
    }
    if ca_pem is not None:
        conf["transport"]["link"] = {"tls": {
            "root_ca_certificate_base64": base64.b64encode(ca_pem).decode()}}
    return conf


def _openssl(*args: str, cwd: Path) -> None:
    out = subprocess.run(["openssl", *args], cwd=cwd, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"openssl {args[0]} failed: {out.stderr.strip()}")


def _write_private(path: Path, text: str) -> None:
    """Write a file only its owner may read, from its first byte (not chmod after)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(text)
    path.chmod(0o600)  # it may have existed with another mode


def make_certificates(folder: Path, hosts: list[str]) -> None:
    """A certificate authority and the router's certificate for ``hosts`` (names or IPs)."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    folder.chmod(0o700)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    _openssl("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.crt", "-days", "3650",
             "-subj", "/CN=Lunaris deployment CA", cwd=folder)
    _openssl("req", *ec, "-keyout", "router.key", "-out", "router.csr", "-subj",
             f"/CN={hosts[0]}", cwd=folder)
    names = ",".join(f"IP:{h}" if re.fullmatch(r"[0-9.]+|[0-9a-fA-F:]+:[0-9a-fA-F:]*", h)
                     else f"DNS:{h}" for h in hosts)
    (folder / "router.ext").write_text(
        f"subjectAltName={names}\nbasicConstraints=CA:FALSE\n"
        "keyUsage=digitalSignature,keyEncipherment\nextendedKeyUsage=serverAuth\n")
    _openssl("x509", "-req", "-in", "router.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
             "-CAcreateserial", "-out", "router.crt", "-days", "825", "-extfile", "router.ext",
             cwd=folder)
    for name in ("router.csr", "router.ext", "ca.srl"):
        (folder / name).unlink(missing_ok=True)
    for key in ("ca.key", "router.key"):
        (folder / key).chmod(0o600)


def make_secrets(folder: Path, hosts: list[str], connect: str, tls: bool = True,
                 rotate: list[str] | None = None, fleet: list[RoverNames] | None = None,
                 mf: MappingFile | None = None) -> list[str]:
    """Make (or, with ``rotate``, renew some of) the secrets of a deployment; returns what
    was written."""
    folder.mkdir(parents=True, exist_ok=True)
    folder.chmod(0o700)
    cred_path = folder / "credentials.txt"
    creds = _read_credentials(cred_path) if cred_path.is_file() else {}
    unknown = sorted(set(rotate or []) - set(IDENTITIES))
    if unknown:
        raise ValueError(f"unknown identity {', '.join(unknown)} (identities: {', '.join(IDENTITIES)})")
    for user in IDENTITIES:
        if rotate is None or user in rotate or user not in creds:
            creds[user] = _password()
    written = []
    if tls and (rotate is None or not (folder / "tls" / "ca.crt").is_file()):
        make_certificates(folder / "tls", hosts)
        written.append("tls/")
    ca = (folder / "tls" / "ca.crt").read_bytes() if tls else None
    _write_private(cred_path, "".join(f"{u}:{p}\n" for u, p in creds.items()))
    written.append("credentials.txt")
    for user in IDENTITIES:
        if rotate is not None and user not in rotate:
            continue
        path = folder / f"client-{user}.json5"
        _write_private(path, json.dumps(client_config(user, creds[user], ca, connect), indent=2) + "\n")
        written.append(path.name)
    accounts = folder / "console-accounts.json"
    if not accounts.exists():  # people, not machines: made empty once, never overwritten
        _write_private(accounts, '{"users": {}}\n')
        written.append(accounts.name)
    if rotate is None or "dashboard" in rotate:
        fleet = fleet if fleet is not None else fleet_names()
        mf = mf if mf is not None else load_mapping(DEFAULT_MAPPING)
        base = mf.bridge.outputs.ros2.domain_id or 0
        several = len(fleet) > 1
        files = {f"zenoh-bridge-ros2dds-{r.id}.json5": ros2dds_config(
            creds["dashboard"], ca, r.id, mf.bridge.rover_domains.get(r.id, base + place),
            inbound_regexes(mf),
            mf.bridge.fleet_namespace.replace("{rover}", ros_name(r.id)) if several else None)
            for place, r in enumerate(fleet)}
        files["rmw-zenoh-dashboard.json5"] = rmw_zenoh_config(creds["dashboard"], ca, connect)
        for name, conf in files.items():
            path = folder / name
            _write_private(path, json.dumps(conf, indent=2) + "\n")
            written.append(path.name)
    return written


def _open_to_others(folder: Path) -> list[str]:
    """The folder, its subfolders and every file of it but the public certificates, when
    its group or others may read, write or enter it: each named, with the command that
    closes it."""
    out = []
    for path in [folder, *sorted(folder.rglob("*"))]:
        mode = path.stat().st_mode & 0o777
        if path.is_dir() and mode & 0o077:
            out.append(f"{path}: the folder is open to others (mode {mode:o}, not 700): "
                       f"chmod 700 {path}")
        elif path.is_file() and path.suffix != ".crt" and mode & 0o077:
            out.append(f"{path.relative_to(folder)}: readable by others (mode {mode:o}, "
                       f"not 600): chmod 600 {path}")
    return out


def check_secrets(folder: Path, tls: bool = True) -> list[str]:
    """Every reason the secrets in ``folder`` cannot be trusted (empty: they can): a file
    missing, open to others, a weak or demo password, an identity the deployment does not
    know (a line the router would let in), a client whose password is not the router's."""
    cred_path = folder / "credentials.txt"
    if not cred_path.is_file():
        return [f"{cred_path}: missing (make the secrets with `lunaris deploy secrets {folder}`)"]
    problems = _open_to_others(folder)
    creds = _read_credentials(cred_path)
    seen: set[str] = set()
    for number, line in enumerate(cred_path.read_text().splitlines(), 1):
        user, colon, _ = line.partition(":")
        if not line.strip():
            continue
        if not colon:
            problems.append(f"credentials.txt: line {number} is not user:password")
        elif user not in IDENTITIES:
            problems.append(f"credentials.txt: {user!r} (line {number}) is no identity of this "
                            "deployment, and the router would let it in: remove its line")
        elif user in seen:
            problems.append(f"credentials.txt: {user} has more than one line (line {number})")
        seen.add(user)
    for user in IDENTITIES:
        password = creds.get(user)
        if password is None:
            problems.append(f"credentials.txt: no password for {user}")
        else:
            problems += [f"credentials.txt: {p}" for p in password_problems(user, password)]
    for user in IDENTITIES:
        path = folder / f"client-{user}.json5"
        if not path.is_file():
            problems.append(f"{path.name}: missing")
            continue
        auth = json.loads(path.read_text()).get("transport", {}).get("auth", {}).get("usrpwd", {})
        if auth.get("user") != user or auth.get("password") != creds.get(user):
            problems.append(f"{path.name}: its password is not the router's for {user}")
    if tls:
        for name in ("ca.crt", "router.crt", "router.key"):
            if not (folder / "tls" / name).is_file():
                problems.append(f"tls/{name}: missing")
    return problems


# -- the command -----------------------------------------------------------------------------


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    a = sub.add_parser("acl", help="write the router configuration with its access control")
    a.add_argument("--bridge-config", metavar="FILE", help="bridge mapping (default: the shipped one)")
    a.add_argument("--rover", action="append", metavar="FILE",
                   help=f"the deployment's rovers, in order (default {' '.join(FLEET_FILES)})")
    a.add_argument("--output", metavar="FILE", default=str(ROUTER_FILE))
    a.add_argument("--secrets-dir", metavar="DIR", default=ROUTER_SECRETS,
                   help="where the router finds the secrets (default: the container's "
                        f"{ROUTER_SECRETS}; a folder of this machine to run it outside Docker)")
    a.add_argument("--check", action="store_true", help="exit 1 if the file is not up to date")
    s = sub.add_parser("secrets", help="make passwords, client configurations and certificates")
    s.add_argument("dir", metavar="DIR", help="where to write them (deploy/secrets)")
    s.add_argument("--host", action="append", metavar="NAME",
                   help="a name or address of the router in its certificate (default: router, "
                        "localhost, 127.0.0.1; repeat)")
    s.add_argument("--connect", default="tls/router:7447", metavar="ENDPOINT",
                   help="the endpoint the clients connect to (default tls/router:7447)")
    s.add_argument("--no-tls", action="store_true", help="plain TCP: no certificates")
    s.add_argument("--rotate", action="append", metavar="USER",
                   help="give only this identity a new password (repeat)")
    s.add_argument("--rover", action="append", metavar="FILE",
                   help="the deployment's rovers, in order: one zenoh-bridge-ros2dds file each "
                        f"(default {' '.join(FLEET_FILES)})")
    s.add_argument("--bridge-config", metavar="FILE", help="bridge mapping (default: the shipped one)")
    c = sub.add_parser("check", help="refuse secrets that cannot be trusted (exit 1)")
    c.add_argument("dir", metavar="DIR")
    c.add_argument("--no-tls", action="store_true")


def main(args: argparse.Namespace) -> int:
    if args.action == "acl":
        mf = load_mapping(args.bridge_config or DEFAULT_MAPPING)
        secrets_dir = args.secrets_dir
        if secrets_dir != ROUTER_SECRETS:
            secrets_dir = str(Path(secrets_dir).resolve())
        text = render_router_config(mf, fleet_names(args.rover or FLEET_FILES), secrets_dir)
        out = Path(args.output)
        if args.check:
            if not out.is_file() or out.read_text() != text:
                print(f"{out} is stale: run lunaris deploy acl", file=sys.stderr)
                return 1
            return 0
        out.write_text(text)
        print(f"wrote {out}")
        return 0
    if args.action == "secrets":
        hosts = args.host or ["router", "localhost", "127.0.0.1"]
        try:
            written = make_secrets(Path(args.dir), hosts, args.connect, not args.no_tls, args.rotate,
                                   fleet_names(args.rover or FLEET_FILES),
                                   load_mapping(args.bridge_config or DEFAULT_MAPPING))
        except (ValueError, RuntimeError, OSError) as exc:
            print(f"lunaris deploy secrets: {exc}", file=sys.stderr)
            return 2
        print(f"wrote {', '.join(written)} in {args.dir} (keep it private: chmod 700)")
        if args.rotate:
            print("restart the router and the containers of the rotated identities")
        return 0
    problems = check_secrets(Path(args.dir), not args.no_tls)
    for problem in problems:
        print(f"lunaris deploy check: {problem}", file=sys.stderr)
    if problems:
        print("lunaris deploy check: REFUSED: the deployment does not start with these secrets",
              file=sys.stderr)
        return 1
    print(f"lunaris deploy check: the secrets in {args.dir} are fit to use")
    return 0
