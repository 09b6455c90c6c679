"""A deployment's secrets: passwords, client configurations, certificates, and their check
(``lunaris deploy secrets|check``, one router; a site's: :mod:`lunaris.deploy_routers`).

- ``secrets DIR`` makes what a deployment must not share with anyone: a random password
  for every identity (``credentials.txt``, the router's dictionary), one client
  configuration per identity (``client-<identity>.json5``, TLS with the CA inlined), the
  dashboard's own client files (a ``zenoh-bridge-ros2dds`` per rover, the rmw_zenoh session:
  :func:`dashboard_files`) and a certificate authority with the router's certificate
  (``tls/``, by ``openssl``).
  ``--rotate USER`` gives one identity a new password and leaves the others. It also makes
  the console's accounts file, empty (``lunaris console users add`` fills it), and never
  overwrites it. Every file is its owner's only, from its first byte.
- ``check DIR`` refuses secrets that cannot be trusted, each named in words: a missing
  file, a file or folder open to others, a weak or demo password, an identity the
  deployment does not know, a client whose password is not the router's. The deployment
  runs it first and starts nothing when it fails.
"""

from __future__ import annotations

import base64
import json
import os
import re
import secrets as random_secrets
import subprocess
from pathlib import Path
from typing import Any

from common.connection import is_demo_password
from lunaris.deploy_dashboard import fleet_names, inbound_regexes
from lunaris.deploy_site import IDENTITIES
from services.bridge import DEFAULT_MAPPING, MappingFile, RoverNames, load_mapping, ros_name

__all__ = ["MIN_DISTINCT_CHARS", "MIN_PASSWORD_LEN", "check_secrets", "client_config",
           "credentials_problems", "dashboard_files", "make_ca", "make_certificate", "make_certificates",
           "make_secrets", "new_password", "open_to_others", "password_problems",
           "read_credentials", "rmw_zenoh_config", "ros2dds_config", "write_private"]

MIN_PASSWORD_LEN = 16
MIN_DISTINCT_CHARS = 8

def new_password() -> str:
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


def read_credentials(path: Path) -> dict[str, str]:
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


def write_private(path: Path, text: str) -> None:
    """Write a file only its owner may read, from its first byte (not chmod after)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(text)
    path.chmod(0o600)  # it may have existed with another mode


def _private_folder(folder: Path) -> None:
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    folder.chmod(0o700)


_EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def make_ca(folder: Path) -> None:
    """The deployment's certificate authority: ``ca.key`` (stays with whoever makes the
    secrets) and ``ca.crt`` (every client and router trusts it)."""
    _private_folder(folder)
    _openssl("req", "-x509", *_EC, "-keyout", "ca.key", "-out", "ca.crt", "-days", "3650",
             "-subj", "/CN=Lunaris deployment CA", cwd=folder)
    (folder / "ca.key").chmod(0o600)


def make_certificate(folder: Path, ca: Path, common_name: str, hosts: list[str],
                     linked: bool = False) -> None:
    """``router.key`` and ``router.crt`` in ``folder``, signed by the CA in ``ca``: the names
    and addresses ``hosts`` (what clients check), ``common_name`` (what another router's
    access control matches); ``linked``: also a TLS client's certificate, for the links it
    opens to other routers (mutual TLS)."""
    # openssl runs in the certificate's folder: the CA's path must not be relative to ours
    folder, ca = folder.resolve(), ca.resolve()
    _private_folder(folder)
    _openssl("req", *_EC, "-keyout", "router.key", "-out", "router.csr", "-subj",
             f"/CN={common_name}", cwd=folder)
    names = ",".join(f"IP:{h}" if re.fullmatch(r"[0-9.]+|[0-9a-fA-F:]+:[0-9a-fA-F:]*", h)
                     else f"DNS:{h}" for h in dict.fromkeys(hosts))
    usage = "serverAuth,clientAuth" if linked else "serverAuth"
    (folder / "router.ext").write_text(
        f"subjectAltName={names}\nbasicConstraints=CA:FALSE\n"
        f"keyUsage=digitalSignature,keyEncipherment\nextendedKeyUsage={usage}\n")
    _openssl("x509", "-req", "-in", "router.csr", "-CA", str(ca / "ca.crt"), "-CAkey",
             str(ca / "ca.key"), "-CAserial", str(folder / "ca.srl"), "-CAcreateserial",
             "-out", "router.crt", "-days", "825", "-extfile", "router.ext", cwd=folder)
    for name in ("router.csr", "router.ext", "ca.srl"):
        (folder / name).unlink(missing_ok=True)
    (folder / "router.key").chmod(0o600)


def make_certificates(folder: Path, hosts: list[str]) -> None:
    """A certificate authority and the router's certificate for ``hosts`` (names or IPs),
    in one folder: the one-router deployment's ``tls/``."""
    make_ca(folder)
    make_certificate(folder, folder, hosts[0], hosts)


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
    conf = client_config("dashboard", password, ca_pem, connect)
    plugin: dict[str, Any] = {"id": f"lunaris-{ros_name(rover)}", "domain": domain,
                              "allow": {"publishers": inbound, "subscribers": [".*"]}}
    if namespace is not None:
        plugin["namespace"] = namespace
    conf["plugins"] = {"ros2dds": plugin}
    return conf


def rmw_zenoh_config(password: str, ca_pem: bytes | None, connect: str) -> dict[str, Any]:
    """The Zenoh session of a dashboard on rmw_zenoh (``ZENOH_SESSION_CONFIG_URI``): a client of
    the deployment's router as ``dashboard``, timestamping on as rmw_zenoh's own sessions."""
    conf = client_config("dashboard", password, ca_pem, connect)
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


def make_secrets(folder: Path, hosts: list[str], connect: str, tls: bool = True,
                 rotate: list[str] | None = None, fleet: list[RoverNames] | None = None,
                 mf: MappingFile | None = None) -> list[str]:
    """Make (or, with ``rotate``, renew some of) the secrets of a deployment; returns what
    was written."""
    folder.mkdir(parents=True, exist_ok=True)
    folder.chmod(0o700)
    cred_path = folder / "credentials.txt"
    creds = read_credentials(cred_path) if cred_path.is_file() else {}
    unknown = sorted(set(rotate or []) - set(IDENTITIES))
    if unknown:
        raise ValueError(f"unknown identity {', '.join(unknown)} (identities: {', '.join(IDENTITIES)})")
    for user in IDENTITIES:
        if rotate is None or user in rotate or user not in creds:
            creds[user] = new_password()
    written = []
    if tls and (rotate is None or not (folder / "tls" / "ca.crt").is_file()):
        make_certificates(folder / "tls", hosts)
        written.append("tls/")
    ca = (folder / "tls" / "ca.crt").read_bytes() if tls else None
    write_private(cred_path, "".join(f"{u}:{p}\n" for u, p in creds.items()))
    written.append("credentials.txt")
    for user in IDENTITIES:
        if rotate is not None and user not in rotate:
            continue
        path = folder / f"client-{user}.json5"
        write_private(path, json.dumps(client_config(user, creds[user], ca, connect), indent=2) + "\n")
        written.append(path.name)
    accounts = folder / "console-accounts.json"
    if not accounts.exists():  # people, not machines: made empty once, never overwritten
        write_private(accounts, '{"users": {}}\n')
        written.append(accounts.name)
    if rotate is None or "dashboard" in rotate:
        fleet = fleet if fleet is not None else fleet_names()
        mf = mf if mf is not None else load_mapping(DEFAULT_MAPPING)
        for name, conf in dashboard_files(creds["dashboard"], ca, mf, fleet, connect).items():
            path = folder / name
            write_private(path, json.dumps(conf, indent=2) + "\n")
            written.append(path.name)
    return written


def open_to_others(folder: Path) -> list[str]:
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


def credentials_problems(path: Path, known: tuple[str, ...]) -> list[str]:
    """A dictionary's lines that cannot be trusted: not ``user:password``, a user the
    deployment does not know (the router would let it in), a user on two lines; and the
    weak or demo passwords of the users it knows."""
    problems, seen = [], set()
    for number, line in enumerate(path.read_text().splitlines(), 1):
        user, colon, password = line.partition(":")
        if not line.strip():
            continue
        if not colon:
            problems.append(f"{path.name}: line {number} is not user:password")
        elif user not in known:
            problems.append(f"{path.name}: {user!r} (line {number}) is no identity of this "
                            "deployment, and the router would let it in: remove its line")
        elif user in seen:
            problems.append(f"{path.name}: {user} has more than one line (line {number})")
        else:
            problems += [f"{path.name}: {p}" for p in password_problems(user, password)]
        seen.add(user)
    return problems


def check_secrets(folder: Path, tls: bool = True) -> list[str]:
    """Every reason the secrets in ``folder`` cannot be trusted (empty: they can): a file
    missing, open to others, a weak or demo password, an identity the deployment does not
    know (a line the router would let in), a client whose password is not the router's."""
    cred_path = folder / "credentials.txt"
    if not cred_path.is_file():
        return [f"{cred_path}: missing (make the secrets with `lunaris deploy secrets {folder}`)"]
    problems = open_to_others(folder)
    creds = read_credentials(cred_path)
    problems += credentials_problems(cred_path, IDENTITIES)
    problems += [f"credentials.txt: no password for {user}" for user in IDENTITIES
                 if user not in creds]
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
