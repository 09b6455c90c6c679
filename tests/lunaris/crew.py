"""A scripted crew for the shorted-camera drill: a process that sees what the crew's dashboard
shows (a rail's state) and acts as the bridge does for the crew's service calls (SPEC 12a): a
write on ``cmd/rail/<rail>`` carrying ``actor=crew``.

    python -m tests.lunaris.crew ENDPOINT ROVER RAIL [HOLD_S [REACT_S]] [--after-go]

When the rail trips it calls set_enabled false then reset (the rail reads off); once the rail
has read off for HOLD_S seconds of simulated time (the instructor's note: the camera is
isolated) it calls set_enabled true; a rail that trips again is safed again. It prints each
call, and stops on SIGINT or SIGTERM. With ``--after-go`` it acts only once a line has come on
its standard input (a test that must see the drill before the crew has acted says go).
"""

from __future__ import annotations

import json
import signal
import sys
import threading

import zenoh

from common import keys
from common.connection import make_config, write


def main(argv: list[str]) -> int:
    go = threading.Event()
    if "--after-go" in argv:
        argv = [a for a in argv if a != "--after-go"]
        threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
    else:
        go.set()
    endpoint, rover, rail = argv[:3]
    hold_s = float(argv[3]) if len(argv) > 3 else 10.0
    # a crew takes a moment to read its dashboard: it acts this long (sim s) after seeing a
    # trip (acting at once, it switched the rail off before a loaded runner saw the trip)
    react_s = float(argv[4]) if len(argv) > 4 else 10.0
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    states: list[tuple[float, str]] = []
    lock = threading.Condition()

    def on_state(s: zenoh.Sample) -> None:
        v = json.loads(s.payload.to_bytes())
        with lock:
            states.append((v["t_s"], v["state"]))
            lock.notify()

    with zenoh.open(make_config("client", connect=[endpoint])) as session:
        sub = session.declare_subscriber(keys.rail_state(rover, rail), on_state)
        key = keys.cmd_rail(rover, rail)

        def call(payload: dict, what: str) -> None:
            write(session, key, json.dumps(payload), actor="crew")
            print(f"crew: {what}", flush=True)

        off_since: float | None = None
        tripped_at: float | None = None
        safing = False
        print("crew: watching", rail, flush=True)
        while not stop.is_set():
            with lock:
                lock.wait(0.2)
                seen, states[:] = list(states), []
            for t, state in seen:
                if not go.is_set():
                    continue
                if state == "tripped" and not safing:
                    tripped_at = t if tripped_at is None else tripped_at
                    if t - tripped_at >= react_s:
                        call({"on": False}, "set_enabled false")
                        call({"reset": True}, "reset")
                        safing, off_since, tripped_at = True, None, None
                elif state == "off":
                    safing = False
                    off_since = t if off_since is None else off_since
                    if t - off_since >= hold_s:
                        call({"on": True}, "set_enabled true")
                        off_since = None
                elif state == "on":
                    off_since = None
        sub.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
