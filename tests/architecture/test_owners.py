"""One owner per component of the fault catalogue (issue 30): the services' port tables (each
node's ``Owns``) say who applies a component's faults; ``common.writes.FAULT_OWNERS`` is the
same table as the tools and the faults service read it without importing the services, and
the faults service asks exactly the owners a rover file implies."""

from __future__ import annotations

import importlib

from common.config import load_rover
from common.faults import CATALOGUE
from common.writes import FAULT_OWNERS, fault_owners
from lunaris.run import SERVICES
from testbed.twin import ROVERS


def _owns() -> dict[str, str]:
    """component type -> the service whose node declares it owns it."""
    owned: dict[str, str] = {}
    for service in SERVICES:
        node = getattr(importlib.import_module(f"services.{service}.service"), "NODE", None)
        for port in getattr(node, "owns", ()):
            assert port.component not in owned, f"{port.component}: owned by {owned[port.component]} " \
                f"and {service}"
            owned[port.component] = service
    return owned


def test_the_port_tables_and_the_owner_table_are_one():
    assert _owns() == FAULT_OWNERS
    assert set(CATALOGUE) == set(FAULT_OWNERS), "a component of the catalogue with no owner, or the reverse"


def test_the_owners_a_rover_file_implies():
    mapp = load_rover(ROVERS / "mapp.yaml")
    assert fault_owners(mapp) == {"battery", "loads", "power", "solar", "radio"}
    cell = load_rover(ROVERS / "bc18650.yaml")
    assert "battery" in fault_owners(cell) and fault_owners(cell) <= set(FAULT_OWNERS.values())
