"""``lunaris report FILE.mcap --json`` of a one-hour session recording (SPEC §10 target: under 5 s).

Makes the recording first, as ``lunaris record`` would have written it from a live MAPP twin
at 10 Hz: the composed models (services/composed/__init__.py) stepped for an hour of simulated time,
every key the twin publishes each tick (clock, battery, 10 loads, 6 rails, the summary, 2
panels, the umbilical, the radio link, the drive: 24 keys, ~864,000 messages), with a trainee's
session in it (the clock's session id on every tick and event, SPEC 12c): a short on the
navigation camera that trips 5V_CH2 (the crew safes the rail, the short is cleared, the crew
brings it back), then the pack heating under a scenario
(the crew switches 12V off, an expectation met), each event heard twice (the service's key
and the journal's). Then times the command as a user runs it (a new process, imports
included), three times, and the reading alone in-process.

Run: ``.venv/bin/python bench/report_json.py [MINUTES] [--keep FILE.mcap]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import ROOT, machine

from common.config import load_rover
from common.faults import Heating, Short
from common.messages import (
    BatteryState,
    Clock,
    DriveState,
    Event,
    LoadPower,
    PowerSummary,
    RadioLink,
    RailState,
    SolarPower,
    UmbilicalState,
    encode,
)
from lunaris.record import Recorder
from services.composed import ComposedTwin

R = "mapp-1"
P = f"lunaris/{R}/"
SESSION = "20261125-090000"  # the trainee's session, as the clock names it (SPEC 12c)


class Session:
    """The recording being made: every sample with its wall time of reception."""

    def __init__(self, out) -> None:
        self.rec = Recorder(out, "bench/report_json.py")
        self.wall = 1_700_000_000_000_000_000
        self.seq = 0

    def put(self, key: str, payload: bytes) -> None:
        self.wall += 1000
        self.rec.write(P + key, payload, False, self.wall)

    def event(self, t: float, kind: str, key: str, message: str, *, source: str = "power",
              actor: str = "twin", params: dict | None = None) -> None:
        self.seq += 1
        data = encode(Event(t_s=t, severity="info", source=source, kind=kind, key=P + key,
                            message=message, params=params, source_id=f"bench-{source}",
                            seq=self.seq, actor=actor, session=SESSION))
        self.put(f"event/{source}", data)
        self.put("event", data)


def record(path: Path, minutes: float) -> int:
    rover = load_rover(ROOT / "config" / "rovers" / "mapp.yaml")
    twin = ComposedTwin(rover, seed=0, fast=False)
    ticks = int(minutes * 60 * rover.tick_hz)
    with open(path, "wb") as out:
        s = Session(out)
        s.event(0.0, "session", "control/session", f"session {SESSION} of 'Ada' begins", source="clock",
                params={"session": SESSION, "trainee": "Ada", "from_snapshot": None,
                        "started_wall": 1.7e9, "start_t_s": 0.0})
        states: dict[str, str] = {}
        for i in range(ticks):
            twin.step()
            t = round(twin.t_s, 3)
            script(s, twin, t)
            s.put("clock", encode(Clock(t, twin.dt_s, i, 1.0, False, 0, "", SESSION)))
            b = twin.reading()
            s.put("battery/state", encode(BatteryState(t, b.energy_j, b.capacity_j, b.soc, b.ocv_v,
                                                       b.voltage_v, b.current_a, b.power_w,
                                                       b.temperature_c, b.operational, 0, b.faults,
                                                       b.time_to_empty_s)))
            for name, power_w, rail, on in twin.loads.powers():
                s.put(f"load/{name}/power", encode(LoadPower(t, power_w, rail, on, [])))
            readings, summary = twin.power.compute()
            for r in readings:
                s.put(f"rail/{r.name}/state", encode(RailState(t, r.voltage_v, r.current_a, r.power_w,
                                                               r.current_limit_a, r.state, r.reason)))
                if states.get(r.name, "on") != r.state:  # the rail's own alarm, raised and resolved
                    kind = "fault_raised" if r.state == "tripped" else "fault_resolved"
                    if "tripped" in (r.state, states.get(r.name)):
                        s.event(t, kind, f"rail/{r.name}/tripped", f"rail {r.name} {r.state}")
                    states[r.name] = r.state
            s.put("power/summary", encode(PowerSummary(t, *summary)))
            for name, power_w, dust in twin.solar.panels():
                s.put(f"solar/{name}/power", encode(SolarPower(t, power_w, twin.solar.sun_angle_deg, dust)))
            s.put("umbilical/state", encode(UmbilicalState(t, twin.solar.umbilical_connected,
                                                           twin.solar.umbilical_power_w)))
            d = twin.drive
            assert d is not None
            s.put("radio/lander/link", encode(RadioLink(t, True, d.x_m, d.y_m)))
            s.put("drive/state", encode(DriveState(t, *d.reading())))
        s.rec.finish()
        return s.rec.messages


def script(s: Session, twin: ComposedTwin, t: float) -> None:
    """The session's faults and the crew's answers, at their times."""
    def crew(rail: str, on: bool | None = None, reset: bool = False) -> None:
        twin.power.command(rail, on=on, reset=reset)
        s.event(t, "command", f"cmd/rail/{rail}", f"rail {rail}: on={on} reset={reset}", actor="crew",
                params={"on": on, "reset": reset})

    at = {600.0: lambda: (twin.set_faults("load", "nav_camera", [Short(0.05)]),
                          s.event(t, "fault_injected", "fault/load/nav_camera/short", "injected",
                                  source="loads", actor="instructor", params={"resistance_ohm": 0.05})),
          640.0: lambda: (crew("5V_CH2", on=False), crew("5V_CH2", reset=True)),
          700.0: lambda: (twin.set_faults("load", "nav_camera", []),
                          s.event(t, "fault_cleared", "fault/load/nav_camera/short", "cleared",
                                  source="loads", actor="instructor")),
          720.0: lambda: crew("5V_CH2", on=True),
          1800.0: lambda: (twin.set_faults("battery", None, [Heating(45.0)]),
                           s.event(t, "fault_injected", "fault/battery/heating", "injected",
                                   source="battery", actor="scenario", params={"heat_w": 45.0})),
          2400.0: lambda: (crew("12V", on=False), s.event(
              t, "scenario", "control/scenario", "expectation met", source="faults", actor="scenario",
              params={"scenario": "bench", "what": "expect", "step": 2, "expectation": {
                  "index": 1, "label": "isolate the heater", "condition": "rail.12V.state == off",
                  "within_s": 900.0, "met": True, "at_t_s": t, "armed_t_s": 1800.0, "start_t_s": 0.0}})),
          2500.0: lambda: (twin.set_faults("battery", None, []),
                           s.event(t, "fault_cleared", "fault/battery/heating", "cleared", source="battery",
                                   actor="scenario"))}
    action = at.get(t)
    if action is not None:
        action()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("minutes", nargs="?", type=float, default=60.0)
    ap.add_argument("--keep", metavar="FILE.mcap", help="write the recording there and keep it")
    args = ap.parse_args()
    print(f"lunaris report --json of {args.minutes:g} min of a MAPP session at 10 Hz ({machine()})")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(args.keep) if args.keep else Path(tmp) / "session.mcap"
        t0 = time.perf_counter()
        n = record(path, args.minutes)
        print(f"  recording: {n:,} messages, {path.stat().st_size / 1e6:.1f} MB, made in "
              f"{time.perf_counter() - t0:.1f} s")
        walls, out = [], ""
        for _ in range(3):
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "lunaris.cli", "report", str(path), "--json"],
                                  cwd=ROOT, capture_output=True, text=True, check=True)
            walls.append(time.perf_counter() - t0)
            out = done.stdout
        print(f"  lunaris report --json (a new process): best {min(walls):.2f} s, worst {max(walls):.2f} s "
              f"of 3 (target: under 5 s)")
        from lunaris.record import read_messages
        from lunaris.report import load_recording
        t0 = time.perf_counter()
        count = sum(1 for _ in read_messages(path))
        read_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        load_recording(path, plots=False)
        print(f"  in-process: reading {count:,} messages {read_s:.2f} s; reading, decoding and "
              f"measuring the response {time.perf_counter() - t0:.2f} s")
        for session in json.loads(out):
            for f in session["faults"]:
                print(f"  session {session['session']} ({session['trainee']}): {f['fault']} injected "
                      f"{f['injected_t_s']:.1f} s, "
                      f"symptom {f['first_symptom_t_s']}, first crew action {f['first_crew_action_t_s']}, "
                      f"resolved {f['resolved_t_s']}, {len(f['crew_actions'])} action(s)")
            for e in session["expectations"]:
                print(f"  session {session['session']}: expectation {e['label']!r} met={e['met']} "
                      f"at {e['at_t_s']}")


if __name__ == "__main__":
    main()
