"""``lunaris deploy compose --site FILE``: the Docker Compose file of a site of several machines.

One profile per router of the site (``deploy/site.yaml``, :mod:`lunaris.deploy_site`): the
machine's preflight (``lunaris deploy check --site --router``: nothing starts when it fails),
its router (the clients' port published, and the routers' port when another router opens a
link to it; the machine's names as network aliases, the names on its certificate), each
Lunaris service it runs under its own identity for the rovers it serves, the console, and
one zenoh-bridge-ros2dds per rover where the crew's dashboard connects. Written from the
site, so that it never says other than the site: ``docker-compose.site.yml`` is this for
the shipped site, and ``tests/deploy`` fails when it is stale.
"""

from __future__ import annotations

import ipaddress
import json
from pathlib import Path

from lunaris.deploy_acl import REPO
from lunaris.deploy_routers import site_fleet
from lunaris.deploy_site import SERVICES, RouterSpec, Site
from services.bridge import LOCAL_MAPPING

__all__ = ["COMPOSE_FILE", "address_variable", "render_site_compose", "write_site_compose"]

COMPOSE_FILE = REPO / "docker-compose.site.yml"
APP = "/opt/lunaris"  # the image's working directory (deploy/Dockerfile)
STATE = "/var/lib/lunaris"

_HEAD = """\
# Lunaris on {n} machine(s) (SPEC §12f), the site of {site}: a Zenoh router on each machine,
# linked with mutual TLS, each checking its own clients. One profile per machine. Written by
#   lunaris deploy compose --site {site}
# from the site file: edit the site, not this file, and write it again.
#
#   lunaris deploy secrets {secrets} --site {site}   # once, on a safe machine
#   # copy {secrets}/<machine>/ (and this repository) to each machine, then there:
{ups}
#
# Each machine's `preflight` checks its own folder against the site (`lunaris deploy check
# --site --router`) and nothing starts when it fails. The routers publish the clients' port
# and, where another router opens a link to them, the routers' port on LUNARIS_BIND
# (default: every address of the machine: the other machines must reach them). Inside a
# machine, its services reach its router by the machine's name (a network alias), the name
# on the router's certificate. A router reaches the others by their first names in the site:
# these must resolve inside its container, by DNS (a container does not read its machine's
# /etc/hosts), or the site gives a machine's address beside its name (hosts: [NAME, ADDRESS])
# and the routers' extra_hosts pin it (LUNARIS_ADDRESS_<ROUTER> changes it). The console
# publishes its page on LUNARIS_CONSOLE_BIND (default 127.0.0.1) and answers to its machine's
# names in the site, or to those of LUNARIS_ALLOW_HOST (comma-separated). deploy/README.md §9
# has the whole guide; docker-compose.yml is the one-machine case.

x-lunaris: &lunaris
  image: lunaris:${{LUNARIS_TAG:-latest}}
  build:
    context: .
    dockerfile: deploy/Dockerfile

x-router: &router
  image: eclipse/zenoh:${{ZENOH_VERSION:-1.10.2}}
  restart: unless-stopped
  command: ["-c", "/etc/zenoh/secrets/zenohd.json5"]

services:
"""


def _list(items: list[str], indent: int = 0) -> str:
    """A YAML flow list of strings (JSON's quoting is YAML's), broken before 100 columns with
    its lines after the first at ``indent`` + 1 (the column after its ``[``)."""
    lines, line = [], "["
    for i, item in enumerate(items):
        word = json.dumps(item) + ("," if i < len(items) - 1 else "]")
        if len(line) > 1 and indent + len(line) + 1 + len(word) > 100:
            lines.append(line)
            line = " " * (indent + 1) + word
        else:
            line += ("" if line == "[" else " ") + word
    lines.append(line if items else "[]")
    return "\n".join(lines)


def _names(hosts: tuple[str, ...]) -> list[str]:
    """The hosts that are names (a network alias cannot be an address)."""
    out = []
    for h in hosts:
        try:
            ipaddress.ip_address(h)
        except ValueError:
            out.append(h)
    return out


def _address(hosts: tuple[str, ...]) -> str | None:
    """The first address among a machine's hosts (None: names only)."""
    for h in hosts:
        try:
            return str(ipaddress.ip_address(h))
        except ValueError:
            continue
    return None


def address_variable(name: str) -> str:
    """The variable that gives the address of router ``name``'s machine: LUNARIS_ADDRESS_<NAME>."""
    return "LUNARIS_ADDRESS_" + "".join(c if c.isalnum() else "_" for c in name.upper())


def _extra_hosts(site: Site, spec: RouterSpec) -> str:
    """The ``extra_hosts`` of a router that opens links: the name it reaches each other router
    by, pinned to that machine's address (a container does not read its machine's
    /etc/hosts). Given where the site names an address beside the name (the variable
    :func:`address_variable` may change it); otherwise the name must resolve by DNS."""
    lines = []
    for target in spec.connect:
        other = site.router(target)
        address, names = _address(other.hosts), _names(other.hosts)
        if address is not None and names and names[0] == other.hosts[0]:
            lines.append(f'      - "{names[0]}:${{{address_variable(target)}:-{address}}}"\n')
    return "    extra_hosts:\n" + "".join(lines) if lines else ""


def _what(spec: RouterSpec) -> str:
    runs = [r for r in spec.runs if r != "console"]
    parts = []
    if runs:
        parts.append("the " + ", ".join(runs) + (" service" if len(runs) == 1 else " services"))
    if "console" in spec.runs:
        parts.append("the instructor console")
    if "dashboard" in spec.people:
        parts.append("zenoh-bridge-ros2dds for DDS dashboards")
    return "; ".join(parts) or "a router only"


def render_site_compose(site: Site, site_path: str, secrets: str = "deploy/secrets") -> str:
    """The compose file of ``site`` (read from ``site_path``, relative to the repository), its
    machines' folders in ``secrets`` (relative to the repository)."""
    _, fleet = site_fleet(site)
    files = dict(zip((r.id for r in fleet), site.rovers, strict=True))
    bridge_config = site.bridge_config or LOCAL_MAPPING
    ups = "\n".join(f"#   docker compose -f docker-compose.site.yml --profile {r.name} up -d"
                    for r in site.routers)
    out = [_HEAD.format(n=len(site.routers), site=site_path, secrets=secrets, ups=ups)]
    for spec in site.routers:
        name, folder = spec.name, f"./{secrets}/{spec.name}"
        profile = f'profiles: ["{name}"]'
        out.append(f"""\
  # -- {name}: {_what(spec)} {'-' * max(3, 84 - len(name) - len(_what(spec)))}
  {name}-preflight:
    <<: *lunaris
    {profile}
    restart: "no"
    command: ["deploy", "check", "/etc/lunaris/secrets", "--site", {json.dumps(site_path)},
              "--router", {json.dumps(name)}]
    volumes:
      - ./{site_path}:{APP}/{site_path}:ro
      - ./config:{APP}/config:ro
      - {folder}:/etc/lunaris/secrets:ro

  {name}-router:
    <<: *router
    {profile}
    depends_on:
      {name}-preflight:
        condition: service_completed_successfully
    ports:
      - "${{LUNARIS_BIND:-0.0.0.0}}:{spec.client_port}:{spec.client_port}"
""")
        if site.linked_from(name):
            out.append(f'      - "${{LUNARIS_BIND:-0.0.0.0}}:{spec.router_port}:{spec.router_port}"\n')
        aliases = _names(spec.hosts)
        if aliases:
            out.append(f"""\
    networks:
      default:
        aliases: {_list(aliases, len("        aliases: "))}
""")
        out.append(_extra_hosts(site, spec))
        out.append(f"""\
    volumes:
      - {folder}:/etc/zenoh/secrets:ro
""")
        rovers = [rid for rid in files if spec.rovers is None or rid in spec.rovers]
        rover_args = [a for rid in rovers for a in ("--rover", files[rid])]
        for what in spec.runs:
            if what in SERVICES:
                identity = f"lunaris-{what}"
                command = ["run", what, *rover_args, "--state-dir", STATE]
                if what == "bridge":
                    command += ["--bridge-config", bridge_config]
                extra = env = ""
            else:  # the console
                identity = "console"
                command = ["console", "--http", "0.0.0.0:8080", "--accounts",
                           "/etc/lunaris/console-accounts.json", "--scenarios", "config/scenarios",
                           "--recordings", f"{STATE}/recordings", *rover_args]
                extra = ("    ports:\n      - \"${LUNARIS_CONSOLE_BIND:-127.0.0.1}:8080:8080\"\n")
                # the names a browser reaches it by: its machine's (the site's), or the variable's
                env = (f"      LUNARIS_ALLOW_HOST: "
                       f"\"${{LUNARIS_ALLOW_HOST:-{','.join(_names(spec.hosts))}}}\"\n")
            out.append(f"""
  {name}-{what}:
    <<: *lunaris
    {profile}
    restart: unless-stopped
    depends_on:
      {name}-preflight:
        condition: service_completed_successfully
      {name}-router:
        condition: service_started
    environment:
      LUNARIS_ZENOH_CONFIG: /etc/lunaris/zenoh.json5
{env}    command: {_list(command, len("    command: "))}
{extra}    volumes:
      - ./config:{APP}/config:ro
      - {folder}/client-{identity}.json5:/etc/lunaris/zenoh.json5:ro
""")
            if what == "console":
                out.append(f"      - {folder}/console-accounts.json:/etc/lunaris/console-accounts.json:ro\n")
            out.append(f"      - {name}-state:{STATE}\n")
        if "dashboard" in spec.people:
            for rid in files:
                out.append(f"""
  # A dashboard on DDS on this machine: {rid}'s topics in its DDS domain (host networking; it
  # reaches the router on the host's published port).
  {name}-zenoh-bridge-ros2dds-{rid}:
    image: eclipse/zenoh-bridge-ros2dds:${{ZENOH_VERSION:-1.10.2}}
    {profile}
    restart: unless-stopped
    depends_on:
      - {name}-router
    network_mode: host
    command: ["-c", "/etc/zenoh/zenoh-bridge-ros2dds.json5"]
    volumes:
      - {folder}/zenoh-bridge-ros2dds-{rid}.json5:/etc/zenoh/zenoh-bridge-ros2dds.json5:ro
""")
        out.append("\n")
    out.append("volumes:\n" + "".join(f"  {spec.name}-state:\n" for spec in site.routers if spec.runs))
    return "".join(out)


def write_site_compose(site: Site, output: Path, check: bool = False,
                       secrets: str = "deploy/secrets") -> bool:
    """Write (or with ``check`` compare) the compose file of ``site``; whether it was up to
    date. The site file and the secrets are named relative to the compose file's folder (the
    repository: the paths in a compose file are its folder's)."""
    base = output.resolve().parent
    site_path = Path(site.source).resolve()
    try:
        rel = site_path.relative_to(base).as_posix()
    except ValueError:
        raise ValueError(f"the site file {site.source} is not in {base}, the compose file's "
                         "folder (the repository the images are built from)") from None
    text = render_site_compose(site, rel, secrets)
    current = output.is_file() and output.read_text() == text
    if not check and not current:
        output.write_text(text)
    return current
