"""A site of several routers from one description (deploy/site.yaml, SPEC §12f).

The description is checked in words; ``lunaris deploy secrets|acl|check --site`` make and
check each router's folder (its identity, certificate under the one CA, dictionary,
clients, configuration); rotation covers the routers' identities and nothing is left
behind unnoticed. Three routers then run on loopback from their generated configurations
(``lunaris router --config``), linked with mutual TLS: a client's samples cross the links
as each router's access control allows, and neither a router's password alone nor a
certificate the CA did not sign makes a router.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from common import keys
from lunaris.deploy_secrets import make_ca, make_certificate
from lunaris.deploy_site import SiteError, load_site
from lunaris.processes import lunaris_cmd, wait_for
from testbed.deployment import (
    REPO,
    Processes,
    Tap,
    open_as,
    run_lunaris,
    start_router,
)
from tests.deploy.conftest import free_port, read_credentials

pytestmark = pytest.mark.timeout(180)

MAPP = REPO / "config" / "rovers" / "mapp.yaml"
SITE = REPO / "deploy" / "site.yaml"


def test_the_shipped_site_is_three_machines_whose_secrets_check(tmp_path: Path) -> None:
    site = load_site(SITE)
    assert [r.name for r in site.routers] == ["ground", "mapp-1", "crew"]
    out = run_lunaris("deploy", "secrets", str(tmp_path / "s"), "--site", str(SITE))
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "s"
    assert run_lunaris("deploy", "check", str(folder), "--site", str(SITE)).returncode == 0
    for router in site.routers:  # what each machine holds, checked alone as its preflight does
        out = run_lunaris("deploy", "check", str(folder / router.name), "--site", str(SITE),
                          "--router", router.name)
        assert out.returncode == 0, out.stderr
        dictionary = read_credentials(folder / router.name / "credentials.txt")
        linking = [f"router-{r.name}" for r in site.routers if router.name in r.connect]
        assert list(dictionary) == [*router.clients, *linking]
        assert sorted(p.name for p in (folder / router.name).glob("client-*.json5")) == sorted(
            f"client-{c}.json5" for c in router.clients)
    assert not (folder / "ground" / "tls" / "ca.key").exists()  # the CA's key stays home
    ground = (folder / "ground" / "zenohd.json5").read_text()
    assert '"password"' not in ground  # it opens no link: no secret in its configuration
    crew = json.loads("\n".join(line for line in (folder / "crew" / "zenohd.json5").read_text()
                                .splitlines() if not line.startswith("//")))
    retry = "retry_period_init_ms=500;retry_period_max_ms=1000"
    assert crew["connect"]["endpoints"] == [
        f"tls/ground.lunaris.example:7448#enable_mtls=true;{retry}",
        f"tls/mapp-1.lunaris.example:7448#enable_mtls=true;{retry}"]
    assert crew["transport"]["link"]["tx"]["lease"] == 3000
    assert crew["transport"]["auth"]["usrpwd"]["user"] == "router-crew"


@pytest.mark.parametrize(("change", "words"), [
    ("connect: [ground]", "connect: no router is named 'grund'"),
    ("runs: [bridge]", "runs: 'brigde' is not a Lunaris service or the console"),
    ("people: [dashboard, observer]", "people: 'console' is not a person's identity"),
])
def test_a_site_description_is_checked_in_words(tmp_path: Path, change: str, words: str) -> None:
    bad = {"connect: [ground]": "connect: [grund]", "runs: [bridge]": "runs: [brigde]",
           "people: [dashboard, observer]": "people: [dashboard, console]"}[change]
    text = SITE.read_text().replace(change, bad, 1)
    path = tmp_path / "site.yaml"
    path.write_text(text)
    with pytest.raises(SiteError) as err:
        load_site(path)
    assert any(words in p for p in err.value.problems), err.value.problems


def test_every_service_runs_somewhere_and_every_router_is_reached(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(textwrap.dedent("""\
        rovers: [config/rovers/mapp.yaml]
        routers:
          - {name: a, hosts: [a.example], runs: [faults]}
          - {name: c, hosts: [c.example], runs: [faults]}
          - {name: b, hosts: [b.example], runs: [clock]}
        """))
    with pytest.raises(SiteError) as err:
        load_site(path)
    problems = "\n".join(err.value.problems)
    assert "no machine runs the battery service" in problems
    assert "the faults runs on one machine only (not a, c)" in problems
    assert "every router must be reached through the links" in problems


def test_rotating_a_router_renews_its_password_key_and_certificate_everywhere(tmp_path: Path) -> None:
    folder = tmp_path / "s"
    assert run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE)).returncode == 0
    before = read_credentials(folder / "credentials.txt")
    key = (folder / "mapp-1" / "tls" / "router.key").read_bytes()
    old = tmp_path / "old-mapp-1"
    shutil.copytree(folder / "mapp-1", old)
    out = run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE), "--rotate", "router-mapp-1")
    assert out.returncode == 0, out.stderr
    after = read_credentials(folder / "credentials.txt")
    assert after["router-mapp-1"] != before["router-mapp-1"]
    assert {k: v for k, v in after.items() if k != "router-mapp-1"} == \
        {k: v for k, v in before.items() if k != "router-mapp-1"}
    assert (folder / "mapp-1" / "tls" / "router.key").read_bytes() != key
    # the router it opens a link to knows the new password; its own configuration holds it
    assert read_credentials(folder / "ground" / "credentials.txt")["router-mapp-1"] == after["router-mapp-1"]
    assert after["router-mapp-1"] in (folder / "mapp-1" / "zenohd.json5").read_text()
    assert run_lunaris("deploy", "check", str(folder), "--site", str(SITE)).returncode == 0
    # the old folder put back on the machine: its password is not the site's any more
    shutil.rmtree(folder / "mapp-1")
    shutil.copytree(old, folder / "mapp-1")
    out = run_lunaris("deploy", "check", str(folder), "--site", str(SITE))
    assert out.returncode == 1
    assert "mapp-1/zenohd.json5: its password is not the site's for router-mapp-1" in out.stderr


def test_a_rotation_says_which_folders_changed_and_what_to_restart_in_order(tmp_path: Path) -> None:
    """--rotate listed every folder as written even when only the ground's changed (issue 33.6)."""
    folder = tmp_path / "s"
    assert run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE)).returncode == 0
    out = run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE), "--rotate", "instructor")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "changed: ground/ (the client file of instructor, its dictionary)", out.stdout
    assert lines[1] == "unchanged: mapp-1/, crew/ (nothing to copy there)"
    assert lines[2:] == ["copy ground/ to its machine, then restart, in this order:",
                         "  1. the router of ground (ground-router)",
                         "  2. the tools of instructor on ground (they read it when they start)"]
    # a router rotated: the ground learns its new password before the rover's router shows it
    out = run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE), "--rotate", "router-mapp-1")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == [
        "changed: ground/ (its dictionary); mapp-1/ (its certificate, its key, its configuration)",
        "unchanged: crew/ (nothing to copy there)",
        "copy ground/, mapp-1/ to their machines, then restart, in this order:",
        "  1. the router of ground (ground-router)",
        "  2. the router of mapp-1 (mapp-1-router)"], out.stdout
    out = run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE))
    assert out.stdout.strip() == "nothing changed in the machines' folders: nothing to copy or restart"


def test_nothing_is_left_behind_unnoticed(tmp_path: Path) -> None:
    folder = tmp_path / "s"
    assert run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE)).returncode == 0
    with (folder / "ground" / "credentials.txt").open("a") as f:
        f.write("router-old:an-old-routers-password-123\n")
    with (folder / "credentials.txt").open("a") as f:
        f.write("mallory:x\n")
    shutil.copytree(folder / "crew", folder / "old-crew")
    crew = folder / "crew" / "zenohd.json5"
    crew.write_text(crew.read_text().replace('"default_permission": "deny"',
                                             '"default_permission": "allow"'))
    out = run_lunaris("deploy", "check", str(folder), "--site", str(SITE))
    assert out.returncode == 1
    for words in ("ground/credentials.txt: 'router-old' (line",
                  "credentials.txt: 'mallory' (line",
                  "old-crew/: the folder of a router",
                  "crew/zenohd.json5: not the configuration"):
        assert words in out.stderr, out.stderr
    acl = run_lunaris("deploy", "acl", "--site", str(SITE), "--output", str(folder), "--check")
    assert acl.returncode == 1 and "crew/zenohd.json5 is stale" in acl.stderr


def test_a_machines_folder_holds_what_it_needs_and_nothing_more(tmp_path: Path) -> None:
    """The CA's key in the ground's folder, the instructor's client file on the crew's host,
    another router's key: each refused by the site's check and by the machine's own preflight,
    named with why (issue 33.5)."""
    folder = tmp_path / "s"
    assert run_lunaris("deploy", "secrets", str(folder), "--site", str(SITE)).returncode == 0
    shutil.copy(folder / "ca" / "ca.key", folder / "ground" / "tls" / "ca.key")
    shutil.copy(folder / "ground" / "client-instructor.json5", folder / "crew")
    shutil.copy(folder / "mapp-1" / "tls" / "router.key", folder / "crew" / "mapp-1.key")
    out = run_lunaris("deploy", "check", str(folder), "--site", str(SITE))
    assert out.returncode == 1
    for words in ("ground/tls/ca.key: the site's CA's private key: with it anyone makes a router",
                  "crew/client-instructor.json5: the identity instructor does not connect to the "
                  "router crew (it connects to ground): whoever reads this machine would have its "
                  "password",
                  "crew/mapp-1.key: a private key this machine does not need"):
        assert words in out.stderr, out.stderr
    assert "mapp-1/" not in out.stderr.replace("crew/mapp-1.key", "")  # its folder is as made
    for router, words in (("ground", "tls/ca.key: the site's CA's private key"),
                          ("crew", "client-instructor.json5: the identity instructor does not")):
        alone = run_lunaris("deploy", "check", str(folder / router), "--site", str(SITE),
                            "--router", router)
        assert alone.returncode == 1 and words in alone.stderr, alone.stderr
    for extra in ("ground/tls/ca.key", "crew/client-instructor.json5", "crew/mapp-1.key"):
        (folder / extra).unlink()
    out = run_lunaris("deploy", "check", str(folder), "--site", str(SITE))
    assert out.returncode == 0, out.stderr


def _lunaris_in(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "LUNARIS_ZENOH_CONFIG"}
    return subprocess.run(lunaris_cmd(*args), cwd=cwd, capture_output=True, text=True, timeout=120,
                          env=env)


def test_any_spelling_of_the_site_files_path_checks_the_same(tmp_path: Path) -> None:
    """The routers' configurations named the site file as it was typed: a site made as
    deploy/site.yaml and checked as ./deploy/site.yaml or by its absolute path refused every
    router (issue 33.4). A site of one's own (outside the repository) and the shipped one."""
    own = tmp_path / "own"
    (own / "deploy").mkdir(parents=True)
    (own / "deploy" / "site.yaml").write_text(SITE.read_text().replace("config/rovers/mapp.yaml", str(MAPP)))
    made = _lunaris_in(own, "deploy", "secrets", "s", "--site", "deploy/site.yaml")
    assert made.returncode == 0, made.stderr
    for spelling in ("./deploy/site.yaml", str(own / "deploy" / "site.yaml"), "deploy/../deploy/site.yaml"):
        out = _lunaris_in(own, "deploy", "check", "s", "--site", spelling)
        assert out.returncode == 0, (spelling, out.stderr)
        out = _lunaris_in(own, "deploy", "check", "s/crew", "--site", spelling, "--router", "crew")
        assert out.returncode == 0, (spelling, out.stderr)
    # the shipped site, in the repository: made by its absolute path, checked as typed in it
    folder = tmp_path / "shipped"
    assert _lunaris_in(tmp_path, "deploy", "secrets", str(folder), "--site", str(SITE)).returncode == 0
    for spelling in ("deploy/site.yaml", "./deploy/site.yaml"):
        out = _lunaris_in(REPO, "deploy", "check", str(folder), "--site", spelling)
        assert out.returncode == 0, (spelling, out.stderr)
    assert "of the Lunaris site deploy/site.yaml." in (folder / "ground" / "zenohd.json5").read_text()


# -- three routers on loopback, linked -------------------------------------------------------


def _site(folder: Path) -> Path:
    """The shipped site's shape on loopback: every machine 127.0.0.1, ports of its own."""
    ports = {name: (free_port(), free_port()) for name in ("ground", "mapp-1", "crew")}
    text = SITE.read_text().replace("config/rovers/mapp.yaml", str(MAPP))
    for name, (client, router) in ports.items():
        text = text.replace(f"hosts: [{name}.lunaris.example]",
                            f"hosts: [127.0.0.1]\n    client_port: {client}\n"
                            f"    router_port: {router}")
    path = folder / "site.yaml"
    path.write_text(text)
    return path


class Loopback:
    def __init__(self, folder: Path, site: Path):
        self.folder, self.site = folder, load_site(site)
        self.secrets = folder / "secrets"
        self.sessions: list[zenoh.Session] = []

    def open(self, router: str, identity: str) -> zenoh.Session:
        session = open_as(self.secrets / router, identity)
        self.sessions.append(session)
        return session


@pytest.fixture(scope="module")
def loopback(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Loopback]:
    folder = tmp_path_factory.mktemp("site")
    site = _site(folder)
    out = run_lunaris("deploy", "secrets", str(folder / "secrets"), "--site", str(site),
                      "--secrets-dir", str(folder / "secrets"))
    assert out.returncode == 0, out.stderr
    lb = Loopback(folder, site)
    procs = Processes(folder / "logs")
    try:
        for spec in lb.site.routers:
            listen = [f"tls/127.0.0.1:{spec.client_port}"]
            if lb.site.linked_from(spec.name):
                listen.append(f"tls/127.0.0.1:{spec.router_port}#enable_mtls=true")
            start_router(procs, spec.name, folder / "secrets" / spec.name / "zenohd.json5", listen)
        yield lb
    finally:
        for session in lb.sessions:
            session.close()
        procs.stop_all()
        print(procs.tails())


def test_samples_cross_the_links_as_each_routers_access_control_allows(loopback: Loopback) -> None:
    battery = loopback.open("mapp-1", "lunaris-battery")
    debrief, instructor = loopback.open("ground", "debrief"), loopback.open("ground", "instructor")
    observer, dashboard = loopback.open("crew", "observer"), loopback.open("crew", "dashboard")
    seen = {who: Tap() for who in ("debrief", "observer", "battery")}
    subs = [debrief.declare_subscriber("lunaris/*/faults/active/*", seen["debrief"]),
            debrief.declare_subscriber("lunaris/*/battery/state", seen["debrief"]),
            observer.declare_subscriber("lunaris/**", seen["observer"]),
            battery.declare_subscriber("lunaris/*/fault/battery/**", seen["battery"])]
    state = battery.declare_publisher(keys.battery_state("mapp-1"))
    active = battery.declare_publisher(keys.faults_active("mapp-1", "battery"))
    fault = instructor.declare_publisher(keys.fault("mapp-1", "battery", "heating"))
    for pub, what in ((state, "the battery to learn of the ground's and the crew's subscribers"),
                      (active, "the battery to learn of the debrief's wildcard subscriber"),
                      (fault, "the instructor to learn of the battery's subscriber on mapp-1")):
        wait_for(lambda p=pub: p.matching_status.matching, 30, what)
    dashboard.put(keys.fault("mapp-1", "battery", "heating"), b"99")  # refused by crew
    for i in range(5):
        state.put(json.dumps({"t_s": i}))
        active.put(json.dumps({"faults": [], "t_s": i}))
    fault.put(b"40")
    wait_for(lambda: len(seen["debrief"].samples()) >= 10, 20,
               lambda: f"ten samples of mapp-1 at the ground (got {seen['debrief'].samples()})")
    wait_for(lambda: len(seen["observer"].samples()) >= 5, 20, "five at the crew")
    wait_for(lambda: seen["battery"].payloads(keys.fault("mapp-1", "battery", "heating")), 20,
               "the instructor's fault on the rover")
    assert {k for k, _, _ in seen["observer"].samples()} == {keys.battery_state("mapp-1")}
    assert seen["battery"].payloads(keys.fault("mapp-1", "battery", "heating")) == [b"40"]
    del subs


def test_a_routers_password_alone_or_a_foreign_certificate_is_no_router(
        loopback: Loopback, tmp_path: Path) -> None:
    """A client showing router-crew's user and password on the ground's clients' port gets
    a session (the dictionary knows the name) but no rights; a router whose certificate the
    deployment's CA did not sign gets no link."""
    creds = read_credentials(loopback.secrets / "credentials.txt")
    ground = loopback.site.router("ground")
    conf = json.loads((loopback.secrets / "ground" / "client-instructor.json5").read_text())
    conf["transport"]["auth"]["usrpwd"] = {"user": "router-crew", "password": creds["router-crew"]}
    path = tmp_path / "pretender.json5"
    path.write_text(json.dumps(conf))
    pretender = zenoh.open(zenoh.Config.from_file(str(path)))
    loopback.sessions.append(pretender)
    battery = loopback.open("mapp-1", "lunaris-battery")
    got = Tap()
    sub = battery.declare_subscriber("lunaris/*/fault/**", got)
    pretender.put(keys.fault("mapp-1", "battery", "heating"), b"pretender")
    list(pretender.liveliness().get("lunaris/*/service/*", timeout=2.0))  # the router dealt with it
    instructor = loopback.open("ground", "instructor")
    instructor.put(keys.fault("mapp-1", "battery", "capacity_loss"), b"0.1")  # the control
    wait_for(lambda: got.samples(), 20, "the instructor's fault (the control)")
    assert [p for _, p, _ in got.samples()] == [b"0.1"]

    # a fourth router, its certificate from another CA under the crew's name
    other = tmp_path / "other"
    make_ca(other)
    make_certificate(other, other, "router-crew", ["127.0.0.1"], linked=True)
    rogue = {
        "mode": "router", "listen": {"endpoints": [f"tls/127.0.0.1:{free_port()}"]},
        "connect": {"endpoints": [f"tls/127.0.0.1:{ground.router_port}#enable_mtls=true"]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"auth": {"usrpwd": {"user": "router-crew", "password": creds["router-crew"]}},
                      "link": {"tls": {
                          "root_ca_certificate": str(loopback.secrets / "ground" / "tls" / "ca.crt"),
                          "listen_certificate": str(other / "router.crt"),
                          "listen_private_key": str(other / "router.key"),
                          "connect_certificate": str(other / "router.crt"),
                          "connect_private_key": str(other / "router.key")}}},
    }
    router = zenoh.open(zenoh.Config.from_json5(json.dumps(rogue)))
    try:
        injected = router.declare_publisher(keys.fault("mapp-1", "battery", "disconnect"))
        for _ in range(20):  # two seconds of a rogue router trying
            injected.put(b"")
            list(router.liveliness().get("lunaris/*/service/*", timeout=0.1))
        assert not injected.matching_status.matching
        assert [p for _, p, _ in got.samples()] == [b"0.1"]
    finally:
        router.close()
    # the control: the same router with the crew's own certificate is a router
    tls = rogue["transport"]["link"]["tls"]
    for end in ("listen", "connect"):
        tls[f"{end}_certificate"] = str(loopback.secrets / "crew" / "tls" / "router.crt")
        tls[f"{end}_private_key"] = str(loopback.secrets / "crew" / "tls" / "router.key")
    router = zenoh.open(zenoh.Config.from_json5(json.dumps(rogue)))
    try:
        genuine = router.declare_publisher(keys.fault("mapp-1", "battery", "resistance"))
        wait_for(lambda: genuine.matching_status.matching, 20, "the genuine router's link")
    finally:
        router.close()
    del sub
