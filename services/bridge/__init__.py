"""The bridge's public face: what the rest of Lunaris (the CLI, the deployment) may use of it.

- the mapping format (:mod:`services.bridge.mapping`): :class:`MappingFile` and its parts,
  :func:`load_mapping` (every problem named), the shipped mapping (:data:`DEFAULT_MAPPING`,
  package data) and :func:`resolve_mapping` (what ``--bridge-config`` names);
- a mapping over a fleet (:mod:`services.bridge.bindings`): its topics and keys, rover by
  rover (:func:`expand`, :func:`zenoh_key`, :func:`open_keyexpr`);
- the value a one-value topic carries for a twin payload (:func:`out_value`).

The rest of the package is the bridge's own, free to change with it: its process
(``service``, ``outlets``, ``ros2_node``) and its codecs (``cdr``, ``rmw_zenoh``,
``convert``). tests/architecture/test_layers.py holds the CLI to this face.
"""

from services.bridge.bindings import Binding, RoverNames, expand, open_keyexpr, rover_names, zenoh_key
from services.bridge.convert import out_value
from services.bridge.mapping import (
    CONVERTERS,
    DEFAULT_MAPPING,
    PLACEHOLDERS,
    BridgeOptions,
    Mapping,
    MappingFile,
    load_mapping,
    parse_mapping,
    resolve_mapping,
    ros_name,
)

__all__ = ["CONVERTERS", "DEFAULT_MAPPING", "PLACEHOLDERS", "Binding", "BridgeOptions", "Mapping",
           "MappingFile", "RoverNames", "expand", "load_mapping", "open_keyexpr", "out_value",
           "parse_mapping", "resolve_mapping", "ros_name", "rover_names", "zenoh_key"]
