"""A mapping expanded over the rovers a bridge serves: one binding per rover and component.

:func:`expand` turns each mapping into one :class:`Binding` per rover and per component
(``{load}``, ``{rail}``, ``{radio}``, ``{panel}`` placeholders run over the rover's
components), checking the resulting ROS 2 names and that no two bindings share a topic. A
key of the drive (``drive/state``) has no binding for a rover that does not drive, as a
``{radio}`` mapping has none for a rover without radios.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from common import keys
from common.config import Rover
from common.datafile import ConfigError
from services.bridge.mapping import ROS_TOPIC, Mapping, MappingFile, ros_name

__all__ = ["Binding", "RoverNames", "expand", "rover_names"]


class RoverNames(NamedTuple):
    """The component names a mapping's placeholders run over."""

    id: str
    load: tuple[str, ...] = ()
    rail: tuple[str, ...] = ()
    radio: tuple[str, ...] = ()
    panel: tuple[str, ...] = ()
    drives: bool = False  # the rover has a drive section


def rover_names(rover: Rover) -> RoverNames:
    """Components of a rover definition; the solar rail is a rail of the PDM too."""
    return RoverNames(
        rover.id,
        load=tuple(x.name for x in rover.loads),
        rail=tuple([x.name for x in rover.rails] + [rover.solar.rail.name]),
        radio=tuple(x.name for x in rover.radios),
        panel=tuple(x.name for x in rover.solar.panels),
        drives=rover.drive is not None,
    )


class Binding(NamedTuple):
    """One mapping for one rover and one component: a concrete key and topic."""

    position: int  # the mapping's index in the file (a field named index would hide tuple.index)
    mapping: Mapping
    rover: str
    item: str | None  # the component ({load} ...) this binding is for
    key: str  # twin key
    topic: str  # absolute ROS 2 topic

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


def expand(mf: MappingFile, rovers: Iterable[RoverNames], source: str = "<mapping>") -> list[Binding]:
    """Every binding of the mapping for these rovers; raise :class:`ConfigError` naming each
    component a mapping names that a rover lacks, and each topic two bindings would share."""
    rovers = list(rovers)
    prefix = mf.bridge.topic_prefix if len(rovers) <= 1 else mf.bridge.fleet_topic_prefix
    problems: list[str] = []
    out: list[Binding] = []
    owner: dict[tuple[str, str], str] = {}
    for i, m in enumerate(mf.mappings):
        found = keys.family_of_template(m.key)
        assert found is not None, "parse_mapping checked the key"
        shape, item = found
        placeholder = shape.placeholder
        for rover in rovers:
            if shape.owner == "drive" and not rover.drives:
                continue
            if placeholder is None:
                items: tuple[str | None, ...] = (None,)
            elif item is not None and item.startswith("{"):
                items = getattr(rover, placeholder)
            else:
                have = getattr(rover, placeholder)
                if item not in have:
                    problems.append(f"mappings[{i}].key: rover {rover.id} has no {placeholder} "
                                    f"{item!r} ({placeholder}s: {', '.join(have) or 'none'})")
                    continue
                items = (item,)
            for it in items:
                key = _fill(m.key, rover.id, it, m.key, lambda v: v)
                topic = _fill(prefix + m.topic, rover.id, it, m.key, ros_name)
                if not ROS_TOPIC.match(topic):
                    problems.append(f"mappings[{i}].topic: {topic!r} (rover {rover.id}) is not a "
                                    "ROS 2 name: a token starts with a digit?")
                    continue
                where = f"mappings[{i}] for {rover.id}" + (f" {it}" if it else "")
                first = owner.setdefault((m.direction, topic), where)
                if first != where:
                    problems.append(f"mappings[{i}].topic: {topic} of {where} is also the topic "
                                    f"of {first}")
                    continue
                out.append(Binding(i, m, rover.id, it, key, topic))
    if problems:
        raise ConfigError(source, problems)
    return out
