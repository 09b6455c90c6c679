"""The bridge's public face: what the rest of Lunaris (the CLI, the deployment) may use of it.

- the mapping format (:mod:`services.bridge.mapping`): :class:`MappingFile` and its parts,
  :func:`load_mapping` (every problem named), the shipped mapping (:data:`DEFAULT_MAPPING`,
  package data) and :func:`resolve_mapping` (what ``--bridge-config`` names);
- a mapping over a fleet (:mod:`services.bridge.bindings`): its topics and keys, rover by
  rover (:func:`expand`, :func:`zenoh_key`, :func:`open_keyexpr`);
- the value a one-value topic carries for a twin payload (:func:`out_value`);
- what the crew's topics say of a rover, rendered from the twin's values without ROS
  (:func:`crew_view`: the console's "what the crew sees"), and the crew's words for the
  twin's alarms (:data:`SYMPTOMS`).

The rest of the package is the bridge's own, free to change with it: its process
(``service``, ``outlets``, ``controls``, ``ros2_node``) and its codecs (``cdr``, ``srv``,
``rmw_zenoh``, ``convert``). tests/architecture/test_layers.py holds the CLI to this face.
"""

from services.bridge.bindings import Binding, RoverNames, expand, open_keyexpr, rover_names, zenoh_key
from services.bridge.convert import out_value
from services.bridge.crew import SYMPTOMS, crew_view
from services.bridge.mapping import (
    CONVERTERS,
    DEFAULT_MAPPING,
    LOCAL_MAPPING,
    PLACEHOLDERS,
    BridgeOptions,
    Mapping,
    MappingFile,
    load_mapping,
    parse_mapping,
    resolve_mapping,
    ros_name,
)

__all__ = ["CONVERTERS", "DEFAULT_MAPPING", "LOCAL_MAPPING", "PLACEHOLDERS", "SYMPTOMS", "Binding",
           "BridgeOptions", "Mapping", "MappingFile", "RoverNames", "crew_view", "expand", "load_mapping",
           "open_keyexpr", "out_value", "parse_mapping", "resolve_mapping", "ros_name",
           "rover_names", "zenoh_key"]
