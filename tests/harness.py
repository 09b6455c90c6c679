"""Test harness for real multi-process tests: a router, the services, a probe.

The twin on a bench is :mod:`testbed.twin`, which the benchmarks use too (bench/ imports
nothing of tests/); its names are handed on here, where the tests have always found them.
"""

from __future__ import annotations

from testbed.twin import (
    ALL_SERVICES,
    ROOT,
    ROVERS,
    Probe,
    Twin,
    copies_of,
    env_without_zenoh_config,
    free_endpoint,
    json_bridge_extra,
    lunaris_cmd,
    mapp_fleet,
    open_router,
    rover_without_drive,
    start_router_process,
    static_rover,
    stop_process,
    wait_for,
)

__all__ = ["ALL_SERVICES", "ROOT", "ROVERS", "Probe", "Twin", "copies_of", "env_without_zenoh_config",
           "free_endpoint", "json_bridge_extra", "lunaris_cmd", "mapp_fleet", "open_router",
           "rover_without_drive", "start_router_process", "static_rover", "stop_process", "wait_for"]
