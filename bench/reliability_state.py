"""Damaged state, lost time and doubled services, case by case: a table of figures.

    python bench/reliability_state.py [--only NAME ...] [--rounds N]

Each case starts a twin of its own (an embedded router, the services as processes, a
temporary state folder), damages what it says, and measures:

- **up**: seconds from the restart of the service whose state was damaged to its liveliness
  token (the target: within 10 s; "never" when it had not come back after 30 s);
- **said**: whether a ``critical`` event named the damage, and its first words;
- **kept**: whether the intact part was kept (another rover's state, the other saved
  faults, the journal's good lines, the time reached), or, for a restore, whether nothing
  changed; for kill -9 of every service, how many keys sent ``t_s`` back.

The functions ``case_*`` each return a :class:`Row` and can be run on their own
(``bench/reliability.py`` runs them as its ``damaged`` and ``kill9all`` cases); :func:`run` runs
a list of them and prints the table.
Figures, not assertions: a case that goes wrong prints what it saw.
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

from benchlib import ROOT, Probe, Twin, machine, running_twin

from common import keys

R = "mapp-1"
MAPP = ROOT / "config" / "rovers" / "mapp.yaml"
POWER_CHAIN = ("clock", "battery", "loads", "power")
EVERYTHING = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
UP_WITHIN_S = 10.0
NEVER_S = 30.0


class Row(NamedTuple):
    case: str
    up_s: float | None  # None: never back (within NEVER_S), or not a restart case
    said: str  # the critical event's first words, or "no"
    kept: str  # what of the intact part was kept, in a few words
    ok: bool  # every target met


# -- helpers ------------------------------------------------------------------------------------


def _wait(predicate: Callable[[], Any], timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.02)


def _events(p: Probe, kind: str, rover: str = R) -> list[dict]:
    prefix = keys.event(rover)
    with p._lock:
        found = [list(v) for k, v in p.history.items() if k == prefix or k.startswith(prefix + "/")]
    return [e for samples in found for e in samples if isinstance(e, dict) and e.get("kind") == kind]


def _said(p: Probe, *words: str, after: int = 0, rover: str = R, kind: str = "state_damaged",
          timeout_s: float = 10.0) -> str:
    """The first words of the critical event holding every one of ``words``, or "no"."""
    def find() -> dict | None:
        return next((e for e in _events(p, kind, rover)[after:] if e["severity"] == "critical"
                     and all(w in e["message"] for w in words)), None)
    ev = _wait(find, timeout_s)
    return "no" if ev is None else _short(ev["message"])


def _short(text: str, n: int = 70) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def _live(p: Probe, service: str, rover: str = R) -> bool:
    names = {str(r.ok.key_expr).rsplit("/", 1)[-1]
             for r in p.session.liveliness().get(keys.service(rover, "*"), timeout=2.0)
             if r.ok is not None}
    return service in names


def _kill(twin: Twin, service: str) -> None:
    twin.procs[service].kill()
    twin.procs[service].wait(10)


def _restart_damaged(p: Probe, twin: Twin, service: str, damage: Callable[[Path], Any],
                     rover: str = R) -> float | None:
    """kill -9, damage, start: seconds until its token is back (None: not within NEVER_S)."""
    _kill(twin, service)
    _wait(lambda: not _live(p, service, rover), 10)  # the router has dropped the dead one's
    damage(twin.state_dir)
    t0 = time.monotonic()
    twin.start(service)
    return time.monotonic() - t0 if _wait(lambda: _live(p, service, rover), NEVER_S) else None


def _edit(path: Path, change: Callable[[Any], Any]) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def _up_ok(up_s: float | None) -> bool:
    return up_s is not None and up_s <= UP_WITHIN_S


def _twin(services: tuple[str, ...], rover_files: list[Path] | None = None):
    return running_twin(rover_files or [MAPP], services=services)


def _drained(p: Probe, services: tuple[str, ...], rover: str = R, scale: float = 50) -> None:
    p.watch("lunaris/**")
    _wait(lambda: all(_live(p, s, rover) for s in services), 30)
    p.put(keys.input_sun_angle(rover), 90)  # no sun: the pack drains steadily
    p.put(keys.clock_control(rover), {"time_scale": scale})
    _wait(lambda: (p.value(keys.battery_state(rover)) or {}).get("energy_j", 1e9) < 5.3e5 - 3000, 30)


# -- the cases ----------------------------------------------------------------------------------


def case_torn_journal() -> Row:
    """The journal's last line cut short by a kill mid-write."""
    with _twin(("clock", "faults")) as (p, twin, _):
        p.watch("lunaris/**")
        _wait(lambda: _live(p, "faults"), 30)
        for n in range(20):
            p.put(keys.under(R, f"control/rewind{n}"), b"")
        journal = twin.state_dir / f"faults-journal-{R}.jsonl"
        _wait(lambda: journal.is_file() and journal.read_text().count("\n") >= 21, 10)
        before = journal.read_text().count("\n")
        up = _restart_damaged(p, twin, "faults", lambda d: journal.open("ab").write(b'{"t_s": 1.0, "sev'))
        said = _said(p, "journal of mapp-1", "cut short")
        got = _wait(lambda: p.get_json(keys.faults_journal(R)), 10)
        n = len(got[0]) if got else 0
        kept = f"{n} of {before} events answered"
        return Row("journal: last line cut short", up, said, kept,
                   _up_ok(up) and said != "no" and n >= before)


def _battery_state_case(label: str, damage: Callable[[Path], Any], words: tuple[str, ...]) -> Row:
    with _twin(POWER_CHAIN) as (p, twin, _):
        _drained(p, POWER_CHAIN)
        state = twin.state_dir / "battery-state.json"
        _wait(state.is_file, 10)
        errors = len(_events(p, "internal_error"))
        up = _restart_damaged(p, twin, "battery", lambda d: damage(state))
        said = _said(p, "battery state of mapp-1 damaged", *words)
        b = _wait(lambda: p.value(keys.battery_state(R)), 10) or {}
        time.sleep(5.0)  # a window in which a save onto a folder failed every 0.2 s
        errors = len(_events(p, "internal_error")) - errors
        aside = len(list(twin.state_dir.glob("battery-state.json.damaged-*")))
        kept = (f"reset to {b.get('energy_j', 0) / 1000:.1f} kJ; {aside} file set aside; "
                f"{errors} internal errors in 5 s")
        return Row(f"battery state: {label}", up, said, kept,
                   _up_ok(up) and said != "no" and aside == 1 and errors == 0)


def case_battery_wrong_type() -> Row:
    return _battery_state_case('energy_j "lots"', lambda s: _edit(
        s, lambda d: d[R]["state"].update(energy_j="lots")), ("energy_j",))


def case_battery_nan() -> Row:
    return _battery_state_case("energy_j NaN", lambda s: s.write_text(
        s.read_text().replace('"energy_j":', '"energy_j":NaN,"was":', 1)), ("energy_j",))


def case_battery_truncated() -> Row:
    return _battery_state_case("cut short", lambda s: s.write_bytes(s.read_bytes()[:40]),
                               ("not JSON",))


def case_battery_folder() -> Row:
    def folder(s: Path) -> None:
        s.unlink()
        s.mkdir()
        (s / "x").write_text("x")
    return _battery_state_case("a folder in its place", folder, ("a folder",))


def case_battery_other_rover_kept(tmp: Path) -> Row:
    files = []
    base = MAPP.read_text()
    for rid in ("mapp-01", "mapp-02"):
        f = tmp / f"{rid}.yaml"
        f.write_text(base.replace("id: mapp-1", f"id: {rid}"))
        files.append(f)
    with _twin(POWER_CHAIN, files) as (p, twin, _):
        for rover in ("mapp-01", "mapp-02"):
            _drained(p, POWER_CHAIN, rover)
        p.put(keys.clock_control("mapp-02"), {"paused": True})
        paused = _wait(lambda: (p.value(keys.clock("mapp-02")) or {}).get("paused") and
                       p.value(keys.clock("mapp-02")), 10)
        state = twin.state_dir / "battery-state.json"
        _wait(lambda: json.loads(state.read_text())["mapp-02"]["state"]["t_s"] == paused["t_s"], 10)
        kept_e = p.value(keys.battery_state("mapp-02"))["energy_j"]
        up = _restart_damaged(p, twin, "battery", lambda d: _edit(
            state, lambda s: s["mapp-01"]["state"].update(temperature_c="warm")), "mapp-01")
        said = _said(p, "battery state of mapp-01 damaged", "temperature_c", rover="mapp-01")
        time.sleep(1.0)
        e = p.value(keys.battery_state("mapp-02"))["energy_j"]
        return Row("battery state: one rover of two damaged", up, said,
                   f"the other's energy {e - kept_e:+.6f} J",
                   _up_ok(up) and said != "no" and abs(e - kept_e) < 1e-6)


def _faults_case(label: str, damage: Callable[[Path], Any], words: tuple[str, ...],
                 keep_heating: bool) -> Row:
    with _twin(POWER_CHAIN) as (p, twin, _):
        _drained(p, POWER_CHAIN)
        p.put(keys.fault(R, "battery", "heating"), 5)
        p.put(keys.fault(R, "battery", "capacity_loss"), 0.2)
        faults = twin.state_dir / "battery-faults.json"
        _wait(lambda: faults.is_file() and len(json.loads(faults.read_text()).get(R, {})) == 2, 10)
        up = _restart_damaged(p, twin, "battery", lambda d: damage(faults))
        said = _said(p, *words)
        active = _wait(lambda: p.get_json(keys.faults_active(R, "battery")), 10)
        injected = sorted(f["key"].rsplit("/", 1)[-1] for f in (active[0]["faults"] if active else [])
                          if f["origin"] == "injected")
        ok = _up_ok(up) and said != "no" and (injected == ["heating"] if keep_heating else True)
        return Row(f"battery faults: {label}", up, said, f"in effect: {', '.join(injected) or 'none'}",
                   ok)


def case_fault_out_of_range() -> Row:
    return _faults_case("a parameter out of range", lambda f: _edit(
        f, lambda d: d[R]["battery/capacity_loss"]["params"].update(fraction=1.5)),
        ("battery/capacity_loss", "fraction"), keep_heating=True)


def case_faults_garbage() -> Row:
    return _faults_case("garbage file", lambda f: f.write_bytes(b"\x00garbage{"),
                        ("injected faults of mapp-1 damaged",), keep_heating=False)


def case_power_state_list() -> Row:
    with _twin(POWER_CHAIN) as (p, twin, _):
        _drained(p, POWER_CHAIN)
        state = twin.state_dir / "power-state.json"
        _wait(state.is_file, 10)
        up = _restart_damaged(p, twin, "power", lambda d: _edit(state, lambda s: s[R].update(state=[])))
        said = _said(p, "power state of mapp-1 damaged", "a list")
        rails = _wait(lambda: p.value(keys.rail_state(R, "12V")), 10)
        return Row("power state: [] for a rover", up, said,
                   f"rails as the rover file says ({rails['state'] if rails else '?'})",
                   _up_ok(up) and said != "no")


def case_clock_garbage(lost_time_too: bool = False) -> Row:
    with _twin(POWER_CHAIN) as (p, twin, _):
        _drained(p, POWER_CHAIN, scale=20)
        _wait(lambda: (p.value(keys.clock(R)) or {}).get("t_s", 0) > 100, 30)
        _kill(twin, "clock")
        _wait(lambda: not _live(p, "clock"), 10)
        last = max(c["t_s"] for c in p.samples(keys.clock(R)))
        battery_t = p.value(keys.battery_state(R))["t_s"]
        n = len(p.samples(keys.clock(R)))

        def damage(d: Path) -> None:
            (d / "clock-state.json").write_bytes(b'{"mapp-1": {"state": {"t_s": "lo')
            if lost_time_too:
                (d / "clock-time.json").write_text("garbage")
        damage(twin.state_dir)
        t0 = time.monotonic()
        twin.start("clock")
        up = time.monotonic() - t0 if _wait(lambda: _live(p, "clock"), NEVER_S) else None
        said = _said(p, "clock state of mapp-1 damaged")
        p.put(keys.clock_control(R), {"time_scale": 20})
        moved = _wait(lambda: (p.value(keys.battery_state(R)) or {}).get("t_s", 0) > battery_t + 20, 20)
        after = [c["t_s"] for c in p.samples(keys.clock(R))[n:]]
        back = min(after, default=last) - last
        kept = (f"clock resumed at {min(after, default=0):.1f} s after {last:.1f} s "
                f"({back:+.1f} s); battery {'moving' if moved else 'FROZEN'}")
        label = "clock state: garbage" + (" and its saved time too" if lost_time_too else "")
        return Row(label, up, said, kept, _up_ok(up) and said != "no" and back >= 0 and bool(moved))


def case_clock_garbage_time_lost() -> Row:
    return case_clock_garbage(lost_time_too=True)


def case_restore_damaged_part() -> Row:
    with _twin(("clock", "battery", "loads", "power", "solar", "radio", "faults")) as (p, twin, ep):
        _drained(p, POWER_CHAIN, scale=100)
        p.put(keys.control_snapshot(R, "drill"), b"")
        part = twin.state_dir / "snapshots" / "drill" / "battery-snapshot.json"
        _wait(part.is_file, 10)
        time.sleep(0.5)
        _edit(part, lambda s: s[R]["state"].update(energy_j="lots"))
        epoch = p.value(keys.clock(R))["epoch"]
        t0 = time.monotonic()
        out = subprocess.run([sys.executable, "-m", "lunaris.cli", "snapshot", "restore", R, "drill",
                              "--connect", ep], capture_output=True, text=True, timeout=60, cwd=ROOT)
        took = time.monotonic() - t0
        b0 = p.value(keys.battery_state(R))
        time.sleep(1.0)
        b1 = p.value(keys.battery_state(R))
        same_epoch = p.value(keys.clock(R))["epoch"] == epoch
        draining = b1["energy_j"] < b0["energy_j"]
        said = _short((out.stdout.strip() or out.stderr.strip()).split("] ", 1)[-1])
        kept = (f"exit {out.returncode} in {took:.1f} s; epoch {'unchanged' if same_epoch else 'NEW'}; "
                f"pack {'still draining' if draining else 'NOT draining'}")
        return Row("restore: a battery part damaged", None, said, kept,
                   out.returncode == 1 and "battery part is damaged" in out.stdout and same_epoch
                   and draining)


def _went_back(p: Probe) -> dict[str, tuple[float, float]]:
    prefix = keys.rover_prefix(R) + "/"
    with p._lock:
        items = {k: list(v) for k, v in p.history.items() if k.startswith(prefix) and "/event" not in k}
    out = {}
    for key, values in items.items():
        times = [v["t_s"] for v in values if isinstance(v, dict) and "t_s" in v]
        for a, b in zip(times, times[1:], strict=False):
            if b < a:
                out[key] = (a, b)
                break
    return out


def _kill_all(services: tuple[str, ...], first: tuple[str, ...]) -> Row:
    with _twin(services) as (p, twin, _):
        p.watch(keys.under(R))
        _wait(lambda: all(_live(p, s) for s in services), 30)
        p.put(keys.clock_control(R), {"time_scale": 20})
        p.put(keys.fault(R, "battery", "heating"), 2)
        reached = _wait(lambda: (p.value(keys.clock(R)) or {}).get("t_s", 0) > 100
                        and p.value(keys.clock(R))["t_s"], 30) or 0.0
        for proc in twin.procs.values():
            proc.kill()
        for proc in twin.procs.values():
            proc.wait(10)
        t0 = time.monotonic()
        rest = [s for s in services if s not in first]
        for service in [*first, *random.Random(3).sample(rest, len(rest))]:
            twin.start(service)  # the others before the clock is back
            if service == first[-1] and "clock" not in first:
                _wait(lambda: all(_live(p, s) for s in first), 30)
        back_all = _wait(lambda: all(_live(p, s) for s in services), NEVER_S)
        up = time.monotonic() - t0 if back_all else None
        _wait(lambda: (p.value(keys.battery_state(R)) or {}).get("t_s", 0) > reached + 40, 30)
        back = _went_back(p)
        keys_seen = len([k for k in p.history if "/event" not in k])
        kept = f"{len(back)} of {keys_seen} keys sent t_s back" + (
            f" (e.g. {next(iter(back))} {back[next(iter(back))]})" if back else "")
        return Row(f"kill -9 of {', '.join(services) if len(services) < 5 else 'all services'} at once",
                   up, "-", kept, not back and up is not None)


def case_kill_all() -> Row:
    others = tuple(s for s in EVERYTHING if s != "clock")
    return _kill_all(EVERYTHING, others)


def case_kill_clock_and_battery() -> Row:
    return _kill_all(("clock", "battery"), ("battery",))


def case_two_clocks(rounds: int = 4) -> Row:
    """Two clocks with different state folders started together, ``rounds`` times."""
    doubled = 0
    with running_twin([MAPP], services=()) as (p, _twin, ep), tempfile.TemporaryDirectory() as tmp:
        p.watch(keys.clock(R))
        for n in range(rounds):
            procs = [subprocess.Popen([sys.executable, "-m", "lunaris.cli", "run", "clock", "--rover",
                                       str(MAPP), "--connect", ep, "--state-dir", f"{tmp}/{n}-{i}"],
                                      cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                     for i in range(2)]
            try:
                _wait(lambda ps=procs: any(q.poll() is not None for q in ps), 15)
                before = len(p.samples(keys.clock(R)))
                time.sleep(2.0)  # a measurement window: how many ticks in 2 s
                ticks = len(p.samples(keys.clock(R))) - before
                doubled += ticks > 25 or all(q.poll() is None for q in procs)
            finally:
                for q in procs:
                    if q.poll() is None:
                        q.terminate()
                        q.wait(20)
    return Row(f"two clocks started at once ({rounds} times)", None, "-",
               f"{doubled} of {rounds} starts ran two", doubled == 0)


CASES: dict[str, Callable[[], Row]] = {
    "torn_journal": case_torn_journal,
    "battery_wrong_type": case_battery_wrong_type,
    "battery_nan": case_battery_nan,
    "battery_truncated": case_battery_truncated,
    "battery_folder": case_battery_folder,
    "fault_out_of_range": case_fault_out_of_range,
    "faults_garbage": case_faults_garbage,
    "power_state_list": case_power_state_list,
    "clock_garbage": case_clock_garbage,
    "clock_garbage_time_lost": case_clock_garbage_time_lost,
    "restore_damaged_part": case_restore_damaged_part,
    "kill_all": case_kill_all,
    "kill_clock_and_battery": case_kill_clock_and_battery,
    "two_clocks": case_two_clocks,
}


def print_table(rows: list[Row]) -> None:
    print(f"{'case':<42} {'up':>7}  {'ok':<4} said / kept")
    for r in rows:
        up = "-" if r.up_s is None and r.case.startswith(("restore", "two")) else (
            "never" if r.up_s is None else f"{r.up_s:.1f} s")
        print(f"{r.case:<42} {up:>7}  {'yes' if r.ok else 'NO':<4} {r.said}")
        print(f"{'':<42} {'':>7}        {r.kept}")


def run(names: list[str]) -> list[Row]:
    rows = []
    for name in names:
        t0 = time.monotonic()
        try:
            if name == "battery_other_rover_kept":
                with tempfile.TemporaryDirectory() as tmp:
                    row = case_battery_other_rover_kept(Path(tmp))
            else:
                row = CASES[name]()
        except Exception as exc:  # a figure, not a crash of the whole bench
            row = Row(name, None, "no", f"the case failed: {type(exc).__name__}: {exc}", False)
        print(f"  {name}: {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
        rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    names = [*CASES, "battery_other_rover_kept"]
    ap.add_argument("--only", nargs="*", choices=names, help="run only these cases")
    args = ap.parse_args()
    print(machine())
    rows = run(args.only or names)
    print_table(rows)
    print(f"{sum(r.ok for r in rows)} of {len(rows)} cases met every target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
