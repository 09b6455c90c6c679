"""What every benchmark shares: the machine it ran on, percentiles, a twin to measure."""

from __future__ import annotations

import os
import platform
import sys
import tempfile
from contextlib import contextmanager
from importlib.metadata import version
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from testbed.twin import (  # noqa: E402
    ALL_SERVICES,
    Probe,
    Twin,
    free_endpoint,
    open_router,
    start_router_process,
    stop_process,
)

__all__ = ["ROOT", "machine", "percentiles", "running_twin"]


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, eclipse-zenoh {version('eclipse-zenoh')}")


def percentiles(samples_ms: list[float]) -> str:
    s = sorted(samples_ms)
    def q(p: float) -> float:
        return s[min(len(s) - 1, int(round(p * (len(s) - 1))))]
    return (f"n={len(s)}  p50={q(0.50):.2f} ms  p90={q(0.90):.2f} ms  p99={q(0.99):.2f} ms  "
            f"max={s[-1]:.2f} ms")


@contextmanager
def running_twin(rover_files: list[str | Path], services=ALL_SERVICES, extra=None,
                 router_process: bool = False):
    """A router, the services as processes, and a probe: (probe, twin, endpoint). The router
    is embedded in this process, or with ``router_process`` is ``lunaris router`` in a process
    of its own (``twin.router``), so its CPU and memory can be told from the measuring's."""
    endpoint = free_endpoint()
    router = None if router_process else open_router(endpoint)
    proc = None
    try:
        with tempfile.TemporaryDirectory(prefix="lunaris-bench-") as tmp:
            if router_process:
                proc = start_router_process(endpoint, Path(tmp) / "router.log")
            with Twin(endpoint, list(rover_files), Path(tmp), services=tuple(services),
                      extra=extra) as twin, Probe(endpoint) as probe:
                twin.router = proc
                yield probe, twin, endpoint
    finally:
        if proc is not None:
            stop_process(proc)
        if router is not None:
            router.close()
