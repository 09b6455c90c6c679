"""Console latency and load: a fault put by another client, seen changing on the page.

In a real browser (Debian's headless Chromium, driven by Selenium), the console's Live view
of mapp-1 is open. Another Zenoh client (this process) shorts nav_camera, which trips 5V_CH2;
a MutationObserver in the page stamps the moment the rail's state on the page reads
``tripped`` (``performance.timeOrigin + performance.now()``, the same wall clock as this
process's ``time.time()``). The latency is that stamp minus the time just before the put.
Each run then clears the short, resets the rail and waits for the page to read ``on``.
SPEC §10 target: p99 under 250 ms.

Then the console's CPU: with 0, and with 20 live clients (streams of /api/live read to the
end, as a page reads them), the twin ticking at 10 Hz, over ``--cpu-s`` seconds of wall
time, from /proc (user + system time of the console's process).

Run: `.venv/bin/python bench/console_latency.py [--faults 100] [--clients 20] [--cpu-s 20]`.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import threading
import time
import urllib.request

from benchlib import ROOT, machine, percentiles, running_twin

from common import keys
from testbed.browser import available, open_browser
from testbed.twin import lunaris_cmd, static_rover, wait_for

R = "mapp-1"
SHORT = keys.fault(R, "load/nav_camera", "short")
OBSERVE = """
const el = document.querySelector('#main [data-key="rail/5V_CH2/state"][data-field="state"]');
window.__seen = {};
new MutationObserver(() => {
  const t = performance.timeOrigin + performance.now();
  if (!(el.textContent in window.__seen)) window.__seen[el.textContent] = t;
}).observe(el, {childList: true, characterData: true, subtree: true});
"""


def cpu_s(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def reader(url: str, stop: threading.Event, got: list[int]) -> None:
    with urllib.request.urlopen(url, timeout=30) as r:
        while not stop.is_set():
            line = r.readline()
            if not line:
                return
            got[0] += len(line)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faults", type=int, default=100)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--cpu-s", type=float, default=20.0)
    args = ap.parse_args()
    if not available():
        print("needs Debian's chromium and chromium-driver (make system-deps as root)")
        return 2
    print(f"machine: {machine()}")
    with running_twin([static_rover("mapp.yaml")]) as (p, twin, endpoint):
        p.watch(f"lunaris/{R}/**")
        p.wait_services(R, ("clock", "battery", "loads", "power", "faults"))
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        console = subprocess.Popen(lunaris_cmd("console", "--http", f"127.0.0.1:{port}", "--connect",
                                               endpoint), cwd=ROOT, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
        url = f"http://127.0.0.1:{port}"
        try:
            wait_for(lambda: _up(url), 30, "the console")
            with open_browser(1280, 800) as driver:
                driver.get(url + "/")
                wait_for(lambda: driver.execute_script(
                    "const el = document.querySelector('#main [data-key=\"rail/5V_CH2/state\"]"
                    "[data-field=\"state\"]'); return !!el && el.textContent === 'on'"), 30, "the page")
                driver.execute_script(OBSERVE)
                latencies = []
                for _ in range(args.faults):
                    driver.execute_script("window.__seen = {}")
                    t0 = time.time()
                    p.put(SHORT, b"")
                    seen = wait_for(lambda: driver.execute_script("return window.__seen.tripped || null"), 10,
                                    "the page to show the trip")
                    latencies.append(seen - t0 * 1000.0)
                    n = len(p.events(R))
                    p.delete(SHORT)
                    wait_for(lambda n=n: any(e["kind"] == "fault_cleared" and e["key"] == SHORT
                                             for e in p.events(R)[n:]), 10, "the clearing")
                    p.put(keys.cmd_rail(R, "5V_CH2"), {"reset": True})
                    wait_for(lambda: driver.execute_script("return window.__seen.on || null"), 10, "back on")
                print(f"fault put by another client -> the page shows the trip: {percentiles(latencies)}")
            for clients in (0, args.clients):
                stop, got = threading.Event(), [0]
                threads = [threading.Thread(target=reader, args=(url + "/api/live", stop, got), daemon=True)
                           for _ in range(clients)]
                for t in threads:
                    t.start()
                time.sleep(2.0)  # the streams are open and past their snapshots (not measured)
                c0, w0, b0 = cpu_s(console.pid), time.monotonic(), got[0]
                time.sleep(args.cpu_s)  # the measurement window itself
                c1, w1, b1 = cpu_s(console.pid), time.monotonic(), got[0]
                stop.set()
                print(f"console CPU with {clients:2d} live clients: {100 * (c1 - c0) / (w1 - w0):5.1f} % of "
                      f"one core; {(b1 - b0) / (w1 - w0) / 1e3:7.1f} kB/s sent to them "
                      f"(twin at 10 Hz, {len(p.latest)} keys of {R})")
        finally:
            console.send_signal(signal.SIGINT)
            console.wait(15)
    return 0


def _up(url: str) -> bool:
    try:
        urllib.request.urlopen(url + "/favicon.ico", timeout=1)
        return True
    except OSError:
        return False


if __name__ == "__main__":
    raise SystemExit(main())
