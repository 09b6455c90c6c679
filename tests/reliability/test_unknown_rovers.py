"""Memory stays flat under keys naming rovers nobody serves.

Found: every unknown rover id cost about 7 KB, never freed, in the faults service, the bridge
and the router (3,000 ids added about 20 MB to each): the rejection of each was published on
a new advanced publisher (a cache, a liveliness token and a queryable per id). Now a
rejection for a rover a service does not serve is a plain put.
"""

from __future__ import annotations

import pytest

from common import keys
from common.connection import write
from tests.harness import Probe, Twin, free_endpoint, start_router_process, stop_process, wait_for
from tests.reliability.conftest import MAPP, WITH_BRIDGE, R, rss_kib

pytestmark = pytest.mark.timeout(180)

IDS = 3000
# A flood as large as the measured one first: the queues and allocators reach the size a
# flood of 3,000 needs (on a loaded machine a backlog of queued puts takes megabytes that the
# allocator keeps), so what the second flood adds is what each id leaves behind.
WARM_UP = IDS
GROWTH_LIMIT_KIB = 4096  # 3,000 ids cost about 20 MB each before; flat is well under 4 MB


def flood(p: Probe, prefix: str, n: int) -> None:
    """Put on n rover ids nobody serves and wait for every rejection."""
    rejected: set[str] = set()
    sub = p.session.declare_subscriber(
        keys.event_of("*", "faults"),
        lambda s: rejected.add(str(s.key_expr)) if prefix in str(s.key_expr) else None)
    try:
        for i in range(n):
            write(p.session, keys.input_sun_angle(f"{prefix}-{i}"), "10")
        wait_for(lambda: len(rejected) >= n, 120, lambda: f"{n} rejections (have {len(rejected)})",
                 poll_s=0.1)
    finally:
        sub.undeclare()


def test_memory_is_flat_under_3000_unknown_rover_ids(tmp_path):
    endpoint = free_endpoint()
    router = start_router_process(endpoint, tmp_path / "router.log")
    try:
        with Twin(endpoint, [MAPP], tmp_path / "state", services=WITH_BRIDGE) as twin, \
                Probe(endpoint) as p:
            p.wait_services(R, WITH_BRIDGE)
            flood(p, "warm", WARM_UP)
            watched = {"router": router.pid, "faults": twin.procs["faults"].pid,
                       "bridge": twin.procs["bridge"].pid}
            before = {name: rss_kib(pid) for name, pid in watched.items()}
            flood(p, "ghost", IDS)
            after = {name: rss_kib(pid) for name, pid in watched.items()}
            growth = {name: after[name] - before[name] for name in watched}
            print(f"RSS growth over {IDS} unknown ids [KiB]: {growth}")
            assert all(g < GROWTH_LIMIT_KIB for g in growth.values()), growth
    finally:
        stop_process(router)
