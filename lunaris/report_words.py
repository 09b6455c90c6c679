"""The debrief in plain words (``lunaris report``): what the twin records - keys, kinds, JSON
parameters, ``name=value`` pairs, scenario conditions - said as an instructor or a trainee
without a technical background reads it.

A fault is named by the catalogue's words (:data:`common.faults.CATALOGUE`: each kind's plain
``name``, each parameter's label and unit): ``fault/solar/left/dust {"fraction": 0.6}`` is
"Solar panel left: Dust (dust cover 60 %)". An alarm of the rover's own is its part and its
name in words ("Rail 5V_CH2: tripped"), a condition of a scenario a sentence ("rail 5V_CH2 is
off"). The console's page says the same things the same way (``static/format.js``); the few
field labels the report needs are kept here in :data:`FIELD_WORDS`.
"""

from __future__ import annotations

import json
import re
from typing import Any

from common.faults import CATALOGUE, parameters

__all__ = ["FIELD_WORDS", "KIND_WORDS", "condition_words", "event_words", "fault_words", "key_words",
           "params_words", "part_name", "plain"]

# A field: (label, unit, scale). The same names as format.js's FIELD_WORDS.
FIELD_WORDS: dict[str, tuple[str, str, float]] = {
    "soc": ("charge", "%", 100.0), "voltage_v": ("voltage", "V", 1.0), "current_a": ("current", "A", 1.0),
    "current_limit_a": ("current limit", "A", 1.0), "power_w": ("power", "W", 1.0),
    "max_w": ("highest allowed power", "W", 1.0), "heat_w": ("extra heat", "W", 1.0),
    "temperature_c": ("temperature", "°C", 1.0), "capacity_j": ("capacity", "kJ", 0.001),
    "energy_j": ("stored energy", "kJ", 0.001), "generation_w": ("generation", "W", 1.0),
    "load_power_w": ("loads", "W", 1.0), "in_range": ("in range", "", 1.0),
    "time_scale": ("speed of the clock", "×", 1.0), "t_s": ("sim time", "s", 1.0),
    "depleted_soc": ("empty charge", "%", 100.0), "cutoff_c": ("cut-off temperature", "°C", 1.0),
    "max_c": ("alarm temperature", "°C", 1.0), "min_c": ("lowest temperature", "°C", 1.0),
    "max_discharge_a": ("highest discharge current", "A", 1.0),
    "shed_below_soc": ("shed below a charge of", "%", 100.0),
    "restore_above_soc": ("restored above a charge of", "%", 100.0),
}

# An event's kind, as the console's event log says it (widgets.js KIND).
KIND_WORDS = {"rejected": "refused", "fault_injected": "fault injected", "fault_cleared": "fault cleared",
              "fault_raised": "alarm", "fault_resolved": "alarm ended", "command": "command",
              "input": "input", "clock": "clock", "session": "session", "scenario": "drill",
              "internal_error": "twin error", "mark": "your mark", "state_damaged": "state damaged",
              "journal_gap": "gap in the journal"}

PART_WORDS = {"battery": "Battery", "load": "Load", "rail": "Rail", "solar": "Solar panel",
              "umbilical": "Umbilical", "radio": "Radio", "drive": "Drive", "clock": "Clock"}

# The rover's own alarms (common.faults.DERIVED), in words.
ALARM_WORDS = {"thermal_cutoff": "switched off: too hot", "no_output": "gives no power",
               "depleted": "empty", "brownout": "cannot deliver the demand",
               "over_current": "drawing too much current", "under_voltage": "voltage too low",
               "under_voltage_cutoff": "switched off: voltage too low",
               "over_temperature": "too hot", "under_temperature": "too cold",
               "tripped": "tripped (switched itself off: too much current)",
               "shed": "shed (switched off to save the battery)", "unpowered": "without power"}

_COMPARE = {"<=": "at most", ">=": "at least", "<": "below", ">": "above", "==": "is", "!=": "is not"}


def words(s: str) -> str:
    return str(s).replace("_", " ")


def _number(v: float) -> str:
    return f"{v:,.0f}" if float(v).is_integer() else f"{float(f'{v:.3g}'):g}"


def part_name(component: str) -> str:
    """``solar/left`` -> "Solar panel left"; ``load/nav_camera`` -> "Load nav camera" (a rail
    keeps its name: the crew's dashboard says 5V_CH2)."""
    family, _, name = component.partition("/")
    head = PART_WORDS.get(family, words(family).capitalize())
    return f"{head} {name if family == 'rail' else words(name)}".strip()


def fault_words(component: str, kind: str) -> tuple[str, str]:
    """A fault kind's plain name and effect from the catalogue ("Dust", "the panel's output drops
    by the share the dust covers"); the kind in words when the catalogue has no such kind."""
    spec = CATALOGUE.get(component.split("/")[0], {}).get(kind)
    return (spec.name, spec.effect) if spec is not None else (words(kind).capitalize(), "")


def _value(v: Any, label: str, unit: str, scale: float = 1.0) -> str:
    if isinstance(v, bool):
        return f"{label}: {'yes' if v else 'no'}"
    if not isinstance(v, int | float):
        return f"{label} {words(str(v))}"
    if unit == "fraction":
        return f"{label} {_number(v * 100)} %"
    if unit == "×":
        return f"{label.removesuffix(' times')} ×{_number(v)}"
    return f"{label} {_number(v * scale)}{' ' + unit if unit else ''}"


def params_words(component: str, kind: str, params: dict | None) -> str:
    """A fault's parameters as they read: "dust cover 60 %", "extra heat 45 W"."""
    spec = CATALOGUE.get(component.split("/")[0], {}).get(kind)
    known = {p.name: p for p in parameters(spec.params)} if spec is not None else {}
    out = []
    for name, v in (params or {}).items():
        p = known.get(name)
        if p is not None and p.label:
            out.append(_value(v, p.label.lower(), p.unit))
        else:
            label, unit, scale = FIELD_WORDS.get(name, (words(name), "", 1.0))
            out.append(_value(v, label, unit, scale))
    return ", ".join(out)


def _fault_path(key: str) -> tuple[str, str] | None:
    """(component, kind) of a fault's key (``lunaris/<rover>/fault/solar/left/dust``) or path."""
    tail = re.sub(r"^lunaris/[^/]+/", "", key)
    if not tail.startswith("fault/"):
        return None
    bits = tail.removeprefix("fault/").split("/")
    return "/".join(bits[:-1]), bits[-1]


def key_words(key: str) -> str:
    """What a key names: a fault ("Solar panel left: Dust"), an alarm of the rover's own
    ("Rail 5V_CH2: tripped (...)"), a command's target ("rail 12V"), else its tail in words."""
    tail = re.sub(r"^lunaris/[^/]+/", "", key)
    fault = _fault_path(key)
    if fault is not None:
        component, kind = fault
        return f"{part_name(component)}: {fault_words(component, kind)[0]}"
    bits = tail.split("/")
    if len(bits) >= 2 and bits[-1] in ALARM_WORDS:
        return f"{part_name('/'.join(bits[:-1]))}: {ALARM_WORDS[bits[-1]]}"
    if bits[:2] == ["cmd", "rail"] and len(bits) == 3:
        return f"rail {bits[2]}"
    return words(tail)


def plain(message: str, key: str = "") -> str:
    """A message of the twin's with what a person would not read said again plainly: JSON
    objects as labelled values, ``name=value`` as words, field names as labels; the twin's own
    words kept."""
    fault = _fault_path(key)

    def obj(m: re.Match) -> str:
        try:
            value = json.loads(m.group(0))
        except ValueError:
            return m.group(0)
        if not isinstance(value, dict):
            return m.group(0)
        said = (params_words(*fault, value) if fault is not None
                else ", ".join(_value(v, *FIELD_WORDS.get(k, (words(k), "", 1.0))) for k, v in value.items()))
        return f"({said})" if said else ""

    out = re.sub(r"\{[^{}]*\}", obj, message)

    def pair(m: re.Match) -> str:
        name, v = m.group(1), m.group(2)
        if name == "on":
            return "switch on" if v == "true" else "switch off"
        if name == "reset":
            return "reset" if v == "true" else ""
        if name not in FIELD_WORDS:
            return m.group(0)
        label, unit, scale = FIELD_WORDS[name]
        return _value(v == "true" if v in ("true", "false") else float(v), label, unit, scale)

    out = re.sub(r"\b([a-z][a-z0-9]*(?:_[a-z0-9]+)*)=(true|false|-?[\d.]+)\b", pair, out)
    # a part by its path (load/nav_camera power) as it is named: "load nav camera power"
    out = re.sub(r"\b(load|solar|radio|rail)/([\w.-]+)(?!/)\b", lambda m: part_name(m.group(0)).lower()
                 if m.group(1) != "rail" else f"rail {m.group(2)}", out)
    out = re.sub(r"\b(load|panel|radio) ([a-z0-9]+(?:_[a-z0-9]+)+)\b", lambda m: words(m.group(0)), out)
    out = re.sub(r"\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b",
                 lambda m: FIELD_WORDS[m.group(0)][0] if m.group(0) in FIELD_WORDS else m.group(0), out)
    if fault is not None:  # "injected solar/left/dust" -> its name
        component, kind = fault
        path = f"{component}/{kind}"
        out = out.replace(path, key_words(key))
    return re.sub(r" {2,}", " ", out).replace(" ;", ";").replace(", ;", ";").strip(" ,")


def event_words(e: dict) -> str:
    """What an event says, in words, without repeating its kind."""
    kind, key, message = e.get("kind", ""), e.get("key", ""), str(e.get("message", ""))
    given = e.get("params")
    params: dict = given if isinstance(given, dict) else {}
    if kind == "mark":
        return message.removeprefix("mark: ")
    if kind in ("fault_injected", "fault_cleared"):
        fault = _fault_path(key)
        if fault is not None:
            values = params_words(*fault, params) if kind == "fault_injected" else ""
            return key_words(key) + (f" ({values})" if values else "")
    if kind in ("fault_raised", "fault_resolved"):
        said = "" if kind == "fault_resolved" or message in ("", kind) else f": {plain(message, key)}"
        return key_words(key) + said
    if kind == "session":
        trainee = params.get("trainee")
        whose = f"{trainee}'s session" if trainee else "The session (no trainee named)"
        if "end_t_s" in params:
            return f"{whose} ended"
        if trainee is not None:
            return f"{whose} began"
    if kind == "rejected":
        return plain(message.removeprefix("rejected: "), key)
    return plain(message, key)


_SOURCES = {"battery": "the battery's", "summary": "the rover's", "clock": "the clock's",
            "umbilical": "the umbilical's", "drive": "the rover's"}


def _comparison(source: str, name: str, field: str, op: str, raw: str) -> str:
    yes = (raw == "true") == (op == "==")
    if raw in ("true", "false"):
        if field == "in_range":
            return f"radio {name} is {'in range' if yes else 'out of range'}"
        if field == "on":
            return f"load {words(name)} is {'on' if yes else 'off'}"
        if field == "connected":
            return f"the umbilical is {'plugged in' if yes else 'unplugged'}"
        if field == "paused":
            return f"the clock is {'paused' if yes else 'running'}"
    if field == "state" and source == "rail":
        return f"rail {name} is {'not ' if op == '!=' else ''}{words(raw)}"
    who = _SOURCES.get(source, f"{PART_WORDS.get(source, source).lower()} {words(name)}")
    label, unit, scale = FIELD_WORDS.get(field, (words(field), "", 1.0))
    try:
        value = _value(float(raw), "", unit, scale).strip()
    except ValueError:
        value = words(raw)
    return f"{who} {label} {_COMPARE.get(op, op)} {value}"


def condition_words(text: str) -> str:
    """A scenario's condition (``rail.5V_CH2.state == off and battery.soc < 0.3``) in words:
    "rail 5V_CH2 is off and the battery's charge below 30 %"; in words as it is when it does
    not read as one."""
    said = []
    for part in re.split(r"\s+and\s+", text.strip()):
        m = re.fullmatch(r"\s*([A-Za-z][\w.-]*)\s*(<=|>=|==|!=|<|>)\s*(\S+)\s*", part)
        if m is None:
            return words(text)
        source, *rest = m.group(1).split(".")
        if not rest:
            return words(text)
        said.append(_comparison(source, ".".join(rest[:-1]), rest[-1], m.group(2), m.group(3)))
    return " and ".join(said)
