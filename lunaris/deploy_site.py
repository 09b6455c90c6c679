"""A deployment's machines from one description (``deploy/site.yaml``, SPEC §12f).

A *site* names its routers (one per machine: a ground station, each rover's computer, the
crew's dashboard host), the names and addresses of each on its certificate, the links
between them (``connect``: the routers a router opens a link to) and what runs on each
machine: Lunaris services and the console (``runs``, each under its own identity) and the
people's tools that connect there (``people``). Every identity connects to the router of its
machine only; each router knows, checks and enforces its own clients, and knows the routers
it is linked with as routers (``router-<name>``), nothing more.

The one-router deployment of ``docker-compose.yml`` is the site :data:`DEFAULT_SITE`: one
router, ``router``, with everything on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import msgspec

from common.datafile import ConfigError, Name, Strict, doc, parse_yaml, read_text

__all__ = ["CLIENT_PORT", "DEFAULT_SITE", "IDENTITIES", "PEOPLE", "ROUTER_PORT", "SERVICES",
           "RouterSpec", "Site", "SiteError", "load_site", "router_identity", "site_label"]

REPO = Path(__file__).resolve().parent.parent  # in a container, its working directory

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
PEOPLE = {
    "instructor": "injects and clears faults, commands, inputs, time and sessions; reads all",
    "console": "the instructor console's own identity: what an instructor may do",
    "observer": "the crew's view: telemetry only (no fault puts, faults, journal or events)",
    "debrief": "reads everything an instructor reads, writes nothing (an explicit choice)",
    "dashboard": "the crew's dashboard: reads only the bridge's topics, writes its inbound ones",
}
IDENTITIES = tuple(f"lunaris-{s}" for s in SERVICES) + tuple(PEOPLE)
RUNNABLE = (*SERVICES, "console")  # what `runs:` may name: a process of this machine
CLIENT_PORT = 7447  # the clients' TLS listener (user and password)
ROUTER_PORT = 7448  # the other routers' listener (mutual TLS, and user and password)


Port = Annotated[int, msgspec.Meta(ge=1, le=65535)]


class SiteError(ConfigError):
    """A site description with problems."""


def router_identity(name: str) -> str:
    """The identity of a router: its user name, and its certificate's common name."""
    return f"router-{name}"


class RouterFile(Strict, frozen=True):
    name: Annotated[Name, doc("the router's name: its identity is router-<name>")]
    hosts: Annotated[list[str], doc("names and addresses of its machine, on its certificate; "
                                    "clients and other routers reach it by the first")]
    connect: Annotated[list[Name], doc("the routers this one opens a link to")] = []
    runs: Annotated[list[str], doc("Lunaris services and the console running on this machine, "
                                   "each under its own identity")] = []
    people: Annotated[list[str], doc("identities of people's tools connecting here: "
                                     "instructor, observer, debrief, dashboard")] = []
    rovers: Annotated[list[str] | None, doc("ids of the rovers this machine's services serve "
                                            "(default: every rover of the site)")] = None
    client_port: Annotated[Port | None, doc("its clients' port (default: the site's)")] = None
    router_port: Annotated[Port | None, doc("the other routers' port (default: the site's)")] = None


class SiteFile(Strict, frozen=True):
    rovers: Annotated[list[str], doc("the deployment's rover files, in order (rover i has "
                                     "ROS 2 domain i); relative to the repository, the "
                                     "image's working directory")]
    routers: Annotated[list[RouterFile], doc("one per machine")]
    bridge_config: Annotated[str | None, doc("bridge mapping (default: the shipped one)")] = None
    client_port: Annotated[Port, doc("the clients' port of every router (TLS, user and "
                                     "password)")] = CLIENT_PORT
    router_port: Annotated[Port, doc("the routers' port of every router (mutual TLS)")] = ROUTER_PORT


@dataclass(frozen=True)
class RouterSpec:
    name: str
    hosts: tuple[str, ...]
    connect: tuple[str, ...]
    runs: tuple[str, ...]
    people: tuple[str, ...]
    rovers: tuple[str, ...] | None
    client_port: int = CLIENT_PORT
    router_port: int = ROUTER_PORT

    @property
    def identity(self) -> str:
        return router_identity(self.name)

    @property
    def clients(self) -> tuple[str, ...]:
        """The identities that connect to this router, in the order of :data:`IDENTITIES`."""
        mine = {f"lunaris-{r}" if r in SERVICES else r for r in self.runs} | set(self.people)
        return tuple(i for i in IDENTITIES if i in mine)


@dataclass(frozen=True)
class Site:
    rovers: tuple[str, ...]  # rover files, the fleet's order
    routers: tuple[RouterSpec, ...]
    bridge_config: str | None = None
    source: str = "<default>"  # as it was given: for words to the user
    label: str = "<default>"  # as the generated files name it (:func:`site_label`)

    @property
    def single(self) -> bool:
        """One router and no link: the flat layout of docker-compose.yml."""
        return len(self.routers) == 1

    def router(self, name: str) -> RouterSpec:
        return next(r for r in self.routers if r.name == name)

    def linked_from(self, name: str) -> tuple[str, ...]:
        """The routers that open a link to ``name``."""
        return tuple(r.name for r in self.routers if name in r.connect)

    def neighbours(self, name: str) -> tuple[str, ...]:
        return tuple(dict.fromkeys((*self.router(name).connect, *self.linked_from(name))))

    @property
    def identities(self) -> tuple[str, ...]:
        """Every identity of the site: its clients', then its routers'."""
        clients = {i for r in self.routers for i in r.clients}
        return tuple(i for i in IDENTITIES if i in clients) + tuple(r.identity for r in self.routers)

    def routers_of(self, identity: str) -> tuple[str, ...]:
        """The routers whose dictionary holds ``identity``: where it connects, or (a
        router's) those it opens links to."""
        out = [r.name for r in self.routers if identity in r.clients]
        out += [n for r in self.routers if r.identity == identity for n in r.connect]
        return tuple(out)


DEFAULT_SITE = Site(
    rovers=("config/rovers/mapp.yaml", "config/rovers/ltv.yaml"),
    routers=(RouterSpec("router", ("router", "localhost", "127.0.0.1"), (), RUNNABLE,
                        tuple(p for p in PEOPLE if p != "console"), None),),
)


def site_label(path: str | Path) -> str:
    """How the generated files name a site file, whichever way its path was typed
    (``deploy/site.yaml``, ``./deploy/site.yaml``, its absolute path): relative to the
    repository when it is in it (as in the image, whose working directory is the repository),
    otherwise its name in its own folder."""
    resolved = Path(path).resolve()
    try:
        return resolved.relative_to(REPO).as_posix()
    except ValueError:
        return resolved.name


def load_site(path: str | Path) -> Site:
    """Read and check a site description; :class:`SiteError` lists every problem."""
    source = str(path)
    data, problems = parse_yaml(read_text(path, SiteError), source, SiteFile, SiteError)
    if problems:
        raise SiteError(source, problems)
    f = msgspec.convert(data, SiteFile)
    names = [r.name for r in f.routers]
    if not f.routers:
        problems.append("routers: a site has at least one router")
    for name in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"routers: {name!r} is named more than once")
    placed: dict[str, list[str]] = {}
    for i, r in enumerate(f.routers):
        where = f"routers[{i}] ({r.name})"
        if not r.hosts:
            problems.append(f"{where}.hosts: at least one name or address of its machine")
        for target in r.connect:
            if target not in names:
                problems.append(f"{where}.connect: no router is named {target!r} "
                                f"(routers: {', '.join(names)})")
            elif target == r.name:
                problems.append(f"{where}.connect: a router does not link to itself")
        for other in f.routers:
            if other.name in r.connect and r.name in other.connect and r.name < other.name:
                problems.append(f"{where}.connect: {r.name} and {other.name} both open the "
                                "link between them: name it on one side only")
        for what in sorted({w for w in r.runs if r.runs.count(w) > 1}):
            problems.append(f"{where}.runs: {what!r} is named more than once")
        for what in dict.fromkeys(r.runs):
            if what not in RUNNABLE:
                problems.append(f"{where}.runs: {what!r} is not a Lunaris service or the console "
                                f"({', '.join(RUNNABLE)})")
            placed.setdefault(what, []).append(r.name)
        for who in r.people:
            if who not in PEOPLE or who == "console":
                problems.append(f"{where}.people: {who!r} is not a person's identity "
                                f"({', '.join(p for p in PEOPLE if p != 'console')})")
    for what in RUNNABLE:
        if what not in placed and what != "console":
            problems.append(f"routers: no machine runs the {what} service")
    for what in ("faults", "console"):
        if len(placed.get(what, [])) > 1:
            problems.append(f"routers: the {what} runs on one machine only "
                            f"(not {', '.join(placed[what])})")
    if f.routers and not _connected(f):
        problems.append("routers: every router must be reached through the links "
                        "(connect) from every other")
    if problems:
        raise SiteError(source, problems)
    return Site(
        rovers=tuple(f.rovers), bridge_config=f.bridge_config, source=source,
        label=site_label(path),
        routers=tuple(RouterSpec(r.name, tuple(r.hosts), tuple(r.connect), tuple(r.runs),
                                 tuple(r.people), None if r.rovers is None else tuple(r.rovers),
                                 r.client_port or f.client_port, r.router_port or f.router_port)
                      for r in f.routers))


def _connected(f: SiteFile) -> bool:
    names = {r.name for r in f.routers}
    links = {r.name: {t for t in r.connect if t in names and t != r.name} for r in f.routers}
    for r in f.routers:
        for target in r.connect:
            if target in links:
                links[target].add(r.name)
    seen, todo = set(), [f.routers[0].name]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo += links[name] - seen
    return seen == set(links)
