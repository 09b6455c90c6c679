"""A deployment's secrets: made, checked, rotated; demo passwords refused everywhere."""

from __future__ import annotations

import json
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
