"""Session switch: from ``put control/session`` to every service's events carrying the new id.

SPEC §10 (third release): ``control/session`` -> every service in the new session (events
carry the new id) under 2 s. A full MAPP twin (every service of ``lunaris up`` but the
bridge, the drive included) is asked for a new trainee's session, many times. Right after
each put, and again every ``POKE_S`` until it answers in the new session, each service is
sent one write it answers with an event of its own (a fault, a rail command, a clock control,
a traverse, a mark); the time of a service is that of the first event of its own carrying the
new session's id, on the wall clock of this process (the writer's). A write that reaches a
service before the new session's first tick is answered in the previous session (and undone
by the reset): that is the point of measuring, not an error.

Printed: per service and for the slowest service of each switch (the time the whole twin is
in the new session), percentiles over the switches. A figure, never an assertion.
Run: `.venv/bin/python bench/session_switch.py [N]`.
"""

from __future__ import annotations

import json
import sys
import threading
import time

from benchlib import ROOT, machine, percentiles, running_twin

from common import keys

R = "mapp-1"
POKE_S = 0.02  # how often a service not yet heard from in the new session is written to again
TIMEOUT_S = 10.0
SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults")
POKES: dict[str, tuple[str, object]] = {  # service -> a write it answers with an event
    "clock": (keys.clock_control(R), {"time_scale": 1}),
    "battery": (keys.fault(R, "battery", "heating"), 5),
    "loads": (keys.fault(R, "load/nav_camera", "stuck"), {"power_w": 1.0}),
    "power": (keys.cmd_rail(R, "3V3_CH2"), {"on": True}),
    "solar": (keys.fault(R, "solar/left", "dust"), 0.1),
    "radio": (keys.fault(R, "radio/lander", "degraded"), 0.5),
    "drive": (keys.input_drive_traverse(R), {"waypoints": [{"x_m": 5, "y_m": 0, "z_m": 0}]}),
    "faults": (keys.control_mark(R), {"text": "bench"}),
}


class Switch:
    """One switch: the previous session's id, and when each service was first heard in another."""

    def __init__(self, previous: str):
        self.previous = previous
        self.t0 = 0.0
        self.new = ""
        self.at: dict[str, float] = {}
        self.lock = threading.Lock()
        self.all_in = threading.Event()

    def on_event(self, ev: dict, t: float) -> None:
        session, source = ev.get("session", ""), ev.get("source", "")
        if not session or session == self.previous or source not in SERVICES:
            return
        with self.lock:
            if self.new and session != self.new:
                return
            self.new = session
            self.at.setdefault(source, t - self.t0)
            if len(self.at) == len(SERVICES):
                self.all_in.set()


def main(n: int = 20) -> None:
    print(f"session switch: {n} switches of a MAPP twin ({', '.join(SERVICES)}) on {machine()}")
    with running_twin([ROOT / "config/rovers/mapp.yaml"], SERVICES) as (probe, _, _):
        probe.watch(f"lunaris/{R}/clock")
        probe.wait_services(R, SERVICES)
        current: list[Switch | None] = [None]

        def on_event(s) -> None:
            t = time.perf_counter()
            switch = current[0]
            if switch is not None:
                switch.on_event(json.loads(s.payload.to_bytes()), t)

        sub = probe.session.declare_subscriber(keys.event_of(R, "*"), on_event)
        previous = probe.wait_value(keys.clock(R), lambda c: c["session"])["session"]
        per_service: dict[str, list[float]] = {s: [] for s in SERVICES}
        whole: list[float] = []
        for i in range(n):
            switch = current[0] = Switch(previous)
            switch.t0 = time.perf_counter()
            probe.put(keys.control_session(R), {"trainee": f"bench {i}"})
            deadline = switch.t0 + TIMEOUT_S
            while not switch.all_in.is_set():
                with switch.lock:
                    waiting = [s for s in SERVICES if s not in switch.at]
                for service in waiting:
                    key, payload = POKES[service]
                    probe.put(key, payload)
                if switch.all_in.wait(POKE_S):
                    break
                if time.perf_counter() > deadline:
                    raise SystemExit(f"switch {i}: no event in the new session from "
                                     f"{', '.join(waiting)} within {TIMEOUT_S:g} s")
            for service, dt in switch.at.items():
                per_service[service].append(dt * 1000)
            whole.append(max(switch.at.values()) * 1000)
            previous = switch.new
            probe.wait_value(keys.clock(R), lambda c, s=switch.new: c["session"] == s)
            time.sleep(1.1)  # session ids are seconds: one a second keeps them the wall time's
        sub.undeclare()
    for service, samples in per_service.items():
        print(f"  {service:<8} {percentiles(samples)}")
    print(f"every service in the new session: {percentiles(whole)} (SPEC target: under 2 s)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
