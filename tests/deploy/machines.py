"""The shipped site (deploy/site.yaml) on three machines made of network namespaces.

Each router of the site gets a machine of tests/netns.py (its address the router's only
host), the site's secrets are made by ``lunaris deploy secrets --site --secrets-dir``, and on
each machine run its router (``lunaris router --config <machine>/zenohd.json5``: TLS, mutual
TLS between routers, access control, all as generated) and its services, each under its own
identity. :meth:`SiteOnMachines.remote` puts a client of any identity on any machine.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import Any

from lunaris.deploy_site import Site, load_site
from tests import netns
from tests.deploy.deployment import REPO, Remote, lunaris, run_lunaris, wait_until

__all__ = ["MAPP", "SiteOnMachines"]

MAPP = REPO / "config" / "rovers" / "mapp.yaml"
SITE = REPO / "deploy" / "site.yaml"


class SiteOnMachines:
    def __init__(self, folder: Path, rover: Path = MAPP):
        self.folder, self.rover = folder, rover
        folder.mkdir(parents=True, exist_ok=True)
        self.net = netns.Network(folder / "logs")
        self.secrets = folder / "secrets"
        self.remotes: list[Remote] = []
        self.site: Site | None = None

    def __enter__(self) -> SiteOnMachines:
        self.net.__enter__()
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _start(self) -> None:
        shipped = load_site(SITE)
        text = SITE.read_text().replace("config/rovers/mapp.yaml", str(self.rover))
        for spec in shipped.routers:
            machine = self.net.add(spec.name)
            text = text.replace(f"hosts: [{spec.hosts[0]}]", f"hosts: [{machine.address}]")
        path = self.folder / "site.yaml"
        path.write_text(text)
        self.site = load_site(path)
        made = run_lunaris("deploy", "secrets", str(self.secrets), "--site", str(path),
                           "--secrets-dir", str(self.secrets))
        assert made.returncode == 0, made.stderr
        for spec in self.site.routers:
            self.net.popen(spec.name, lunaris("router", "--config",
                                              str(self.secrets / spec.name / "zenohd.json5")),
                           log=f"{spec.name}-router", cwd=REPO, env=_env())
        for spec in self.site.routers:
            wait_until(lambda n=spec.name: "listening" in self.log(f"{n}-router"), 60,
                       lambda n=spec.name: f"the router of {n}: {self.log(f'{n}-router')[-2000:]}")
        for spec in self.site.routers:
            for service in spec.runs:
                if service == "console":
                    continue
                self.start_service(spec.name, service)

    def start_service(self, machine: str, service: str) -> subprocess.Popen:
        return self.net.popen(machine, lunaris(
            "run", service, "--config", str(self.secrets / machine / f"client-lunaris-{service}.json5"),
            "--rover", str(self.rover), "--state-dir", str(self.folder / f"state-{machine}")),
            log=f"{machine}-{service}", cwd=REPO, env=_env())

    def log(self, name: str) -> str:
        path = self.folder / "logs" / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def tails(self, chars: int = 1500) -> str:
        return "\n".join(f"--- {p.stem} ---\n{p.read_text(errors='replace')[-chars:]}"
                         for p in sorted((self.folder / "logs").glob("*.log")))

    def remote(self, machine: str, identity: str) -> Remote:
        """A client of ``identity`` on ``machine``, from the client file of its folder."""
        proc = self.net.popen(machine, Remote.argv(self.secrets / machine / f"client-{identity}.json5"),
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=REPO,
                              env=_env())
        remote = Remote(proc, f"{identity}@{machine}")
        self.remotes.append(remote)
        return remote

    def lunaris_on(self, machine: str, identity: str, *args: str,
                   timeout_s: float = 60.0) -> subprocess.CompletedProcess:
        """A ``lunaris`` command on ``machine`` under ``identity`` (an instructor's CLI)."""
        return self.net.run(machine, lunaris(*args, "--config",
                                             str(self.secrets / machine / f"client-{identity}.json5")),
                            timeout_s=timeout_s, cwd=REPO, env=_env())

    def lunaris_popen(self, machine: str, identity: str, *args: str) -> subprocess.Popen:
        """The same, started: its output (stdout and stderr) kept in a pipe."""
        return self.net.popen(machine, lunaris(*args, "--config",
                                               str(self.secrets / machine / f"client-{identity}.json5")),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=REPO,
                              env=_env())

    def close(self) -> None:
        for remote in self.remotes:
            remote.close()
        self.remotes.clear()
        self.net.close()


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "LUNARIS_ZENOH_CONFIG"}
