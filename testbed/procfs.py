"""What a process costs, read from ``/proc`` (Linux): CPU time and resident memory."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cpu_s", "rss_kib"]


def cpu_s(pid: int) -> float:
    """CPU time (user and system) a process has used so far [s]."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_kib(pid: int) -> int:
    """Resident set size of a process [KiB]."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for pid {pid}")
