"""The secrets and the routers' configurations of a site of several machines
(``lunaris deploy secrets|acl|check --site FILE``, see :mod:`lunaris.deploy_site`).

The secrets folder ``DIR`` of a site::

    DIR/credentials.txt        every identity's password, routers' included: the copy
                               of whoever makes the secrets, never on a machine
    DIR/ca/ca.crt, ca.key      the deployment's one certificate authority
    DIR/<router>/              what the machine of <router> needs, and nothing more:
        credentials.txt        its dictionary: the identities that connect to it and the
                               routers that open a link to it
        tls/                   ca.crt, and its own router.crt / router.key (common name
                               router-<router>, its hosts; a TLS client's too when it
                               opens links: mutual TLS)
        zenohd.json5           its configuration: access control for its own clients and
                               its links, and (when it opens links) its own password: a
                               secret like the rest of the folder
        client-<id>.json5      each identity of the machine, connecting to this router
        console-accounts.json, zenoh-bridge-ros2dds-<rover>.json5, rmw-zenoh-dashboard.json5
                               where the console, the dashboard run

Making them again keeps what exists and makes what is missing (a router added to the site
gets its identity, certificate and folder); ``--rotate ID`` renews one identity (a
router's: its password and its key and certificate) everywhere it appears.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

from lunaris.deploy_acl import REPO, ROUTER_SECRETS, render_router_config
from lunaris.deploy_dashboard import fleet_names
from lunaris.deploy_secrets import (
    client_config,
    credentials_problems,
    dashboard_files,
    make_ca,
    make_certificate,
    new_password,
    open_to_others,
    password_problems,
    read_credentials,
    write_private,
)
from lunaris.deploy_site import SERVICES, RouterSpec, Site
from services.bridge import DEFAULT_MAPPING, MappingFile, RoverNames, load_mapping

__all__ = ["check_router_folder", "check_site_secrets", "folder_contents", "make_site_secrets",
           "router_folder_files", "site_changes", "site_fleet", "site_problems",
           "write_router_configs"]

_LOCAL_HOSTS = ["localhost", "127.0.0.1"]  # on every router's certificate: its own machine


def site_fleet(site: Site) -> tuple[MappingFile, list[RoverNames]]:
    """The bridge mapping and the fleet (rovers in order) a site serves."""
    mapping = site.bridge_config or DEFAULT_MAPPING
    path = Path(mapping) if Path(mapping).is_absolute() else REPO / mapping
    return load_mapping(path), fleet_names(list(site.rovers))


def site_problems(site: Site, fleet: list[RoverNames]) -> list[str]:
    """What a site asks that its fleet cannot give: a rover a machine names that the site
    does not have, a rover a service kind serves on two machines or on none."""
    ids = [r.id for r in fleet]
    problems = []
    for spec in site.routers:
        for rid in spec.rovers or ():
            if rid not in ids:
                problems.append(f"routers ({spec.name}).rovers: no rover of the site is {rid!r} "
                                f"(rovers: {', '.join(ids)})")
    for service in SERVICES:
        for rid in ids:
            where = [s.name for s in site.routers if service in s.runs
                     and (s.rovers is None or rid in s.rovers)]
            if len(where) > 1:
                problems.append(f"the {service} service of {rid} runs on {' and '.join(where)}: "
                                "one machine only")
            elif not where:
                problems.append(f"no machine runs the {service} service of {rid}")
    return problems


def _dictionary(site: Site, spec: RouterSpec) -> tuple[str, ...]:
    """Who the router lets in: its clients, and the routers that open a link to it."""
    return spec.clients + tuple(site.router(n).identity for n in site.linked_from(spec.name))


def _client_endpoint(site: Site, spec: RouterSpec) -> str:
    return f"tls/{spec.hosts[0]}:{spec.client_port}"


def _runtime_dir(secrets_dir: str | None, name: str) -> str:
    """Where a router finds its folder when it runs: the container's /etc/zenoh/secrets, or
    (outside Docker) ``<secrets_dir>/<router>``."""
    return ROUTER_SECRETS if secrets_dir is None else str(Path(secrets_dir).resolve() / name)


def make_site_secrets(folder: Path, site: Site, rotate: list[str] | None = None,
                      secrets_dir: str | None = None) -> list[str]:
    """Make what is missing of a site's secrets, renew the identities in ``rotate``, and
    write every router's folder and configuration; returns what was written."""
    unknown = sorted(set(rotate or []) - set(site.identities))
    if unknown:
        raise ValueError(f"unknown identity {', '.join(unknown)} "
                         f"(identities of {site.source}: {', '.join(site.identities)})")
    mf, fleet = site_fleet(site)
    problems = site_problems(site, fleet)
    if problems:
        raise ValueError("; ".join(problems))
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    folder.chmod(0o700)
    written = []
    master = folder / "credentials.txt"
    creds = read_credentials(master) if master.is_file() else {}
    for identity in site.identities:
        if identity not in creds or identity in (rotate or []):
            creds[identity] = new_password()
    write_private(master, "".join(f"{u}:{p}\n" for u, p in creds.items()))
    written.append("credentials.txt")
    ca = folder / "ca"
    if not (ca / "ca.crt").is_file():
        make_ca(ca)
        written.append("ca/")
    ca_pem = (ca / "ca.crt").read_bytes()
    for spec in site.routers:
        rfolder = folder / spec.name
        tls = rfolder / "tls"
        tls.mkdir(mode=0o700, parents=True, exist_ok=True)
        rfolder.chmod(0o700)
        if not (tls / "router.crt").is_file() or spec.identity in (rotate or []):
            linked = bool(spec.connect)
            make_certificate(tls, ca, spec.identity, [*spec.hosts, *_LOCAL_HOSTS], linked)
            written.append(f"{spec.name}/tls/router.crt")
        shutil.copyfile(ca / "ca.crt", tls / "ca.crt")
        write_private(rfolder / "credentials.txt",
                      "".join(f"{u}:{creds[u]}\n" for u in _dictionary(site, spec)))
        for identity in spec.clients:
            write_private(rfolder / f"client-{identity}.json5", json.dumps(client_config(
                identity, creds[identity], ca_pem, _client_endpoint(site, spec)), indent=2) + "\n")
        if "console" in spec.runs and not (rfolder / "console-accounts.json").exists():
            write_private(rfolder / "console-accounts.json", '{"users": {}}\n')
        if "dashboard" in spec.clients:
            for name, conf in dashboard_files(creds["dashboard"], ca_pem, mf, fleet,
                                              _client_endpoint(site, spec),
                                              f"tls/127.0.0.1:{spec.client_port}").items():
                write_private(rfolder / name, json.dumps(conf, indent=2) + "\n")
        written.append(f"{spec.name}/")
    written += write_router_configs(folder, site, secrets_dir)
    return written


def folder_contents(folder: Path, site: Site) -> dict[str, dict[str, bytes]]:
    """Every router's folder of a site's secrets, file by file (what a rerun compares)."""
    out = {}
    for spec in site.routers:
        rfolder = folder / spec.name
        out[spec.name] = {p.relative_to(rfolder).as_posix(): p.read_bytes()
                          for p in sorted(rfolder.rglob("*")) if p.is_file()} if rfolder.is_dir() else {}
    return out


_ROUTER_FILES = {"credentials.txt": "its dictionary", "tls/router.crt": "its certificate",
                 "tls/router.key": "its key", "tls/ca.crt": "the CA's certificate",
                 "zenohd.json5": "its configuration"}


def _what_changed(name: str) -> str:
    if name in _ROUTER_FILES:
        return _ROUTER_FILES[name]
    if name.startswith("client-"):
        return f"the client file of {name.removeprefix('client-').removesuffix('.json5')}"
    return name


def _containers(spec: RouterSpec, files: list[str]) -> list[str]:
    """What takes a changed client file: the compose service of the process, or the people's
    tools (they read it when they start)."""
    out = []
    for f in files:
        if f.startswith("client-"):
            identity = f.removeprefix("client-").removesuffix(".json5")
            if identity.startswith("lunaris-") or identity == "console":
                out.append(f"{spec.name}-{identity.removeprefix('lunaris-')}")
            else:
                out.append(f"the tools of {identity} on {spec.name} (they read it when they start)")
        elif f.startswith("zenoh-bridge-ros2dds-"):
            out.append(f"{spec.name}-{f.removesuffix('.json5')}")
        elif f == "rmw-zenoh-dashboard.json5":
            out.append(f"the dashboard on rmw_zenoh on {spec.name}")
    return out


def site_changes(site: Site, before: dict[str, dict[str, bytes]],
                 after: dict[str, dict[str, bytes]]) -> list[str]:
    """In words, after ``deploy secrets --site`` made again or rotated: which machines' folders
    changed (and what in them), which did not, and what to restart, in order: a router whose
    dictionary, certificate or configuration changed, those that others link to before those
    that link to them (a rotated router's new password is known where it is shown before it is
    shown), then the containers of the changed client files."""
    changed = {}
    for spec in site.routers:
        old, new = before.get(spec.name, {}), after.get(spec.name, {})
        files = sorted(f for f in set(old) | set(new) if old.get(f) != new.get(f))
        if files:
            changed[spec.name] = files
    if not changed:
        return ["nothing changed in the machines' folders: nothing to copy or restart"]
    lines = ["changed: " + "; ".join(
        f"{n}/ (" + ("made" if not before.get(n) else ", ".join(_what_changed(f) for f in fs)) + ")"
        for n, fs in changed.items())]
    same = [f"{r.name}/" for r in site.routers if r.name not in changed]
    if same:
        lines.append(f"unchanged: {', '.join(same)} (nothing to copy there)")
    routers = [n for n, fs in changed.items() if any(f in _ROUTER_FILES for f in fs)]
    order: list[str] = []
    while len(order) < len(routers):
        ready = [n for n in routers if n not in order
                 and all(t in order or t not in routers for t in site.router(n).connect)]
        order += ready or [n for n in routers if n not in order]  # a ring of links: site order
    steps = [f"the router of {n} ({n}-router)" for n in order]
    steps += [c for n, fs in changed.items() for c in _containers(site.router(n), fs)]
    machines = "its machine" if len(changed) == 1 else "their machines"
    lines.append(f"copy {', '.join(f'{n}/' for n in changed)} to {machines}, then restart, in "
                 "this order:")
    lines += [f"  {i}. {step}" for i, step in enumerate(steps, 1)]
    return lines


def _config_text(folder: Path, site: Site, spec: RouterSpec, secrets_dir: str | None,
                 mf: MappingFile, fleet: list[RoverNames]) -> str:
    creds = read_credentials(folder / "credentials.txt")
    return render_router_config(mf, fleet, _runtime_dir(secrets_dir, spec.name), site, spec.name,
                                creds.get(spec.identity) if spec.connect else None)


def write_router_configs(folder: Path, site: Site, secrets_dir: str | None = None,
                         check: bool = False) -> list[str]:
    """Every router's ``zenohd.json5`` in its folder (its password from the site's
    credentials); ``check``: write nothing, return the stale ones."""
    mf, fleet = site_fleet(site)
    out = []
    for spec in site.routers:
        path = folder / spec.name / "zenohd.json5"
        runtime = secrets_dir if secrets_dir is not None or not path.is_file() else \
            _secrets_dir_of(path, spec.name)
        text = _config_text(folder, site, spec, runtime, mf, fleet)
        if check:
            if not path.is_file() or path.read_text() != text:
                out.append(f"{spec.name}/zenohd.json5")
        else:
            write_private(path, text)
            out.append(f"{spec.name}/zenohd.json5")
    return out


def _secrets_dir_of(config: Path, name: str) -> str | None:
    """The ``--secrets-dir`` a router's configuration was written for (None: Docker's)."""
    dictionary = Path(_config(config)["transport"]["auth"]["usrpwd"]["dictionary_file"]).parent
    return None if str(dictionary) == ROUTER_SECRETS else str(dictionary.parent)


def _config(path: Path) -> dict:
    """A generated configuration: JSON after its comment lines."""
    return json.loads("\n".join(line for line in path.read_text().splitlines()
                                if not line.lstrip().startswith("//")))


# -- the checks ------------------------------------------------------------------------------


def _certificate_problems(tls: Path, identity: str) -> list[str]:
    if not all((tls / n).is_file() for n in ("ca.crt", "router.crt", "router.key")):
        return []  # said as missing files
    try:
        verify = subprocess.run(["openssl", "verify", "-CAfile", str(tls / "ca.crt"),
                                 str(tls / "router.crt")], capture_output=True, text=True)
    except FileNotFoundError:
        return ["tls/router.crt: cannot be checked: openssl is not installed"]
    if verify.returncode != 0:
        return ["tls/router.crt: not signed by the deployment's CA (tls/ca.crt): make it again "
                f"with `lunaris deploy secrets DIR --site FILE --rotate {identity}`"]
    subject = subprocess.run(["openssl", "x509", "-noout", "-subject", "-in",
                              str(tls / "router.crt")], capture_output=True, text=True).stdout
    if not re.search(rf"CN\s*=\s*{re.escape(identity)}\s*$", subject.strip()):
        return [f"tls/router.crt: its common name is not {identity} ({subject.strip()})"]
    return []


def router_folder_files(site: Site, spec: RouterSpec) -> set[str]:
    """What the folder of router ``spec``'s machine holds (paths in it), and nothing more."""
    files = {"credentials.txt", "zenohd.json5", "tls/ca.crt", "tls/router.crt", "tls/router.key"}
    files |= {f"client-{identity}.json5" for identity in spec.clients}
    if "console" in spec.runs:
        files.add("console-accounts.json")
    if "dashboard" in spec.clients:
        _, fleet = site_fleet(site)
        files |= {f"zenoh-bridge-ros2dds-{r.id}.json5" for r in fleet} | {"rmw-zenoh-dashboard.json5"}
    return files


def _unneeded(rfolder: Path, site: Site, spec: RouterSpec) -> list[str]:
    """Each file or folder of a machine's folder that its machine does not need, and why it must
    go: the CA's key above all (with it anyone makes a router of the site), another machine's
    or identity's secrets (whoever reads this machine would have them)."""
    needed = router_folder_files(site, spec)
    folders = {str(Path(f).parent) for f in needed} - {"."}
    identities = {i for r in site.routers for i in r.clients}
    out = []
    for path in sorted(rfolder.rglob("*")):
        rel = path.relative_to(rfolder).as_posix()
        if rel in needed or (path.is_dir() and rel in folders):
            continue
        if path.is_dir():
            if not any(p.is_file() for p in path.rglob("*")):
                out.append(f"{rel}/: not something this machine needs: remove it")
            continue
        text = path.read_bytes()[:100_000] if path.is_file() else b""
        client = rel.removeprefix("client-").removesuffix(".json5") if rel.startswith("client-") else None
        if path.name == "ca.key":
            out.append(f"{rel}: the site's CA's private key: with it anyone makes a router the "
                       "site trusts; no machine needs it, it stays with whoever makes the secrets "
                       "(DIR/ca/): remove it from this machine")
        elif b"PRIVATE KEY" in text:
            out.append(f"{rel}: a private key this machine does not need (its own is "
                       "tls/router.key): remove it")
        elif client is not None and "/" not in rel:
            where = [r.name for r in site.routers if client in r.clients]
            out.append(f"{rel}: the identity {client} does not connect to the router {spec.name}"
                       + (f" (it connects to {', '.join(where)})" if where else
                          "" if client in identities else " (no machine of the site has it)")
                       + ": whoever reads this machine would have its password: remove it")
        else:
            out.append(f"{rel}: not something the machine of {spec.name} needs (its folder "
                       f"holds what it needs and nothing more): remove it")
    return out


def check_router_folder(rfolder: Path, site: Site, name: str) -> list[str]:
    """What one machine's folder holds that cannot be trusted (what its ``preflight``
    checks): files missing or open to others, its dictionary (weak passwords, identities it
    should not let in), clients that do not match it, a certificate that is not its own
    under the CA, a configuration that is not the site's."""
    spec = site.router(name)
    if not (rfolder / "credentials.txt").is_file():
        return [f"{rfolder}/credentials.txt: missing (make the secrets with `lunaris deploy "
                f"secrets DIR --site {site.source}`, then copy DIR/{name} to this machine)"]
    problems = open_to_others(rfolder) + _unneeded(rfolder, site, spec)
    expected = _dictionary(site, spec)
    dictionary = read_credentials(rfolder / "credentials.txt")
    problems += credentials_problems(rfolder / "credentials.txt", expected)
    problems += [f"credentials.txt: no password for {i}" for i in expected if i not in dictionary]
    for identity in spec.clients:
        path = rfolder / f"client-{identity}.json5"
        if not path.is_file():
            problems.append(f"{path.name}: missing")
            continue
        auth = json.loads(path.read_text())["transport"]["auth"]["usrpwd"]
        if auth.get("user") != identity or auth.get("password") != dictionary.get(identity):
            problems.append(f"{path.name}: its password is not the router's for {identity}")
    for f in ("tls/ca.crt", "tls/router.crt", "tls/router.key", "zenohd.json5"):
        if not (rfolder / f).is_file():
            problems.append(f"{f}: missing")
    problems += _certificate_problems(rfolder / "tls", spec.identity)
    config = rfolder / "zenohd.json5"
    if config.is_file():
        usrpwd = _config(config)["transport"]["auth"]["usrpwd"]
        if spec.connect:
            problems += [f"zenohd.json5: {p}" for p in
                         password_problems(spec.identity, usrpwd.get("password", ""))]
        mf, fleet = site_fleet(site)
        want = render_router_config(mf, fleet, _runtime_dir(_secrets_dir_of(config, name), name),
                                    site, name, usrpwd.get("password") if spec.connect else None)
        if config.read_text() != want:
            problems.append(f"zenohd.json5: not the configuration {site.source} gives the router "
                            f"{name}: run `lunaris deploy acl --site {site.source}`")
    return [f"{name}/{p}" if not p.startswith(str(rfolder)) else p for p in problems]


def check_site_secrets(folder: Path, site: Site) -> list[str]:
    """Every reason a site's secrets cannot be trusted: the master copy's, each router's
    folder's (:func:`check_router_folder`), the routers' dictionaries and passwords against
    the master copy, and anything left behind: a folder of a router the site no longer has,
    an identity no router of it knows."""
    master = folder / "credentials.txt"
    if not master.is_file():
        return [f"{master}: missing (make the secrets with `lunaris deploy secrets {folder} "
                f"--site {site.source}`)"]
    problems = [p for p in open_to_others(folder) if not any(
        p.startswith(f"{r.name}/") or p.startswith(str(folder / r.name)) for r in site.routers)]
    problems += credentials_problems(master, site.identities)
    creds = read_credentials(master)
    problems += [f"credentials.txt: no password for {i}" for i in site.identities if i not in creds]
    names = {r.name for r in site.routers}
    for path in sorted(folder.iterdir()):
        if path.is_dir() and path.name != "ca" and path.name not in names:
            problems.append(f"{path.name}/: the folder of a router {site.source} does not have: "
                            "remove it (and its machine's router)")
    for spec in site.routers:
        rfolder = folder / spec.name
        problems += check_router_folder(rfolder, site, spec.name)
        dictionary = read_credentials(rfolder / "credentials.txt") \
            if (rfolder / "credentials.txt").is_file() else {}
        for identity, password in dictionary.items():
            if identity in creds and password != creds[identity]:
                problems.append(f"{spec.name}/credentials.txt: the password of {identity} is not "
                                f"the site's: run `lunaris deploy secrets {folder} --site "
                                f"{site.source}` again")
        config = rfolder / "zenohd.json5"
        if spec.connect and config.is_file():
            password = _config(config)["transport"]["auth"]["usrpwd"].get("password")
            if password != creds.get(spec.identity):
                problems.append(f"{spec.name}/zenohd.json5: its password is not the site's for "
                                f"{spec.identity}: the routers it links to would refuse it")
    return problems
