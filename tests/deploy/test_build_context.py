"""What every builder sends the Docker daemon to build deploy/Dockerfile (issue 33.2).

BuildKit reads ``deploy/Dockerfile.dockerignore``; the legacy builder (``docker-compose`` 1.x,
``DOCKER_BUILDKIT=0``) reads only the root ``.dockerignore``: without one it sent the whole
repository, ``.git`` and ``deploy/secrets`` included. The two files hold the same rules, and the
context is computed by the code docker-compose 1.x builds with (docker-py's ``exclude_paths``,
from the interpreter that runs ``docker-compose``), on a tree with a ``.git`` and secrets of its
own and on the repository itself.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.deploy.conftest import REPO

pytestmark = pytest.mark.timeout(60)

ROOT_IGNORE = REPO / ".dockerignore"
BUILDKIT_IGNORE = REPO / "deploy" / "Dockerfile.dockerignore"
COPIED = ("pyproject.toml", "common/", "services/", "lunaris/", "config/")  # deploy/Dockerfile's COPY

# docker-py as docker-compose 1.x calls it (docker/api/build.py): the root .dockerignore's
# lines, comments and blanks aside, then the files of the context.
_CONTEXT = """
import json, os, sys
from docker.utils.build import exclude_paths
root, dockerfile = sys.argv[1], sys.argv[2]
exclude = []
ignore = os.path.join(root, ".dockerignore")
if os.path.exists(ignore):
    with open(ignore) as f:
        exclude = [l.strip() for l in f.read().splitlines() if l.strip() and l.strip()[0] != "#"]
sent = exclude_paths(root, exclude, dockerfile=dockerfile)
print(json.dumps(sorted(p for p in sent if os.path.isfile(os.path.join(root, p)))))
"""


def _rules(path: Path) -> list[str]:
    return [line.strip() for line in path.read_text().splitlines()
            if line.strip() and not line.strip().startswith("#")]


def test_both_builders_read_the_same_rules() -> None:
    assert ROOT_IGNORE.is_file(), "no root .dockerignore: the legacy builder sends everything"
    assert _rules(ROOT_IGNORE) == _rules(BUILDKIT_IGNORE)


def _legacy_interpreter() -> str:
    compose = shutil.which("docker-compose")
    if compose is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    first = Path(compose).read_bytes().split(b"\n", 1)[0].decode()
    python = first[2:].strip().split()[0] if first.startswith("#!") else ""
    if not python or subprocess.run([python, "-c", "import docker.utils.build"],
                                    capture_output=True).returncode != 0:
        pytest.skip(f"docker-compose's interpreter ({python or '?'}) has no docker-py")
    return python


def _legacy_context(root: Path) -> list[str]:
    """The files the legacy builder sends (the Dockerfile and .dockerignore always go)."""
    done = subprocess.run([_legacy_interpreter(), "-c", _CONTEXT, str(root), "deploy/Dockerfile"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _in_copied(path: str) -> bool:
    return path in ("deploy/Dockerfile", ".dockerignore") or any(
        path == c or (c.endswith("/") and path.startswith(c)) for c in COPIED)


def test_the_legacy_builder_sends_only_what_the_image_copies(tmp_path: Path) -> None:
    root = tmp_path / "repo"
    for name in ("pyproject.toml", "common/keys.py", "lunaris/cli.py", "lunaris/__pycache__/cli.pyc",
                 "services/battery/model.py", "config/rovers/mapp.yaml", ".git/config",
                 ".git/objects/ab/cdef", "deploy/secrets/credentials.txt", "deploy/secrets/ca/ca.key",
                 "tests/test_x.py", "recordings/run.mcap", "README.md"):
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text("x\n")
    shutil.copy(REPO / "deploy" / "Dockerfile", root / "deploy" / "Dockerfile")
    if ROOT_IGNORE.is_file():  # without it, the legacy builder sends everything
        shutil.copy(ROOT_IGNORE, root / ".dockerignore")
    sent = _legacy_context(root)
    assert sent == sorted([".dockerignore", "pyproject.toml", "common/keys.py", "lunaris/cli.py",
                           "services/battery/model.py", "config/rovers/mapp.yaml",
                           "deploy/Dockerfile"]), sent


def test_the_repositorys_context_is_what_the_image_copies() -> None:
    sent = _legacy_context(REPO)
    assert "deploy/Dockerfile" in sent and "pyproject.toml" in sent
    assert [p for p in sent if not _in_copied(p)] == []
    assert not [p for p in sent if "__pycache__" in p or p.endswith(".pyc")]
