"""A deployment's secrets: made, checked, rotated; demo passwords refused everywhere."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from common.connection import ConnectionConfigError, make_config
from lunaris.deploy import IDENTITIES, MIN_PASSWORD_LEN, check_secrets, make_secrets
from tests.deploy.conftest import REPO, read_credentials, running_router

pytestmark = pytest.mark.timeout(60)


def lunaris(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lunaris.cli", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def test_the_secrets_are_random_private_and_complete(tmp_path: Path) -> None:
    out = lunaris("deploy", "secrets", str(tmp_path / "s"), "--host", "localhost", "--host", "127.0.0.1")
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "s"
    creds = read_credentials(folder / "credentials.txt")
    assert set(creds) == set(IDENTITIES)
    assert len(set(creds.values())) == len(IDENTITIES)
    assert all(len(p) >= MIN_PASSWORD_LEN for p in creds.values())
    for path in [folder / "credentials.txt", folder / "tls" / "router.key", folder / "tls" / "ca.key",
                 *folder.glob("client-*.json5")]:
        assert path.stat().st_mode & 0o077 == 0, f"{path} is readable by others"
    assert check_secrets(folder) == []
    assert lunaris("deploy", "check", str(folder)).returncode == 0


def test_the_secrets_are_made_in_a_folder_given_relative_to_where_it_runs(tmp_path: Path) -> None:
    """As the README says it (``lunaris deploy secrets deploy/secrets ...``), run from the
    folder above. Found: openssl ran in the certificate's folder with the CA's relative path,
    and both forms failed ("Could not open file ... deploy/secrets/ca/ca.crt")."""
    site = tmp_path / "site.yaml"
    shutil.copy(REPO / "deploy" / "site.yaml", site)
    for args in (("one", "--host", "127.0.0.1"), ("three", "--site", str(site))):
        out = subprocess.run([sys.executable, "-m", "lunaris.cli", "deploy", "secrets", *args],
                             cwd=tmp_path, capture_output=True, text=True, timeout=60,
                             env={**os.environ, "PYTHONPATH": str(REPO)})
        assert out.returncode == 0, out.stderr
    assert check_secrets(tmp_path / "one") == []
    assert lunaris("deploy", "check", str(tmp_path / "three"), "--site", str(site)).returncode == 0


def test_demo_passwords_are_refused_by_the_check_and_by_every_client(tmp_path: Path) -> None:
    folder = tmp_path / "s"
    make_secrets(folder, ["localhost"], "tls/127.0.0.1:7447")
    config = json.loads((folder / "client-instructor.json5").read_text())
    config["transport"]["auth"]["usrpwd"]["password"] = "demo-instructor-CHANGE-ME"
    (folder / "client-instructor.json5").write_text(json.dumps(config))
    creds = read_credentials(folder / "credentials.txt")
    creds["instructor"] = "demo-instructor-CHANGE-ME"
    (folder / "credentials.txt").write_text("".join(f"{u}:{p}\n" for u, p in creds.items()))
    out = lunaris("deploy", "check", str(folder))
    assert out.returncode == 1 and "instructor still has a shipped demo password" in out.stderr
    assert "REFUSED" in out.stderr
    with pytest.raises(ConnectionConfigError, match="demo password"):
        make_config(config_file=folder / "client-instructor.json5")
    run = lunaris("fault", "list", "mapp-1", "--config", str(folder / "client-instructor.json5"))
    assert run.returncode != 0 and "demo password" in run.stderr


def test_a_missing_or_mismatched_secret_is_refused(tmp_path: Path) -> None:
    assert "missing" in check_secrets(tmp_path / "nothing")[0]
    folder = tmp_path / "s"
    make_secrets(folder, ["localhost"], "tls/127.0.0.1:7447")
    (folder / "client-lunaris-clock.json5").unlink()
    (folder / "tls" / "router.key").unlink()
    problems = check_secrets(folder)
    assert "client-lunaris-clock.json5: missing" in problems and "tls/router.key: missing" in problems


def test_rotating_one_password_leaves_the_others_and_locks_out_the_old(tmp_path: Path) -> None:
    folder = tmp_path / "s"
    make_secrets(folder, ["localhost", "127.0.0.1"], "tls/127.0.0.1:7447")
    before = read_credentials(folder / "credentials.txt")
    old = tmp_path / "old-observer.json5"
    shutil.copy(folder / "client-observer.json5", old)
    out = lunaris("deploy", "secrets", str(folder), "--rotate", "observer")
    assert out.returncode == 0, out.stderr
    after = read_credentials(folder / "credentials.txt")
    assert after["observer"] != before["observer"]
    assert {u: p for u, p in after.items() if u != "observer"} == \
        {u: p for u, p in before.items() if u != "observer"}
    assert check_secrets(folder) == []
    with running_router(folder) as router:
        zenoh.open(router.client_config(base=folder / "client-observer.json5", fail_fast=True)).close()
        with pytest.raises(zenoh.ZError):
            zenoh.open(router.client_config(base=old, fail_fast=True)).close()
    assert lunaris("deploy", "secrets", str(folder), "--rotate", "nobody").returncode == 2


def test_a_refused_password_is_said_as_refused_not_as_no_router(tmp_path: Path) -> None:
    """A wrong or rotated password read "No Zenoh router answered ... start the twin with make
    run" though the router answered and refused it (issue 33.7): said as refused, naming the
    user; the current file connects; a stopped router is still "no router answered"."""
    folder = tmp_path / "s"
    make_secrets(folder, ["localhost", "127.0.0.1"], "tls/127.0.0.1:7447")
    old = tmp_path / "old-instructor.json5"
    shutil.copy(folder / "client-instructor.json5", old)
    assert lunaris("deploy", "secrets", str(folder), "--rotate", "instructor").returncode == 0

    def fault_list(config: Path, endpoint: str) -> subprocess.CompletedProcess:
        return lunaris("fault", "list", "mapp-1", "--config", str(config), "--connect", endpoint,
                       "--wait", "2", "--timeout", "0.5")
    with running_router(folder) as router:
        refused = fault_list(old, router.endpoint)
        current = fault_list(folder / "client-instructor.json5", router.endpoint)
    assert refused.returncode == 2, refused
    assert (f"the router at {router.endpoint} answered and refused these credentials (user "
            f"'instructor' of {old})") in refused.stderr, refused.stderr
    assert "No Zenoh router answered" not in refused.stderr
    assert "refused these credentials" not in current.stderr and "No Zenoh router" not in current.stderr, \
        current.stderr
    gone = fault_list(old, router.endpoint)  # the router stopped: nothing listens there
    assert "No Zenoh router answered" in gone.stderr and "refused these" not in gone.stderr, gone.stderr


def _set_password(folder: Path, user: str, password: str) -> None:
    """The router's dictionary and the user's client file agree on ``password``."""
    creds = read_credentials(folder / "credentials.txt")
    creds[user] = password
    (folder / "credentials.txt").write_text("".join(f"{u}:{p}\n" for u, p in creds.items()))
    path = folder / f"client-{user}.json5"
    config = json.loads(path.read_text())
    config["transport"]["auth"]["usrpwd"]["password"] = password
    path.write_text(json.dumps(config))


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    folder = tmp_path / "s"
    make_secrets(folder, ["localhost"], "tls/127.0.0.1:7447")
    assert check_secrets(folder) == []
    return folder


def test_secrets_open_to_others_are_refused_each_named(folder: Path) -> None:
    folder.chmod(0o755)
    (folder / "credentials.txt").chmod(0o644)
    (folder / "tls" / "router.key").chmod(0o640)
    (folder / "client-observer.json5").chmod(0o604)
    out = lunaris("deploy", "check", str(folder))
    assert out.returncode == 1, out.stderr
    for words in (f"{folder}: the folder is open to others (mode 755, not 700): chmod 700",
                  "credentials.txt: readable by others (mode 644, not 600): chmod 600",
                  "tls/router.key: readable by others (mode 640, not 600)",
                  "client-observer.json5: readable by others (mode 604, not 600)"):
        assert words in out.stderr, out.stderr
    assert "ca.crt" not in out.stderr  # a certificate is public
    assert "REFUSED" in out.stderr


@pytest.mark.parametrize(("password", "words"), [
    ("aaaaaaaaaaaaaaaa", "the password of observer is one character repeated"),
    ("abababababababababab", "the password of observer uses only 2 different characters"),
    ("demo-observer-password-1234", "observer still has a shipped demo password"),
    ("Demo-Observer-Password-1234", "observer still has a shipped demo password"),
    ("DEMO_observer_password_1234", "observer still has a shipped demo password"),
    ("observer-change-me-12345678", "observer still has a shipped demo password"),
    ("Xy7-short", "the password of observer is shorter than 16 characters"),
])
def test_weak_and_demo_passwords_are_refused(folder: Path, password: str, words: str) -> None:
    _set_password(folder, "observer", password)
    out = lunaris("deploy", "check", str(folder))
    assert out.returncode == 1 and f"credentials.txt: {words}" in out.stderr, out.stderr


def test_an_identity_the_deployment_does_not_know_is_refused(folder: Path) -> None:
    with (folder / "credentials.txt").open("a") as f:
        f.write("mallory:x\n")
    lines = len((folder / "credentials.txt").read_text().splitlines())
    out = lunaris("deploy", "check", str(folder))
    assert out.returncode == 1
    assert (f"credentials.txt: 'mallory' (line {lines}) is no identity of this deployment, "
            "and the router would let it in: remove its line") in out.stderr, out.stderr
    # rotating another identity keeps the line, and the check still names it
    assert lunaris("deploy", "secrets", str(folder), "--rotate", "observer").returncode == 0
    assert any("'mallory'" in p for p in check_secrets(folder))


@pytest.mark.parametrize("password", ["demo-instructor-password", "Demo-Instructor-1234567",
                                      "instructor-CHANGE-ME-123"])
def test_every_client_refuses_a_demo_password(folder: Path, password: str) -> None:
    _set_password(folder, "instructor", password)
    with pytest.raises(ConnectionConfigError, match="demo password"):
        make_config(config_file=folder / "client-instructor.json5")



def test_the_dashboards_files_are_for_the_deployments_rovers(tmp_path: Path) -> None:
    one = tmp_path / "one"
    out = lunaris("deploy", "secrets", str(one), "--rover", "config/rovers/ltv.yaml")
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in one.glob("zenoh-bridge-ros2dds-*")) == ["zenoh-bridge-ros2dds-ltv-1.json5"]
    plugin = json.loads((one / "zenoh-bridge-ros2dds-ltv-1.json5").read_text())["plugins"]["ros2dds"]
    # a fleet of one: the bridge's keys are the plain topic names, no namespace; domain 0
    assert plugin["domain"] == 0 and "namespace" not in plugin
    two = tmp_path / "two"
    out = lunaris("deploy", "secrets", str(two), "--rover", "config/rovers/ltv.yaml",
                  "--rover", "config/rovers/mapp.yaml")
    assert out.returncode == 0, out.stderr
    plugins = {r: json.loads((two / f"zenoh-bridge-ros2dds-{r}.json5").read_text())["plugins"]["ros2dds"]
               for r in ("ltv-1", "mapp-1")}
    assert [(p["namespace"], p["domain"]) for p in plugins.values()] == [("/ltv_1", 0), ("/mapp_1", 1)]
    bad = lunaris("deploy", "secrets", str(tmp_path / "bad"), "--rover", "no-such-rover.yaml")
    assert bad.returncode == 2 and "no-such-rover.yaml" in bad.stderr
