"""The machinery every Lunaris data file shares: rover definitions, bridge mappings, scenarios.

A data file is YAML checked against a msgspec Struct. :func:`parse_yaml` reads it with
YAML 1.2 scalars and :func:`check_structure` walks the Struct's annotations (types,
ranges, name patterns, unknown and missing fields), so every problem is reported at once
with its path (``battery.ocv_curve.volts[3]: must be >= 0.0, got -1``). Each file format
adds its own cross-field rules on top and raises :class:`ConfigError` listing them all.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Hashable
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec
import msgspec.inspect as mi
import yaml

__all__ = [
    "ID_PATTERN",
    "ConfigError",
    "Efficiency",
    "Fraction",
    "Id",
    "Name",
    "NonNegative",
    "Positive",
    "Strict",
    "YamlLoader",
    "check_structure",
    "doc",
    "load_yaml",
    "field_kind",
    "parse_yaml",
    "read_text",
    "struct_fields",
]

# A name becomes a chunk of a key expression: no '/', wildcards or spaces.
NAME_PATTERN = r"^[A-Za-z0-9_.-]+$"
# An id (a rover's) is the first chunk after lunaris/: lower case, no dots.
ID_PATTERN = r"^[a-z0-9][a-z0-9_-]*$"

Name = Annotated[str, msgspec.Meta(pattern=NAME_PATTERN)]
Id = Annotated[str, msgspec.Meta(pattern=ID_PATTERN)]
Fraction = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Positive = Annotated[float, msgspec.Meta(gt=0.0)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]
Efficiency = Annotated[float, msgspec.Meta(gt=0.0, le=1.0)]

_PATTERN_WORDS = {
    NAME_PATTERN: "letters, digits, '_', '-' and '.'",
    ID_PATTERN: "lower-case letters, digits, '_' and '-', starting with a letter or digit",
}


def doc(text: str) -> msgspec.Meta:
    """A field's description, for the generated reference (``docs/reference``):
    ``capacity_j: Annotated[Positive, doc("usable energy when full [J]")]``."""
    return msgspec.Meta(description=text)


class Strict(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """Base of every data-file Struct: an unknown field is a problem, values never change."""


class ConfigError(ValueError):
    """A data file with problems; ``problems`` lists every one of them. Given the file's
    ``data``, a list item with a name is named in each problem's path (``rails[1]
    (5V_CH1).efficiency: ...``): a reader finds it by name, not by counting."""

    def __init__(self, source: str, problems: list[str], data: Any = None):
        self.source = source
        self.problems = problems = [name_items(p, data) for p in problems] if data else problems
        lines = "\n".join(f"  {p}" for p in problems)
        super().__init__(f"{source}: {len(problems)} problem(s)\n{lines}")


_PART = re.compile(r"([^\[\]]+)((?:\[\d+\])*)")


def name_items(problem: str, data: Any) -> str:
    """``problem`` (``path: words``) with the name of every list item on its path that has
    one in ``data``: ``loads[4].rail`` -> ``loads[4] (hazard_cameras).rail``."""
    path, sep, words = problem.partition(": ")
    if not sep or " " in path:
        return problem
    node, named = data, []
    for part in path.split("."):
        m = _PART.fullmatch(part)
        if m is None:
            return problem
        key, indices = m.groups()
        node = node.get(key) if isinstance(node, dict) else None
        text = key
        for i in map(int, re.findall(r"\d+", indices)):
            node = node[i] if isinstance(node, list) and i < len(node) else None
            name = node.get("name") if isinstance(node, dict) else None
            text += f"[{i}]" + (f" ({name})" if isinstance(name, str) and name else "")
        named.append(text)
    return ".".join(named) + sep + words


def read_text(path: str | Path, error: type[ConfigError] = ConfigError) -> str:
    """A data file's text; an unreadable file is a problem like any other."""
    try:
        return Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise error(str(path), [f"cannot read file: {reason}"]) from None


def struct_fields(struct: type[msgspec.Struct]) -> tuple[mi.Field, ...]:
    """The fields of a Struct class as :mod:`msgspec.inspect` describes them."""
    info = mi.type_info(struct)
    assert isinstance(info, mi.StructType)  # type_info is typed as any Type; a Struct's is this
    return info.fields


# libyaml's parser where PyYAML has it (its wheels do): a rover file parsed in ~1/5 of the
# time, paid by every service and tool as it starts; the scalars are resolved below either way.
_SafeLoader: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YamlLoader(_SafeLoader):  # type: ignore[valid-type,misc]
    """SafeLoader with YAML 1.2 scalars: ``5.3e5`` is a number (YAML 1.1 makes it a string)
    and only ``true``/``false`` are booleans (YAML 1.1 also reads ``on``, ``off``, ``yes``,
    ``no`` as booleans, which would turn a key ``on:`` into ``True:``). A key given twice in
    one mapping is refused: YAML keeps the last without a word (a second ``tick_hz: 0.5``
    below the first went unseen)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            line = key_node.start_mark.line + 1
            if isinstance(key, Hashable) and key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"{key!r} is given twice in one mapping (lines {seen[key]} and {line}): "
                    "YAML would keep the last without a word", key_node.start_mark)
            if isinstance(key, Hashable):
                seen[key] = line
        return super().construct_mapping(node, deep=deep)


_BOOL = "tag:yaml.org,2002:bool"
YamlLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != _BOOL]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
YamlLoader.add_implicit_resolver(_BOOL, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                                 list("tTfF"))
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(text: str, source: str, error: type[ConfigError] = ConfigError) -> Any:
    """YAML text with Lunaris scalars; invalid YAML raises ``error`` naming the problem."""
    try:
        return yaml.load(text, Loader=YamlLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:  # the file by its name, not "<unicode string>"
        said = str(exc).replace('"<unicode string>"', source)
        raise error(source, [f"not valid YAML: {said}"]) from None


def parse_yaml(text: str, source: str, struct: type[msgspec.Struct],
               error: type[ConfigError] = ConfigError) -> tuple[Any, list[str]]:
    """Parse a data file and check it against ``struct``: the data and every structural
    problem found. Invalid YAML raises ``error``."""
    data = load_yaml(text, source, error)
    problems: list[str] = []
    check_structure(data, struct, problems)
    return data, problems


# -- structural validation, driven by the Struct annotations -------------------------------


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a mapping"}.get(type(value), type(value).__name__)


def _check_bounds(value: float, t: Any, path: str, problems: list[str]) -> None:
    where = path or "value"
    if t.ge is not None and value < t.ge:
        problems.append(f"{where}: must be >= {t.ge}, got {value}")
    if t.gt is not None and value <= t.gt:
        problems.append(f"{where}: must be > {t.gt}, got {value}")
    if t.le is not None and value > t.le:
        problems.append(f"{where}: must be <= {t.le}, got {value}")
    if t.lt is not None and value >= t.lt:
        problems.append(f"{where}: must be < {t.lt}, got {value}")


def check_structure(data: Any, struct: type[msgspec.Struct], problems: list[str]) -> None:
    """Check parsed YAML against a Struct's annotations (types, ranges, name patterns,
    unknown and missing fields), appending every problem with its path to ``problems``."""
    _check(data, mi.type_info(struct), "", problems)


def _check(value: Any, t: Any, path: str, problems: list[str]) -> None:
    where = path or "file"
    if isinstance(t, mi.Metadata):  # a field with a description
        _check(value, t.type, path, problems)
    elif isinstance(t, mi.UnionType):
        if value is None and any(isinstance(m, mi.NoneType) for m in t.types):
            return
        members = [m for m in t.types if not isinstance(m, mi.NoneType)]
        # A mapping is checked against the mapping member, anything else against the first other.
        mapping = [m for m in members if isinstance(m, mi.StructType | mi.DictType)]
        others = [m for m in members if m not in mapping] or members
        _check(value, (mapping or others)[0] if isinstance(value, dict) else others[0], path, problems)
    elif isinstance(t, mi.StructType):
        _check_struct(value, t, path, problems)
    elif isinstance(t, mi.ListType):
        if not isinstance(value, list):
            problems.append(f"{where}: expected a list, got {_kind(value)}")
            return
        for i, item in enumerate(value):
            _check(item, t.item_type, f"{path}[{i}]", problems)
    elif isinstance(t, mi.DictType):
        if not isinstance(value, dict):
            problems.append(f"{where}: expected a mapping, got {_kind(value)}")
            return
        for k, v in value.items():
            _check(k, t.key_type, _join(path, str(k)), problems)
            _check(v, t.value_type, _join(path, str(k)), problems)
    elif isinstance(t, mi.FloatType | mi.IntType):
        _check_number(value, t, path, problems)
    elif isinstance(t, mi.StrType):
        if isinstance(value, bool):  # a file edited with a YAML 1.1 tool: on, off, yes, no
            problems.append(f"{where}: a boolean where a name was expected: quote it (\"on\", not "
                            "on: a YAML 1.1 tool such as PyYAML reads on, off, yes and no as true "
                            "and false, and writes them back so)")
        elif not isinstance(value, str):
            problems.append(f"{where}: expected a string, got {_kind(value)}")
        elif t.pattern is not None and re.search(t.pattern, value) is None:
            words = _PATTERN_WORDS.get(t.pattern, f"matching {t.pattern}")
            problems.append(f"{where}: {value!r} is not a valid name ({words})")
    elif isinstance(t, mi.BoolType):
        if not isinstance(value, bool):
            problems.append(f"{where}: expected true or false, got {_kind(value)}")
    elif isinstance(t, mi.LiteralType):
        if value not in t.values:
            choices = ", ".join(str(v) for v in t.values)
            problems.append(f"{where}: expected one of {choices}, got {value!r}")


def _check_struct(value: Any, t: Any, path: str, problems: list[str]) -> None:
    if not isinstance(value, dict):
        problems.append(f"{path or 'file'}: expected a mapping, got {_kind(value)}")
        return
    known = {f.encode_name for f in t.fields}
    missing = [f.encode_name for f in t.fields if f.required and f.encode_name not in value]
    for key in value:
        if key not in known:
            near = difflib.get_close_matches(str(key), missing or sorted(known), n=1, cutoff=0.75)
            problems.append(f"{_join(path, str(key))}: unknown field"
                            + (f" (did you mean {near[0]!r}?)" if near else ""))
    for f in t.fields:
        if f.encode_name in value:
            _check(value[f.encode_name], f.type, _join(path, f.encode_name), problems)
        elif f.required:
            problems.append(f"{_join(path, f.encode_name)}: missing required field")


def _check_number(value: Any, t: Any, path: str, problems: list[str]) -> None:
    where = path or "file"
    want_int = isinstance(t, mi.IntType)
    ok = isinstance(value, int) if want_int else isinstance(value, int | float)
    if isinstance(value, bool) or not ok:
        problems.append(f"{where}: expected {'an integer' if want_int else 'a number'}, "
                        f"got {_kind(value)}")
        return
    if not math.isfinite(value):
        problems.append(f"{where}: must be finite, got {value}")
        return
    _check_bounds(value, t, path, problems)


FieldKind = Literal["number", "bool", "word", "other"]


def field_kind(t: Any) -> tuple[FieldKind, tuple | None]:
    """What a payload field holds, for the tools that read fields by name (bridge mappings,
    scenario conditions): ``number``, ``bool``, ``word`` (with the allowed words of a
    Literal), or ``other``. ``float | None`` counts as a number."""
    if isinstance(t, mi.Metadata):
        return field_kind(t.type)
    if isinstance(t, mi.UnionType):
        members = [m for m in t.types if not isinstance(m, mi.NoneType)]
        return field_kind(members[0]) if len(members) == 1 else ("other", None)
    if isinstance(t, mi.FloatType | mi.IntType):
        return "number", None
    if isinstance(t, mi.BoolType):
        return "bool", None
    if isinstance(t, mi.LiteralType):
        return "word", tuple(t.values)
    if isinstance(t, mi.StrType):
        return "word", None
    return "other", None
