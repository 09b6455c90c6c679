"""What a received sample costs a fleet's service, with and without its key declared.

Zenoh resolves the key of each sample a session receives; for a key the session has not
declared, the time grows with the number of key expressions the session did declare (each
publisher declares its own): a fleet's power service has ~1,000 publishers. The runtime
therefore declares each telemetry key it hears (``Runtime._declare_heard``).

A publisher process sends 100 rovers x 12 loads at 10 Hz (12,000 samples/s) through an
embedded router to a receiving process that drains its channels, in five set-ups side by side:
alone; with 900 publishers of its own (keys it does not receive); the same with the received
keys declared; 400 subscribers (a bridge shard's per-rover subscriptions, 8 families of 50 of the
rovers: 6,000 samples/s match) with and without.
Prints the receiving process's CPU per thread kind (``rx``: Zenoh's receive threads).

Run: ``.venv/bin/python bench/declared_keys.py [SECONDS]``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import zenoh
from benchlib import machine

from common.connection import make_config
from testbed.twin import free_endpoint

ROVERS, LOADS = 100, 12
FAMILIES = ("load/*/power", "rail/*/state", "battery/state", "power/summary", "radio/*/link",
            "solar/*/power", "umbilical/state", "clock")
SETUPS = {  # name -> (publishers of its own, received keys declared, per-rover subscribers)
    "one subscriber": (False, False, False),
    "+ 900 publishers": (True, False, False),
    "+ 900 publishers, received keys declared": (True, True, False),
    "400 subscribers": (False, False, True),
    "400 subscribers, received keys declared": (False, True, True),
}


def thread_cpu_s(pid: int) -> dict[str, float]:
    out: dict[str, float] = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        stat = open(f"/proc/{pid}/task/{tid}/stat").read()
        comm = stat[stat.index("(") + 1:stat.rindex(")")].rstrip("0123456789-")
        fields = stat.rsplit(")", 1)[1].split()
        out[comm] = out.get(comm, 0.0) + (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


def publish(endpoint: str) -> None:
    s = zenoh.open(make_config(connect=[endpoint]))
    pubs = [s.declare_publisher(f"lunaris/r{i:03d}/load/l{j}/power")
            for i in range(ROVERS) for j in range(LOADS)]
    payload = b'{"t_s":1.0,"power_w":12.5,"rail":"5V_CH2","on":true,"faults":[]}'
    due = time.monotonic()
    while True:
        for p in pubs:
            p.put(payload)
        due += 0.1
        time.sleep(max(0.0, due - time.monotonic()))


def receive(endpoint: str, setup: str) -> None:
    own, declared, per_rover = SETUPS[setup]
    s = zenoh.open(make_config(connect=[endpoint]))
    keep = []
    if own:
        keep += [s.declare_publisher(f"lunaris/r{i:03d}/rail/x{j}/state")
                 for i in range(ROVERS) for j in range(9)]
    if declared:
        keep += [s.declare_keyexpr(f"lunaris/r{i:03d}/load/l{j}/power")
                 for i in range(ROVERS) for j in range(LOADS)]
    patterns = ([f"lunaris/r{i:03d}/{f}" for i in range(ROVERS // 2) for f in FAMILIES]
                if per_rover else ["lunaris/*/load/*/power"])
    subs = [s.declare_subscriber(p, zenoh.handlers.FifoChannel(65536)) for p in patterns]
    while True:
        for sub in subs:
            while sub.try_recv() is not None:
                pass
        time.sleep(0.002)


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] in ("publish", "receive"):
        publish(sys.argv[2]) if sys.argv[1] == "publish" else receive(sys.argv[2], sys.argv[3])
        return
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    endpoint = free_endpoint()
    router = zenoh.open(make_config("router", listen=[endpoint]))
    print(f"declared keys: {ROVERS * LOADS * 10:,} samples/s received, {seconds:g} s per set-up "
          f"({machine()})")
    pub = subprocess.Popen([sys.executable, __file__, "publish", endpoint])
    try:
        for setup in SETUPS:
            rx = subprocess.Popen([sys.executable, __file__, "receive", endpoint, setup])
            try:
                time.sleep(5.0)  # declared, and the stream steady
                a = thread_cpu_s(rx.pid)
                time.sleep(seconds)
                b = thread_cpu_s(rx.pid)
            finally:
                rx.terminate()
                rx.wait(10)
            used = {k: (b[k] - a.get(k, 0.0)) / seconds * 100 for k in b}
            detail = ", ".join(f"{k} {v:.1f} %" for k, v in sorted(used.items(), key=lambda kv: -kv[1])
                               if v >= 0.5)
            print(f"  {setup:<42} {sum(used.values()):5.1f} % of a core  ({detail})", flush=True)
    finally:
        pub.terminate()
        pub.wait(10)
        router.close()


if __name__ == "__main__":
    main()
