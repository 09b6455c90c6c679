"""Driving from the console (issue 26.3) and the radio that follows the drive (26.2), against a
twin that drives: the MAPP rover (its lander radio at a site follows the drive) and the LTV
without its drive section (its radios take the position input).

- ``GET /api/traverses`` lists the shipped traverse files and a folder's, checked, with their
  waypoints (and a plan from where the rover is, given its rover file);
  ``POST /api/rovers/<rover>/traverse`` sends one through the writer and answers as every write;
- ``GET /api/rovers`` says which radios follow the drive, from the rover files or, without
  them, as far as the twin's liveliness tells;
- ``lunaris input ... radio/<radio>/position`` on a radio that follows the drive is refused by
  the twin, and the command says where to drive the rover instead; on a rover that does not
  drive it is accepted.
"""

from __future__ import annotations

import math
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh

from common import keys
from common.config import load_rover
from common.connection import make_config
from common.traverse import length_and_duration, load_traverse, plan
from lunaris.console.auth import Accounts
from lunaris.console.rovers import RoverFiles
from lunaris.console.server import make_app
from tests.console.test_server import client, wait_rover
from tests.harness import (
    ROOT,
    ROVERS,
    Probe,
    Twin,
    env_without_zenoh_config,
    free_endpoint,
    lunaris_cmd,
    open_router,
    rover_without_drive,
    wait_for,
)

pytestmark = pytest.mark.timeout(180)

R, LTV = "mapp-1", "ltv-1"
SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "faults", "drive")
SHORT = """\
traverse: {name: A few metres east, description: out and stop}
speed_m_per_s: 0.05
waypoints:
  - {x_m: 8, y_m: 0, z_m: 0}
"""


class Live:
    def __init__(self, endpoint: str, probe: Probe, files: list[Path], folder: Path):
        self.endpoint, self.probe, self.files, self.folder = endpoint, probe, files, folder


@pytest.fixture(scope="module")
def live(tmp_path_factory) -> Iterator[Live]:
    endpoint = free_endpoint()
    router = open_router(endpoint)
    ltv = rover_without_drive(ROVERS / "ltv.yaml", tmp_path_factory.mktemp("rovers"))
    files = [ROVERS / "mapp.yaml", ltv]
    try:
        with Twin(endpoint, files, tmp_path_factory.mktemp("twin"), services=SERVICES), \
                Probe(endpoint) as p:
            p.watch("lunaris/**")
            p.wait_services(R, SERVICES)
            p.wait_services(LTV, tuple(s for s in SERVICES if s != "drive"))
            p.wait_value(keys.drive_state(R))
            p.wait_value(keys.radio_link(R, "lander"))
            yield Live(endpoint, p, files, tmp_path_factory.mktemp("traverses"))
    finally:
        router.close()


@pytest.fixture
def session(live) -> Iterator[zenoh.Session]:
    s = zenoh.open(make_config("client", connect=[live.endpoint]))
    try:
        yield s
    finally:
        s.close()


def _radios(answer: dict, rover: str) -> dict[str, dict]:
    (entry,) = [r for r in answer["rovers"] if r["id"] == rover]
    return {r["name"]: r for r in entry["radios"]}


# -- 26.2: which radios follow the drive ------------------------------------------------------------


def test_the_rovers_radios_that_follow_the_drive_from_the_rover_files(live, session):
    app = make_app(session, None, rover_files=RoverFiles(live.files))
    with client(app) as c:
        wait_rover(app)
        wait_for(lambda: len(_radios(c.get("/api/rovers").json(), LTV)) == 2, 10, "the LTV's radios")
        answer = c.get("/api/rovers").json()
        (mapp,) = [r for r in answer["rovers"] if r["id"] == R]
        assert mapp["drives"] is True and mapp["rover_file"].endswith("mapp.yaml")
        lander = _radios(answer, R)["lander"]
        assert lander["follows_drive"] is True and lander["site"] == {"x_m": 0.0, "y_m": 0.0}
        assert (lander["a_m"], lander["b_m"]) == (400.0, 250.0)
        assert "move the rover with a traverse" in lander["why"]
        (ltv,) = [r for r in answer["rovers"] if r["id"] == LTV]
        assert ltv["drives"] is False
        assert {n: r["follows_drive"] for n, r in _radios(answer, LTV).items()} == {
            "lander": False, "hls_relay": False}
        assert _radios(answer, LTV)["lander"]["why"] == "the radio's telemetry says so"


def test_without_rover_files_the_console_learns_the_radios_from_their_telemetry(live, session):
    app = make_app(session, None)
    with client(app) as c:
        wait_rover(app)
        wait_for(lambda: "lander" in _radios(c.get("/api/rovers").json(), R)
                 and len(_radios(c.get("/api/rovers").json(), LTV)) == 2, 10, "the radios' telemetry")
        answer = c.get("/api/rovers").json()
        (mapp,) = [r for r in answer["rovers"] if r["id"] == R]
        assert mapp["drives"] is True and mapp["drives_why"] == "the twin's drive service serves it"
        lander = _radios(answer, R)["lander"]  # the radio's telemetry says it all
        assert lander["follows_drive"] is True and "the radio's telemetry says so" in lander["why"]
        assert lander["site"] == {"x_m": 0.0, "y_m": 0.0} and (lander["a_m"], lander["b_m"]) == (400.0, 250.0)
        assert {n: r["follows_drive"] for n, r in _radios(answer, LTV).items()} == {
            "lander": False, "hls_relay": False}


def test_lunaris_input_says_where_to_drive_the_rover_instead(live):
    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(lunaris_cmd(*args, "--connect", live.endpoint), capture_output=True, text=True,
                              timeout=60, cwd=ROOT, env=env_without_zenoh_config())
    drive = live.probe.value(keys.drive_state(R))
    done = run("input", R, "radio/lander/position", "300", "45")
    said = done.stdout + done.stderr
    assert done.returncode == 1, said
    assert "follows the rover's drive" in said
    # The lander stands at the site's origin: 300 m at 45 deg is (212.1, 212.1).
    x = y = 300 * math.cos(math.radians(45))
    assert f"drive it there: lunaris traverse {R} --to {x:.1f} {y:.1f} {drive['z_m']:.1f}" in said, said
    assert "counter-clockwise from east" in said and "Traceback" not in said
    done = run("input", LTV, "radio/lander/position", "300", "45")  # a rover that does not drive
    assert done.returncode == 0, done.stdout + done.stderr
    assert "accepted: input" in done.stdout and "300 m at 45 deg" in done.stdout


# -- 26.3: traverses from the console ----------------------------------------------------------------


def test_the_traverse_files_are_listed_checked_and_planned(live, session):
    (live.folder / "short.yaml").write_text(SHORT)
    (live.folder / "broken.yaml").write_text("traverse: {name: x}\nwaypoints: [{x_m: 1}]\n")
    (live.folder / "mapp-crater-rim.yaml").write_text(SHORT)  # the shipped one's name
    (live.folder / "notes.txt").write_text("not a traverse")
    app = make_app(session, None, traverse_dirs=[live.folder], rover_files=RoverFiles(live.files))
    with client(app) as c:
        wait_rover(app)
        answer = c.get("/api/traverses").json()
        listed = {(Path(t["folder"]).name, t["file"]): t for t in answer["traverses"]}
        shipped = listed[("traverses", "mapp-crater-rim.yaml")]
        tf = load_traverse(ROOT / "config" / "traverses" / "mapp-crater-rim.yaml")
        assert shipped["problems"] == [] and shipped["name"] == tf.traverse.name
        assert shipped["waypoints"] == msgspec.to_builtins(tf.waypoints)
        assert shipped["return_to_start"] is True
        assert ("traverses", "ltv-crater-rim.yaml") in listed
        mine = {t["file"]: t for t in answer["traverses"] if t["folder"] == str(live.folder.resolve())}
        assert set(mine) == {"short.yaml", "broken.yaml", "mapp-crater-rim.yaml"}
        assert mine["short.yaml"]["problems"] == [] and mine["short.yaml"]["speed_m_per_s"] == 0.05
        assert any("z_m" in p for p in mine["broken.yaml"]["problems"])
        assert "has the same name" in mine["mapp-crater-rim.yaml"]["problems"][0]

        planned = {t["file"]: t for t in c.get(f"/api/traverses?rover={R}").json()["traverses"]
                   if t["folder"] == str(live.folder.resolve())}
        drive = live.probe.value(keys.drive_state(R))
        at = (drive["x_m"], drive["y_m"], drive["z_m"])
        legs, _ = plan(load_traverse(live.folder / "short.yaml").command(),
                       load_rover(ROVERS / "mapp.yaml").drive, at)
        length, duration = length_and_duration(at, legs)
        got = planned["short.yaml"]["plan"]
        assert got["from"] == "where the rover is" and got["problems"] == []
        assert got["length_m"] == pytest.approx(length, abs=0.05) and got["duration_s"] == pytest.approx(
            duration, abs=1.0)
        assert "plan" not in planned["broken.yaml"]
        assert c.get(f"/api/traverses?rover={LTV}").json()["plan_missing"] == f"{LTV} does not drive"


def _put_seen(p: Probe, key: str, since: int) -> list[Any]:
    return p.samples(key)[since:]


def test_a_traverse_file_is_sent_from_the_console_and_answered_by_the_drive(live, session, tmp_path):
    (live.folder / "short.yaml").write_text(SHORT)
    p = live.probe
    key = keys.input_drive_traverse(R)
    app = make_app(session, None, traverse_dirs=[live.folder])
    with client(app) as c:
        wait_rover(app)
        seen = len(p.samples(key))
        r = c.post(f"/api/rovers/{R}/traverse", json={"file": "short.yaml", "return_to_start": True})
        assert r.status_code == 200, r.text
        answer = r.json()
        assert answer["verdict"] == "accepted" and answer["event"]["kind"] == "input"
        assert answer["event"]["source"] == "drive"
        sent = wait_for(lambda: _put_seen(p, key, seen), 5, "the traverse on its key")
        expected = load_traverse(live.folder / "short.yaml").command()
        assert sent[0] == msgspec.to_builtins(msgspec.structs.replace(expected, return_to_start=True))
        stop = c.delete(f"/api/rovers/{R}/keys/input/drive/traverse")
        assert stop.status_code == 200, stop.text

        for body, words in [({"file": "nowhere.yaml"}, "no traverse file 'nowhere.yaml'"),
                            ({"fil": "short.yaml"}, "not sent: "),
                            ({"file": "short.yaml", "speed_m_per_s": -1}, "speed_m_per_s must be")]:
            r = c.post(f"/api/rovers/{R}/traverse", json=body)
            assert r.status_code == 422 and words in r.json()["message"], (body, r.text)
            assert "$." not in r.json()["message"] and "`" not in r.json()["message"]

    users = tmp_path / "users.json"
    Accounts.add(users, "obi", "observer", "lander-side-observer")
    app = make_app(session, Accounts(users), traverse_dirs=[live.folder])
    with client(app) as c:
        c.post("/login", data={"user": "obi", "password": "lander-side-observer", "next": "/"})
        assert c.get("/api/traverses").status_code == 200  # an observer reads
        seen = len(p.samples(key))
        r = c.post(f"/api/rovers/{R}/traverse", json={"file": "short.yaml"})
        assert r.status_code == 403 and "observer" in r.json()["message"]
    assert len(p.samples(key)) == seen
