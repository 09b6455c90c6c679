"""docker-compose.yml as docker-compose itself resolves it (`docker-compose config`).

No Docker engine is needed (SPEC §11): the file is validated and its services, profile
and mounts are checked, with every mounted file looked up in the repository, or among the
secrets `lunaris deploy secrets` makes (deploy/secrets/ is never in the repository).
test_containers.py runs it in an engine of its own, where one can start.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path, PurePosixPath
from typing import Any

import pytest
import yaml

from lunaris.deploy import check_secrets
from lunaris.deploy_site import load_site
from lunaris.processes import lunaris_cmd
from tests.deploy.conftest import REPO, make_test_secrets

SECRETS = REPO / "deploy" / "secrets"

SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
STATE_DIR = "/var/lib/lunaris"
DOCKER_COMPOSE = shutil.which("docker-compose")

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def compose(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    if DOCKER_COMPOSE is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    result = subprocess.run(
        [DOCKER_COMPOSE, "-f", "docker-compose.yml", "config"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
        # The defaults of the file, not whatever ZENOH_VERSION or DOCKER_HOST say here.
        env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"),
             "HOME": str(tmp_path_factory.mktemp("home"))},
    )
    assert result.returncode == 0, result.stderr
    return yaml.safe_load(result.stdout)


def _mounts(service: dict[str, Any]) -> dict[str, str]:
    """Container path -> host path (or volume name) of a resolved service."""
    mounts = {}
    for volume in service.get("volumes", []):
        if isinstance(volume, str):  # "source:target[:mode]"
            source, target = volume.split(":")[:2]
        else:
            source, target = volume["source"], volume["target"]
        mounts[target] = source
    return mounts


def _host_path(mounts: dict[str, str], container_path: str, workdir: str) -> Path:
    """Where a path seen inside the container comes from on the host."""
    path = PurePosixPath(workdir) / container_path
    for target, source in sorted(mounts.items(), key=lambda m: -len(m[0])):
        if path == PurePosixPath(target) or PurePosixPath(target) in path.parents:
            return Path(source) / path.relative_to(target)
    raise AssertionError(f"{path} is not mounted from the host")


@pytest.fixture(scope="module")
def made_secrets(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_test_secrets(tmp_path_factory.mktemp("secrets"))


def _exists(source: str, made: Path) -> bool:
    """A mounted host file: in the repository, or one the secrets command makes."""
    path = Path(source)
    if SECRETS in path.parents or path == SECRETS:
        return (made / path.relative_to(SECRETS)).exists()
    return path.exists()


def test_the_router_is_zenohd_with_the_deploy_configuration(compose: dict[str, Any]) -> None:
    router = compose["services"]["router"]
    assert router["image"].startswith("eclipse/zenoh:")
    assert router["restart"] == "unless-stopped"
    # Loopback unless LUNARIS_BIND says otherwise (docker-compose v1 writes a short form).
    assert router["ports"] in (["127.0.0.1:7447:7447/tcp"],
                               [{"host_ip": "127.0.0.1", "published": "7447", "target": 7447,
                                 "protocol": "tcp", "mode": "ingress"}])
    mounts = _mounts(router)
    command = router["command"]
    config = command[command.index("-c") + 1]
    assert Path(mounts[config]) == REPO / "deploy/zenohd.json5"
    assert Path(mounts["/etc/zenoh/secrets/credentials.txt"]) == SECRETS / "credentials.txt"
    assert Path(mounts["/etc/zenoh/secrets/tls"]) == SECRETS / "tls"
    text = (REPO / "deploy/zenohd.json5").read_text()
    assert "/etc/zenoh/secrets/credentials.txt" in text and "/etc/zenoh/secrets/tls/router.crt" in text


def test_nothing_starts_before_the_secrets_are_checked(compose: dict[str, Any], made_secrets: Path,
                                                       tmp_path: Path) -> None:
    pre = compose["services"]["preflight"]
    assert pre["command"] == ["deploy", "check", "/etc/lunaris/secrets"]
    assert Path(_mounts(pre)["/etc/lunaris/secrets"]) == SECRETS
    for name, service in compose["services"].items():
        if name == "preflight" or name.startswith("zenoh-bridge-ros2dds"):
            continue
        assert service["depends_on"]["preflight"]["condition"] == "service_completed_successfully", name
    assert check_secrets(made_secrets) == []
    demo = tmp_path / "demo"
    shutil.copytree(made_secrets, demo)
    text = (demo / "credentials.txt").read_text().splitlines()
    text[0] = text[0].split(":")[0] + ":demo-service-CHANGE-ME"
    (demo / "credentials.txt").write_text("\n".join(text) + "\n")
    problems = check_secrets(demo)
    assert any("demo password" in p for p in problems), problems


@pytest.mark.parametrize("name", SERVICES)
def test_each_service_runs_from_the_one_image(compose: dict[str, Any], name: str) -> None:
    service = compose["services"][name]
    assert service["build"]["dockerfile"] == "deploy/Dockerfile"
    assert Path(service["build"]["context"]) == REPO
    assert service["image"] == compose["services"]["clock"]["image"]
    assert service["restart"] == "unless-stopped"
    assert "router" in service["depends_on"]
    command = service["command"]
    assert command[:2] == ["run", name]
    mounts = _mounts(service)
    workdir = "/opt/lunaris"  # deploy/Dockerfile's WORKDIR
    rovers = [command[i + 1] for i, arg in enumerate(command) if arg == "--rover"]
    assert rovers, "no --rover"
    for rover in rovers:
        assert _host_path(mounts, rover, workdir).is_file(), rover
    if "--bridge-config" in command:
        mapping = command[command.index("--bridge-config") + 1]
        assert _host_path(mounts, mapping, workdir).parent.is_dir(), mapping

    zenoh_config = service["environment"]["LUNARIS_ZENOH_CONFIG"]
    assert Path(mounts[zenoh_config]) == SECRETS / f"client-lunaris-{name}.json5"  # its own identity

    assert command[command.index("--state-dir") + 1] == STATE_DIR
    assert mounts[STATE_DIR] in compose["volumes"], "state is not on a named volume"


def test_the_ros2dds_bridges_are_an_optional_profile_one_per_rover(
        compose: dict[str, Any], made_secrets: Path) -> None:
    profiled = {n for n, s in compose["services"].items() if s.get("profiles")}
    rovers = ["mapp-1", "ltv-1"]  # the fleet of the compose file, in its order
    assert profiled == {f"zenoh-bridge-ros2dds-{r}" for r in rovers}
    for domain, rover in enumerate(rovers):
        bridge = compose["services"][f"zenoh-bridge-ros2dds-{rover}"]
        assert bridge["profiles"] == ["ros2dds"]
        assert bridge["image"].startswith("eclipse/zenoh-bridge-ros2dds:")
        assert "router" in bridge["depends_on"]
        command = bridge["command"]
        config = command[command.index("-c") + 1]
        assert Path(_mounts(bridge)[config]) == SECRETS / f"zenoh-bridge-ros2dds-{rover}.json5"
        # the rover's namespace and domain: its dashboard sees the plain topic names
        made = json.loads((made_secrets / f"zenoh-bridge-ros2dds-{rover}.json5").read_text())
        plugin = made["plugins"]["ros2dds"]
        assert plugin["namespace"] == "/" + rover.replace("-", "_") and plugin["domain"] == domain
        assert "/curr_to_receiving_radio_m" in plugin["allow"]["publishers"]
    # every rover served by exactly one bridge process, each given the whole fleet
    shards = [s["command"] for n, s in compose["services"].items()
              if s.get("command", [""])[:2] == ["run", "bridge"]]
    assert sorted(c[c.index("--shard") + 1] for c in shards) == ["1/2", "2/2"]
    for c in shards:
        assert [c[i + 1] for i, a in enumerate(c) if a == "--rover"] == [
            "config/rovers/mapp.yaml", "config/rovers/ltv.yaml"]


def test_every_mounted_host_file_is_in_the_repository(compose: dict[str, Any],
                                                     made_secrets: Path) -> None:
    for name, service in compose["services"].items():
        for target, source in _mounts(service).items():
            if source in compose.get("volumes", {}):
                continue
            assert _exists(source, made_secrets), f"{name}: {source} (for {target}) does not exist"
            assert REPO in Path(source).parents, f"{name}: {source} is outside the repository"


def _instructions() -> list[list[str]]:
    dockerfile = (REPO / "deploy/Dockerfile").read_text().replace("\\\n", " ")
    instructions = [line.split(None, 1) for line in dockerfile.splitlines()
                    if line.strip() and not line.lstrip().startswith("#")]
    return [i for i in instructions if i[0].isupper()]


def test_the_image_installs_the_dependencies_and_runs_lunaris_from_source() -> None:
    first = _instructions()
    assert first[0] == ["FROM", "python:3.11-slim"]
    assert ["ENTRYPOINT", '["python", "-m", "lunaris.cli"]'] in first
    assert any(i[0] == "USER" and i[1] != "root" for i in first), "runs as root"
    assert ["VOLUME", f'["{STATE_DIR}"]'] in first
    assert any(i[0] == "RUN" and "pip install -r" in i[1] for i in first)
    # No package named "common" or "services" is installed into site-packages.
    assert not any(i[0] == "RUN" and "pip install ." in i[1] for i in first)
    assert ["ENV", "PYTHONPATH=/opt/lunaris"] in first


def test_every_file_the_dockerfile_names_exists() -> None:
    """Its comments name files of the repository (deploy/client-service.json5 never existed):
    each is there, or (deploy/secrets/) one that `lunaris deploy secrets` makes."""
    import re
    text = (REPO / "deploy" / "Dockerfile").read_text()
    named = set(re.findall(r"\b(?:deploy|config)/[\w./<>-]*\w", text))
    assert "deploy/secrets/client-<identity>.json5" in named
    for path in named:
        if path.startswith("deploy/secrets/"):
            assert re.fullmatch(r"deploy/secrets/client-<identity>\.json5", path), path
        else:
            assert (REPO / path).exists(), f"deploy/Dockerfile names {path}, which does not exist"


def test_the_image_layout_runs_lunaris(tmp_path: Path) -> None:
    """The image's /opt/lunaris, rebuilt from the Dockerfile's COPY lines, runs `lunaris check`
    with the source on PYTHONPATH (the dependencies are this environment's)."""
    root = tmp_path / "opt-lunaris"
    for instr in _instructions():
        if instr[0] == "COPY":
            src, dst = instr[1].split()
            target = root / dst
            if (REPO / src).is_dir():
                shutil.copytree(REPO / src, target, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                target.mkdir(parents=True, exist_ok=True)  # COPY file ./ : into the WORKDIR
                shutil.copy(REPO / src, target)
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run([sys.executable, "-m", "lunaris.cli", "check", "config/rovers/mapp.yaml"],
                         cwd=root, env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    where = subprocess.run([sys.executable, "-c", "import common; print(common.__file__)"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert where.stdout.startswith(str(root)), where.stdout


def test_the_console_runs_with_its_own_identity_and_requires_a_sign_in(compose: dict[str, Any],
                                                                      made_secrets: Path) -> None:
    console = compose["services"]["console"]
    assert console["image"] == compose["services"]["clock"]["image"]
    assert console["restart"] == "unless-stopped" and "router" in console["depends_on"]
    command = console["command"]
    assert command[0] == "console"

    def rovers(cmd: list[str]) -> list[str]:
        return [cmd[i + 1] for i, arg in enumerate(cmd) if arg == "--rover"]
    # the services' rover files: the map, the drive and the radios' forms need them
    assert rovers(command) == rovers(compose["services"]["clock"]["command"]) != []
    mounts = _mounts(console)
    accounts = command[command.index("--accounts") + 1]
    assert Path(mounts[accounts]) == SECRETS / "console-accounts.json"
    assert (made_secrets / "console-accounts.json").read_text().strip() == '{"users": {}}'
    zenoh_config = console["environment"]["LUNARIS_ZENOH_CONFIG"]
    assert Path(mounts[zenoh_config]) == SECRETS / "client-console.json5"
    assert console["ports"] in (["127.0.0.1:8080:8080/tcp"],
                                [{"host_ip": "127.0.0.1", "published": "8080", "target": 8080,
                                  "protocol": "tcp", "mode": "ingress"}])
    assert command[command.index("--recordings") + 1].startswith(STATE_DIR)


def _resolved(file: str, home: Path, **env: str) -> dict[str, Any]:
    """``file`` as docker-compose resolves it with only ``env`` set."""
    result = subprocess.run([DOCKER_COMPOSE or "docker-compose", "-f", file, "config"], cwd=REPO,
                            capture_output=True, text=True, timeout=60,
                            env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(home),
                                 **env})
    assert result.returncode == 0, result.stderr
    return yaml.safe_load(result.stdout)


@pytest.mark.parametrize(("file", "console", "default"), [
    ("docker-compose.yml", "console", ""),
    ("docker-compose.site.yml", "ground-console", "ground.lunaris.example")])
def test_the_console_is_given_the_names_it_is_reached_by(tmp_path: Path, file: str, console: str,
                                                         default: str) -> None:
    """A console in a container refuses a Host it does not know (421): LUNARIS_ALLOW_HOST reaches
    it from both compose files (the site's: its machine's names by default), as the console
    reads it (tests/console/test_startup.py)."""
    if DOCKER_COMPOSE is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    env = _resolved(file, tmp_path)["services"][console]["environment"]
    assert env["LUNARIS_ALLOW_HOST"] == default
    assert env["LUNARIS_ZENOH_CONFIG"] == "/etc/lunaris/zenoh.json5"
    given = _resolved(file, tmp_path, LUNARIS_ALLOW_HOST="rover-base.example,10.0.0.5")
    assert given["services"][console]["environment"]["LUNARIS_ALLOW_HOST"] == \
        "rover-base.example,10.0.0.5"


# -- the three-machine case: docker-compose.site.yml, the site of deploy/site.yaml ------------


@pytest.fixture(scope="module")
def site_compose(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    if DOCKER_COMPOSE is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    result = subprocess.run(
        [DOCKER_COMPOSE, "-f", "docker-compose.site.yml", "config"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
        env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"),
             "HOME": str(tmp_path_factory.mktemp("home"))},
    )
    assert result.returncode == 0, result.stderr
    return yaml.safe_load(result.stdout)


@pytest.fixture(scope="module")
def site_secrets(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from lunaris.deploy_routers import make_site_secrets
    folder = tmp_path_factory.mktemp("site-secrets") / "s"
    make_site_secrets(folder, load_site(REPO / "deploy" / "site.yaml"))
    return folder


def test_each_machine_of_the_site_is_a_profile_with_its_router_and_its_services(
        site_compose: dict[str, Any], site_secrets: Path) -> None:
    site = load_site(REPO / "deploy" / "site.yaml")
    services = site_compose["services"]
    for spec in site.routers:
        mine = {n: s for n, s in services.items() if s.get("profiles") == [spec.name]}
        router = mine[f"{spec.name}-router"]
        assert router["image"].startswith("eclipse/zenoh:")
        assert router["command"] == ["-c", "/etc/zenoh/secrets/zenohd.json5"]
        assert Path(_mounts(router)["/etc/zenoh/secrets"]) == SECRETS / spec.name
        assert router["networks"]["default"]["aliases"] == [spec.hosts[0]]
        published = {str(p["target"]) if isinstance(p, dict) else p.split(":")[-1].split("/")[0]
                     for p in router["ports"]}
        assert published == {"7447"} | ({"7448"} if site.linked_from(spec.name) else set())
        pre = mine[f"{spec.name}-preflight"]
        assert pre["command"] == ["deploy", "check", "/etc/lunaris/secrets", "--site",
                                  "deploy/site.yaml", "--router", spec.name]
        assert Path(_mounts(pre)["/etc/lunaris/secrets"]) == SECRETS / spec.name
        ran = {}
        for service in mine.values():
            command = service.get("command", [])
            if command[:1] == ["run"]:
                ran[command[1]] = service
            elif command[:1] == ["console"]:
                ran["console"] = service
        assert sorted(ran) == sorted(spec.runs), spec.name
        if "console" in ran:  # the site's rover files: the map, the drive and the radios' forms
            command = ran["console"]["command"]
            assert [command[i + 1] for i, a in enumerate(command) if a == "--rover"] == list(site.rovers)
        for what, service in ran.items():
            identity = f"lunaris-{what}" if what != "console" else "console"
            config = service["environment"]["LUNARIS_ZENOH_CONFIG"]
            assert Path(_mounts(service)[config]) == SECRETS / spec.name / f"client-{identity}.json5"
            assert service["depends_on"][f"{spec.name}-preflight"]["condition"] == \
                "service_completed_successfully"
        for name, service in mine.items():
            for source in _mounts(service).values():
                if source in site_compose.get("volumes", {}):
                    continue
                path = Path(source)
                if SECRETS in path.parents:
                    assert (site_secrets / path.relative_to(SECRETS)).exists(), (name, source)
                else:
                    assert path.exists(), (name, source)
    assert all(s.get("profiles") for s in services.values()), "a service on every machine"


def test_the_site_compose_file_is_written_from_the_site() -> None:
    """docker-compose.site.yml is what `lunaris deploy compose` writes from deploy/site.yaml: it
    was written by hand, and nothing said when the site changed and it did not."""
    done = subprocess.run(lunaris_cmd("deploy", "compose", "--site", "deploy/site.yaml", "--check"),
                          cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


OWN_SITE = """\
rovers: [config/rovers/mapp.yaml, config/rovers/ltv.yaml]
routers:
  - name: base
    hosts: [base.example.org, 10.0.0.5]
    runs: [faults, console, clock, battery, loads, power, solar, radio, drive]
    people: [instructor, debrief]
  - name: dash
    hosts: [dash.example.org]
    connect: [base]
    runs: [bridge]
    people: [dashboard, observer]
"""


def test_a_site_of_ones_own_gets_its_compose_file(tmp_path: Path) -> None:
    """Two machines, two rovers: a profile each, every service of both rovers on the base, a
    zenoh-bridge-ros2dds per rover beside the dashboard; docker-compose reads it; --check says
    when the site has changed since."""
    if DOCKER_COMPOSE is None:
        pytest.skip("docker-compose is not installed (apt-get install docker-compose)")
    site, out = tmp_path / "site.yaml", tmp_path / "docker-compose.site.yml"
    site.write_text(OWN_SITE)

    def compose(*extra: str) -> subprocess.CompletedProcess:
        return subprocess.run(lunaris_cmd("deploy", "compose", "--site", str(site), "--output", str(out),
                                          *extra), cwd=REPO, capture_output=True, text=True, timeout=60)
    done = compose()
    assert done.returncode == 0 and "wrote" in done.stdout, done.stderr
    assert "--site site.yaml" in out.read_text()  # what the machines run: the site beside it
    result = subprocess.run([DOCKER_COMPOSE, "-f", str(out), "config"], cwd=tmp_path, capture_output=True,
                            text=True, timeout=60, env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"),
                                                        "HOME": str(tmp_path)})
    assert result.returncode == 0, result.stderr
    services = yaml.safe_load(result.stdout)["services"]
    assert {n: s["profiles"] for n, s in services.items()} == {
        **{f"base-{w}": ["base"] for w in ("preflight", "router", "faults", "console", "clock", "battery",
                                            "loads", "power", "solar", "radio", "drive")},
        **{f"dash-{w}": ["dash"] for w in ("preflight", "router", "bridge", "zenoh-bridge-ros2dds-mapp-1",
                                            "zenoh-bridge-ros2dds-ltv-1")}}
    battery = services["base-battery"]["command"]
    assert [battery[i + 1] for i, a in enumerate(battery) if a == "--rover"] == [
        "config/rovers/mapp.yaml", "config/rovers/ltv.yaml"]
    bridge = services["dash-bridge"]["command"]
    assert bridge[bridge.index("--bridge-config") + 1] == "config/bridge/default.yaml"
    ports = {name: sorted(str(p["target"]) if isinstance(p, dict) else p.split(":")[-1].split("/")[0]
                          for p in services[f"{name}-router"]["ports"]) for name in ("base", "dash")}
    assert ports == {"base": ["7447", "7448"], "dash": ["7447"]}  # dash opens the link to base
    assert services["base-router"]["networks"]["default"]["aliases"] == ["base.example.org"]
    # dash's router reaches base by its name: pinned to the address the site gives beside it
    # (a container does not read its machine's /etc/hosts), which a variable may change
    assert services["dash-router"]["extra_hosts"] == ["base.example.org:10.0.0.5"]
    assert "extra_hosts" not in services["base-router"]  # it opens no link
    moved = subprocess.run([DOCKER_COMPOSE, "-f", str(out), "config"], cwd=tmp_path, capture_output=True,
                           text=True, timeout=60, env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"),
                                                       "HOME": str(tmp_path),
                                                       "LUNARIS_ADDRESS_BASE": "10.0.0.9"})
    assert moved.returncode == 0, moved.stderr
    assert yaml.safe_load(moved.stdout)["services"]["dash-router"]["extra_hosts"] == [
        "base.example.org:10.0.0.9"]
    assert compose("--check").returncode == 0
    site.write_text(OWN_SITE.replace("runs: [bridge]", "runs: [bridge, console]").replace(
        "faults, console,", "faults,"))
    stale = compose("--check")
    assert stale.returncode == 1 and "is stale: run lunaris deploy compose" in stale.stderr, stale.stderr
