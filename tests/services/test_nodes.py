"""Every service that is a node (``NODE`` in ``services/<name>/service.py``) is made without a
TypeError (a port naming a method the class lacks, a payload its key family does not carry)
and lists its ports in :func:`common.node.port_table`; no Zenoh session, no process."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from common.node import Node, port_table

SERVICES = sorted(p.parent.name for p in (Path(__file__).parents[2] / "services").glob("*/service.py"))


def _node(service: str) -> type[Node] | None:
    # made as the module is imported: a port naming no method raises TypeError here
    return getattr(importlib.import_module(f"services.{service}.service"), "NODE", None)


def test_the_services_that_are_nodes() -> None:
    nodes = [s for s in SERVICES if _node(s) is not None]
    # (the bridge is a class of its own, declaring its ports in Bridge.start)
    assert nodes == ["battery", "clock", "drive", "faults", "loads", "power", "radio",
                     "solar"]


@pytest.mark.parametrize("service", [s for s in SERVICES if _node(s) is not None])
def test_a_node_lists_its_ports_and_each_names_a_method(service: str) -> None:
    node = _node(service)
    assert node is not None
    assert issubclass(node, Node) and node.name == service
    rows = port_table(node)
    ports = (*node.reads, *node.hears, *node.publishes, *node.answers, *node.owns)
    assert len(rows) == len(ports) and rows, f"{service}: {rows}"
    for direction, key, payload, what in rows:
        assert direction in ("reads", "hears", "publishes", "answers", "owns")
        assert key.startswith("lunaris/*/"), key
        assert payload
        if direction != "publishes":
            method = what.rsplit(" ", 1)[-1]  # "telemetry -> on_load", "on_query", "apply"
            assert callable(getattr(node, method, None)), f"{service}: {direction} {key} -> {method}"


def test_a_port_naming_no_method_is_refused_when_the_class_is_made() -> None:
    from common.messages import ClockControl
    from common.node import Hears, PerRover, Reads

    with pytest.raises(TypeError, match="its ports name no method on_nothing"):
        class Broken(Node[PerRover]):
            name = "broken"
            reads = (Reads("clock/control", ClockControl, "on_nothing", kind="command"),)
    with pytest.raises(TypeError, match="declare it with Reads"):
        Hears("clock/control", "on_control")
