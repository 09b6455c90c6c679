"""What the crew sees (SPEC §12b): the rover's own alarms and silent telemetry, never which
fault an instructor injected.

The crew's ``/diagnostics`` in the ``symptoms`` view (the default; ``bridge.crew_view``) is
made only of what the rover's own sensors and protection would report:

- the twin's alarms, the *derived* faults of the owners' ``faults/active/<service>`` (an
  injected fault in the same record is never looked at), in the crew's words: a rail's
  ``tripped`` is an over-current trip, the pack's ``over_temperature`` an over-temperature;
  but not those the rover's own instruments cannot measure
  (:data:`common.symptoms.UNSEEN_ALARMS`): a load's
  ``over_current``. A PDM measures and protects its channels, the rails: a channel's trip is
  its rail's ERROR; the loads on a channel share its current, and none is singled out as the
  one that drew too much. (Found by an instructor: a short showed ``load/nav_camera ERROR
  over-current`` for the 13 ms between the camera's surge and its rail's trip, the answer to
  the drill's "find the load".)
- what the component's own telemetry shows: a rail with no output while switched on (its
  converter dead), a radio without a link;
- silence: a component whose telemetry stopped is STALE.

So a short shows as an over-current trip, heating as a rising temperature (the BatteryState)
and above ``max_c`` an over-temperature alarm, a radio failure as a lost link, dust as less
power from a panel; no status, message or value names an injected fault, its kind, its
parameters or the word "injected". The ``full`` view (:func:`~services.bridge.convert.
diagnostic_statuses`) lists every fault in effect, for integration work.

:func:`crew_view` renders, from the twin's values alone, what every crew topic of a rover
says (the console's "what the crew sees" view, without ROS): the same functions make the
bridge's messages.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cache
from typing import Any

from common import keys
from common.config import Rover
from common.messages import ActiveFault, ActiveFaults, RadioLink, RailState
from common.symptoms import UNSEEN_ALARMS
from services.bridge.bindings import RoverNames, expand, rover_names
from services.bridge.convert import (
    DIAG_ERROR,
    DIAG_OK,
    DIAG_STALE,
    DIAG_WARN,
    component_of_fault,
    components,
    data_key,
    diagnostic_statuses,
    level_name,
    topic_message,
)
from services.bridge.mapping import MappingFile, load_mapping, resolve_mapping

__all__ = ["READS", "SYMPTOMS", "crew_statuses", "crew_view", "seen", "symptom_of"]

# The twin's alarms (common.faults.DERIVED) as the crew's dashboard names them.
SYMPTOMS: dict[str, dict[str, str]] = {
    "battery": {
        "thermal_cutoff": "over-temperature cut-off: the pack switched itself off",
        "no_output": "no output: the pack supplies nothing",
        "depleted": "depleted",
        "under_voltage_cutoff": "under-voltage cut-off: the pack switched itself off",
        "brownout": "brown-out: demand beyond what the pack can deliver",
        "over_current": "over-current: discharge held at the pack's limit",
        "under_voltage": "under-voltage",
        "over_temperature": "over-temperature",
        "under_temperature": "under-temperature",
    },
    "rail": {"tripped": "over-current trip: off until reset", "shed": "load shed: low charge"},
    "radio": {"unpowered": "no power"},
}
_LEVEL = {"info": DIAG_OK, "warning": DIAG_WARN, "critical": DIAG_ERROR}
READS = (RailState, RadioLink)  # the telemetry the crew's view reads beside the alarms


def symptom_of(component: str, alarm: str) -> str:
    """An alarm of a component (``rail/12V``, ``tripped``) in the crew's words."""
    return SYMPTOMS.get(component.split("/", 1)[0], {}).get(alarm, alarm.replace("_", " "))


def seen(component: str, payload: Any) -> tuple[int, str, str] | None:
    """What a component's own telemetry shows beside its alarms: (level, words, value); None
    for nothing to say (and for a payload the crew's view does not read). A bridge republishes
    the rover's ``/diagnostics`` when this changes."""
    if isinstance(payload, RailState):
        if payload.state == "failed":
            return DIAG_ERROR, "no output (0 V) while switched on", "0 V"
        if payload.state == "off":
            return DIAG_OK, "switched off", payload.reason
        if payload.state == "tripped":  # the alarm says so too (its event may come first)
            return DIAG_ERROR, symptom_of(component, "tripped"), payload.reason
    if isinstance(payload, RadioLink) and not payload.in_range:
        return DIAG_WARN, "no link", "lost"
    return None


def crew_statuses(rover: str, component_names: list[str], active: list[ActiveFault],
                  telemetry: Mapping[str, Any], age_s: Mapping[str, float | None],
                  stale_after_s: float) -> list[dict]:
    """One ``DiagnosticStatus`` per component as the crew sees it (the ``symptoms`` view).

    ``active``: the faults in effect as the owners list them (only the derived ones are
    read); ``telemetry``: each component's latest payload (``rail/12V`` -> its RailState,
    ``radio/lander`` -> its RadioLink; others are not read); ``age_s``: how long each
    component's telemetry has been silent (None: never came). The level is the worst of the
    component's alarms (a critical one ERROR, a warning WARN), of what its telemetry shows,
    or STALE; each alarm is a ``KeyValue`` (its name -> the crew's words and since when)."""
    alarms: dict[str, list[ActiveFault]] = {}
    for f in active:
        if f.origin == "derived":
            comp, alarm = component_of_fault(f.key)
            if (comp.split("/", 1)[0], alarm) not in UNSEEN_ALARMS:
                alarms.setdefault(comp, []).append(f)
    statuses = []
    for comp in component_names:
        own = alarms.get(comp, [])
        level = max((_LEVEL.get(f.severity, DIAG_WARN) for f in own), default=DIAG_OK)
        words, values = [], []
        for f in own:
            name = component_of_fault(f.key)[1]
            words.append(symptom_of(comp, name))
            values.append({"key": name, "value": f"{symptom_of(comp, name)} "
                                                 f"(since t={f.since_t_s:.1f} s)"})
        shown = seen(comp, telemetry.get(comp))
        if shown is not None:
            seen_level, seen_words, value = shown
            level = max(level, seen_level)
            if seen_words not in words:
                words.append(seen_words)
            if value:
                values.append({"key": "reading", "value": value})
        message = ", ".join(words) or "OK"
        age = age_s.get(comp)
        if comp in age_s and (age is None or age > stale_after_s):
            level = DIAG_STALE
            silent = "no data yet" if age is None else f"no data for {age:.1f} s"
            message = silent + (f"; {message}" if words else "")
        statuses.append({"level": level, "name": f"{rover}/{comp}", "message": message,
                         "hardware_id": rover, "values": values})
    return statuses


# -- the console's view: what every crew topic of a rover says -----------------------------------


@cache
def _default_mapping() -> MappingFile:
    return load_mapping(resolve_mapping(None))


def _names_from_values(rover: str, values: Mapping[str, Any]) -> RoverNames:
    """A rover's components as its telemetry shows them (no rover file at hand)."""
    found: dict[str, list[str]] = {"load": [], "rail": [], "radio": [], "panel": []}
    where = {("load", "power"): "load", ("rail", "state"): "rail", ("radio", "link"): "radio",
             ("solar", "power"): "panel"}
    drives = False
    for key in values:
        r, parts = keys.split(key)
        if r != rover:
            continue
        if len(parts) == 3 and (parts[0], parts[2]) in where:
            found[where[(parts[0], parts[2])]].append(parts[1])
        drives |= parts == ["drive", "state"]
    return RoverNames(rover, load=tuple(sorted(found["load"])), rail=tuple(sorted(found["rail"])),
                      radio=tuple(sorted(found["radio"])), panel=tuple(sorted(found["panel"])),
                      drives=drives)


def _plain(value: Any) -> Any:
    """JSON as a browser reads it: NaN and infinities are null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def crew_view(rover: str, values: Mapping[str, Any], age_s: Mapping[str, float] | None = None, *,
              config: Rover | None = None, mapping: MappingFile | None = None,
              stamp_ns: int = 0) -> dict[str, Any]:
    """What the crew's topics say of ``rover`` now, from the twin's values alone (pure).

    ``values``: twin key -> its latest payload (the family's Struct, as the client's mirror
    holds them), the owners' ``faults/active/<service>`` included; ``age_s``: twin key -> how
    long ago it came [s] (default: all fresh); ``config``: the rover file (without it the
    components are those the telemetry shows, and the battery's charges are unknown);
    ``mapping``: the bridge mapping (default: the one the bridge would load). Returns::

        {"rover", "view": "symptoms"|"full", "t_s": the rover's clock or null,
         "diagnostics": [{"name", "component", "level", "level_name", "message",
                          "values": [{"key", "value"}]}],
         "topics": [{"topic", "type", "key", "message": the ROS fields or null}],
         "controls": [{"service", "type", "key", "write"}]}

    ``topics`` lists every outbound topic of the mapping for the rover, ``/diagnostics`` among
    them, in the mapping's order; a topic whose key has no value yet has message null."""
    mf = mapping if mapping is not None else _default_mapping()
    opts = mf.bridge
    names = rover_names(config) if config is not None else _names_from_values(rover, values)
    bindings = expand(mf, [names])
    ages = dict(age_s or {})
    comps = components(config) if config is not None else (
        ["battery"] + [f"rail/{r}" for r in names.rail] + [f"load/{x}" for x in names.load]
        + [f"solar/{p}" for p in names.panel] + ["umbilical"] + [f"radio/{r}" for r in names.radio])
    active = [f for key, v in sorted(values.items()) if isinstance(v, ActiveFaults)
              and keys.split(key)[0] == rover for f in v.faults]
    active.sort(key=lambda f: (f.since_t_s, f.key))
    comp_age: dict[str, float | None] = {c: ages.get(data_key(rover, c), 0.0)
                                         if data_key(rover, c) in values else None for c in comps}
    telemetry = {c: values.get(data_key(rover, c)) for c in comps}
    if opts.crew_view == "full":
        statuses = diagnostic_statuses(rover, comps, active, comp_age, opts.stale_after_s)
    else:
        statuses = crew_statuses(rover, comps, active, telemetry, comp_age, opts.stale_after_s)
    battery = config.battery if config is not None else None
    battery_stale = (comp_age.get("battery") or 0.0) > opts.stale_after_s
    topics, controls = [], []
    for b in bindings:
        m = b.mapping
        if m.kind == "service":
            controls.append({"service": b.topic, "type": m.type, "key": b.key, "write": m.write})
            continue
        if m.direction == "in":
            continue
        if m.convert == "diagnostics":
            msg: dict | None = {"header": {"stamp": {"sec": stamp_ns // 10**9,
                                                     "nanosec": stamp_ns % 10**9},
                                           "frame_id": m.frame_id}, "status": statuses}
        else:
            payload = values.get(b.key)
            msg = None if payload is None else topic_message(m, payload, battery, stamp_ns,
                                                             opts.ros_distro, battery_stale)
        topics.append({"topic": b.topic, "type": m.type, "key": b.key, "message": _plain(msg)})
    clock = values.get(keys.clock(rover))
    return {
        "rover": rover,
        "view": opts.crew_view,
        "t_s": getattr(clock, "t_s", None),
        "diagnostics": [{"name": st["name"], "component": st["name"].split("/", 1)[1],
                         "level": st["level"], "level_name": level_name(st["level"]),
                         "message": st["message"], "values": st["values"]} for st in statuses],
        "topics": topics,
        "controls": controls,
    }
