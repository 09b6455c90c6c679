"""A mapping expanded over the rovers a bridge serves: one binding per rover and component.

:func:`expand` turns each mapping into one :class:`Binding` per rover and per component
(``{load}``, ``{rail}``, ``{radio}``, ``{panel}`` placeholders run over the rover's
components; a command on ``{rail}`` over the rails that can be switched, not the solar rail),
checking the resulting ROS 2 names and that no two bindings share a topic in
one ROS 2 domain. A key of the drive (``drive/state``) has no binding for a rover that does
not drive, as a ``{radio}`` mapping has none for a rover without radios; a key that names a
component the rover lacks follows the mapping's ``otherwise`` (``first``: the rover's first
one of that kind, so the default mapping's ``lander`` radio works for any rover).

The *fleet* is every rover of the deployment, in order, whichever bridge process serves
which of them: each rover has its own ROS 2 domain (the flavour's ``domain_id`` plus its place
in the fleet, unless ``rover_domains`` names it), so every rover's dashboard sees the plain
topic names. :func:`zenoh_key` gives a binding's key in each Zenoh flavour.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import NamedTuple

from common import keys
from common.config import Rover
from common.datafile import ConfigError
from services.bridge.mapping import PLACEHOLDERS, ROS_TOPIC, BridgeOptions, Mapping, MappingFile, ros_name
from services.bridge.rmw_zenoh import rmw_topic_key

__all__ = ["Binding", "RoverNames", "domain_of", "expand", "open_keyexpr", "rover_names", "zenoh_key"]


class RoverNames(NamedTuple):
    """The component names a mapping's placeholders run over."""

    id: str
    load: tuple[str, ...] = ()
    rail: tuple[str, ...] = ()
    radio: tuple[str, ...] = ()
    panel: tuple[str, ...] = ()
    drives: bool = False  # the rover has a drive section
    solar_rail: str = ""  # the rail of the panels: in the PDM, but never switched


def rover_names(rover: Rover) -> RoverNames:
    """Components of a rover definition; the solar rail is a rail of the PDM too."""
    return RoverNames(
        rover.id,
        load=tuple(x.name for x in rover.loads),
        rail=tuple([x.name for x in rover.rails] + [rover.solar.rail.name]),
        radio=tuple(x.name for x in rover.radios),
        panel=tuple(x.name for x in rover.solar.panels),
        drives=rover.drive is not None,
        solar_rail=rover.solar.rail.name,
    )


class Binding(NamedTuple):
    """One mapping for one rover and one component: a concrete key and topic."""

    position: int  # the mapping's index in the file (a field named index would hide tuple.index)
    mapping: Mapping
    rover: str
    item: str | None  # the component ({load} ...) this binding is for
    key: str  # twin key
    topic: str  # absolute ROS 2 topic
    place: int = 0  # the rover's place in the fleet
    fleet: bool = False  # the fleet has several rovers

    @property
    def label(self) -> str:
        template = self.mapping.label or self.topic
        return _fill(template, self.rover, self.item, self.mapping.key, lambda v: v)


def _fill(template: str, rover: str, item: str | None, key_template: str, clean) -> str:
    found = keys.family_of_template(key_template)
    placeholder = found[0].placeholder if found else None
    out = template.replace("{rover}", clean(rover))
    if placeholder and item is not None:
        out = out.replace(f"{{{placeholder}}}", clean(item))
    return out


def domain_of(opts: BridgeOptions, base: int | None, rover: str, place: int) -> int:
    """The ROS 2 domain of a rover: ``rover_domains`` names it, else ``base`` + its place."""
    return opts.rover_domains.get(rover, (base or 0) + place)


def zenoh_key(b: Binding, opts: BridgeOptions, flavour: str) -> str:
    """The Zenoh key of a binding in a keyed flavour: ``ros2dds`` the topic without its
    leading ``/``, ``json`` the same after the prefix, both after the rover's namespace in
    a fleet; ``rmw_zenoh`` the key of the rover's domain with the type and its hash."""
    bare = b.topic.strip("/")
    if flavour == "rmw_zenoh":
        domain = domain_of(opts, opts.outputs.rmw_zenoh.domain_id, b.rover, b.place)
        return rmw_topic_key(domain, b.topic, b.mapping.type, opts.ros_distro)
    if b.fleet:
        bare = f"{opts.fleet_namespace.replace('{rover}', ros_name(b.rover)).strip('/')}/{bare}"
    if flavour == "json":
        prefix = opts.outputs.json.prefix
        return f"{prefix}/{bare}" if prefix else bare
    return bare


def open_keyexpr(keyexprs: list[str]) -> str | None:
    """One key expression matching each of ``keyexprs`` (keys of as many chunks): a chunk in
    which they differ keeps what they all begin and end with around ``$*`` (``rail_$*`` for
    ``rail_12V`` and ``rail_5V_CH2``), or is ``*``. So one subscription hears an inbound topic
    of several rovers, and one queryable answers a service of every rail - within what the
    router's generated rules allow the bridge to declare (``pdm/rail_$*/set_enabled``, made
    by this same function from the mapping's templates: a plain ``*`` was refused). None when
    they do not have as many chunks."""
    split = [k.split("/") for k in keyexprs]
    if len({len(chunks) for chunks in split}) != 1:
        return None
    return "/".join(_open_chunk(list(col)) for col in zip(*split, strict=True))


def _open_chunk(values: list[str]) -> str:
    if len(set(values)) == 1:
        return values[0]
    if any("*" in v or "$" in v for v in values):
        return "*"  # already a wildcard: no sub-chunk form of two of them
    head = os.path.commonprefix(values)
    tail = os.path.commonprefix([v[len(head):][::-1] for v in values])[::-1]
    return f"{head}$*{tail}" if head or tail else "*"


def expand(mf: MappingFile, rovers: Iterable[RoverNames], source: str = "<mapping>",
           fleet: list[str] | None = None) -> list[Binding]:
    """Every binding of the mapping for these rovers, members of ``fleet`` (the ids of every
    rover of the deployment, in order; default: these rovers); raise :class:`ConfigError`
    naming each component a mapping names that a rover lacks, and each topic two bindings
    would share in one ROS 2 domain."""
    rovers = list(rovers)
    fleet = fleet if fleet is not None else [r.id for r in rovers]
    missing = [r.id for r in rovers if r.id not in fleet]
    if missing:
        raise ConfigError(source, [f"rover {', '.join(missing)} is not in the fleet"])
    several = len(fleet) > 1
    prefix = mf.bridge.fleet_topic_prefix if several else mf.bridge.topic_prefix
    problems: list[str] = []
    out: list[Binding] = []
    owner: dict[tuple[str, int, str], str] = {}
    for i, m in enumerate(mf.mappings):
        found = keys.family_of_template(m.key)
        assert found is not None, "parse_mapping checked the key"
        shape, item = found
        placeholder = shape.placeholder
        for rover in rovers:
            place = fleet.index(rover.id)
            if shape.owner == "drive" and not rover.drives:
                continue
            if placeholder not in PLACEHOLDERS:  # none, or every owner's (faults/active/*)
                items: tuple[str | None, ...] = (None,)
            elif item is not None and item.startswith("{"):
                items = getattr(rover, placeholder)
                if shape.direction == "in" and placeholder == "rail":  # a command: not the solar rail
                    items = tuple(r for r in items if r != rover.solar_rail)
            else:
                have = getattr(rover, placeholder)
                if item in have:
                    items = (item,)
                elif m.otherwise == "first" and have:
                    items = (have[0],)
                elif m.otherwise == "error":
                    problems.append(f"mappings[{i}].key: rover {rover.id} has no {placeholder} "
                                    f"{item!r} ({placeholder}s: {', '.join(have) or 'none'})")
                    continue
                else:
                    continue  # skip, or first of none: no such topic for this rover
            for it in items:
                key = _fill(m.key.replace(f"/{item}/", "/{" + placeholder + "}/")
                            if it != item and placeholder else m.key, rover.id, it, m.key,
                            lambda v: v)
                topic = _fill(prefix + m.topic, rover.id, it, m.key, ros_name)
                if not ROS_TOPIC.match(topic):
                    problems.append(f"mappings[{i}].topic: {topic!r} (rover {rover.id}) is not a "
                                    "ROS 2 name: a token starts with a digit?")
                    continue
                where = f"mappings[{i}] for {rover.id}" + (f" {it}" if it else "")
                group = mf.bridge.rover_domains.get(rover.id, place)
                role = "service" if m.kind == "service" else m.direction
                first = owner.setdefault((role, group, topic), where)
                if first != where:
                    problems.append(f"mappings[{i}].topic: {topic} of {where} is also the topic "
                                    f"of {first} in the same ROS 2 domain")
                    continue
                out.append(Binding(i, m, rover.id, it, key, topic, place, several))
    if problems:
        raise ConfigError(source, problems)
    return out
