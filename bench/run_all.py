"""Every benchmark, one after the other; each prints its own figures."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

for script in ("sim_8h.py", "battery.py", "drive.py", "fleet_models.py", "fleet.py",
               "declared_keys.py", "fault_latency.py", "fault_latency_bridge.py", "crew_call_latency.py",
               "reliability.py", "console_latency.py", "site_latency.py", "session_switch.py",
               "report_json.py", "supervisor_death.py"):
    print(f"$ python bench/{script}", flush=True)
    subprocess.run([sys.executable, str(HERE / script)], cwd=HERE, check=True)
    print(flush=True)
