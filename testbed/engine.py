"""A Docker engine of the test's own: ``dockerd`` on its own socket and folders, and its images.

:class:`Engine` starts Debian's ``dockerd`` (package ``docker.io``) with a socket, a data root
and an exec root in a folder of its own, without the default bridge or iptables rules (the
deployment's containers talk on the networks compose makes, the host reaches them through the
ports compose publishes on loopback). Its processes run niced, so a test beside other work
takes what is left of the CPU. On exit, pass or fail, it removes every container, network and
volume, stops the daemon (containerd with it), unmounts what is left under its folder and
deletes the folder: images go with the data root.

No image registry is reachable from the tests, so deploy/Dockerfile's base is made here:
:func:`base_rootfs` runs ``debootstrap`` (Debian bookworm, minbase, its Python 3.11 with pip;
``python`` and ``pip`` on PATH as in ``python:3.11-slim``, pip allowed to install into
``/usr/local``) from the mirror apt uses, once, and keeps the root filesystem as a tarball in
:data:`CACHE`; :meth:`Engine.import_base` imports it under the name the Dockerfile's ``FROM``
gives, in this engine only. Needs root; :func:`unavailable` says what is missing, for
``pytest.skip``.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import signal
import subprocess
import tarfile
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

from lunaris.processes import wait_for

__all__ = ["BASE_TAG", "CACHE", "Engine", "base_rootfs", "debian_mirror", "unavailable"]

CACHE = Path(os.environ.get("LUNARIS_TEST_CACHE", "/var/cache/lunaris-tests"))
BASE_TARBALL = CACHE / "debian-bookworm-python3.11.tar"
BASE_TAG = "python:3.11-slim"  # deploy/Dockerfile's FROM, given to the rootfs in this engine only
SUITE = "bookworm"  # Debian's release with Python 3.11
PACKAGES = ("python3", "python3-pip", "python-is-python3", "ca-certificates")
HOST_CA = "/etc/ssl/certs/ca-certificates.crt"  # Debian's bundle: what pip and curl trust here
RUN_DOCKER = Path("/run/docker")  # every dockerd's plugin folder, whatever its exec root
TOOLS = ("dockerd", "containerd", "runc", "docker", "docker-compose")
START_S = 60.0  # dockerd's first start on a fresh data root (a second or two here)


def unavailable() -> str | None:
    """Why no engine can run here (None: one can)."""
    if os.geteuid() != 0:
        return "needs root: it starts a Docker engine of its own (dockerd)"
    missing = [t for t in TOOLS if shutil.which(t) is None]
    if not BASE_TARBALL.exists() and shutil.which("debootstrap") is None:
        missing.append("debootstrap")
    if missing:
        return (f"{', '.join(missing)} not installed (`make system-deps`, as root, installs "
                "docker.io, docker-compose and debootstrap with apt)")
    return None


def debian_mirror() -> str:
    """The Debian mirror apt uses (``$LUNARIS_DEBIAN_MIRROR`` first)."""
    if mirror := os.environ.get("LUNARIS_DEBIAN_MIRROR"):
        return mirror
    sources = sorted(Path("/etc/apt").glob("sources.list.d/*.sources"))
    sources += [Path("/etc/apt/sources.list"), *sorted(Path("/etc/apt").glob("sources.list.d/*.list"))]
    for path in sources:
        text = path.read_text() if path.is_file() else ""
        for uri in re.findall(r"^\s*(?:URIs:|deb(?:\s+\[[^]]*\])?)\s+(\S+)", text, re.MULTILINE):
            if "security" not in uri:
                return uri
    raise RuntimeError("no Debian mirror in /etc/apt/sources.list*: set LUNARIS_DEBIAN_MIRROR")


def base_rootfs() -> Path:
    """The base image's root filesystem as a tarball, made by debootstrap on first use."""
    if BASE_TARBALL.exists():
        return BASE_TARBALL
    CACHE.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="rootfs-", dir=CACHE))
    rootfs, partial = work / "rootfs", work / "rootfs.tar"
    try:
        done = subprocess.run(
            ["nice", "debootstrap", "--variant=minbase", f"--include={','.join(PACKAGES)}",
             SUITE, str(rootfs), debian_mirror()],
            capture_output=True, text=True, timeout=1200)
        if done.returncode != 0:
            raise RuntimeError(f"debootstrap failed ({done.returncode}):\n{done.stdout[-3000:]}"
                               f"\n{done.stderr[-3000:]}")
        # pip installs into /usr/local as in python:3.11-slim, not refused as Debian's Python
        (rootfs / "usr/lib/python3.11/EXTERNALLY-MANAGED").unlink(missing_ok=True)
        for cache in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for item in (rootfs / cache).glob("*"):
                if item.is_file():
                    item.unlink()
        subprocess.run(["tar", "-C", str(rootfs), "-cf", str(partial), "."], check=True, timeout=600)
        partial.replace(BASE_TARBALL)  # whole or not at all: a run cut short leaves no tarball
    finally:
        _unmount_under(work)
        shutil.rmtree(work, ignore_errors=True)
    return BASE_TARBALL


def _unmount_under(folder: Path) -> None:
    """Unmount whatever is still mounted under ``folder`` (deepest first)."""
    prefix = str(folder.resolve()) + "/"
    with open("/proc/self/mounts") as mounts:
        points = [line.split()[1] for line in mounts]
    for point in sorted({p for p in points if p.startswith(prefix)}, key=len, reverse=True):
        subprocess.run(["umount", "-l", point], capture_output=True, timeout=30)


class Engine:
    """A running ``dockerd`` of the test's own (a context manager: everything goes on exit)."""

    def __init__(self) -> None:
        # a short path: the socket's must fit a sockaddr_un (108 bytes)
        self.folder = Path(tempfile.mkdtemp(prefix="lunaris-engine-"))
        self.socket = self.folder / "docker.sock"
        self.host = f"unix://{self.socket}"
        self.home = self.folder / "home"  # the docker CLI's ~/.docker, not the machine's
        self.home.mkdir()
        self.log = self.folder / "dockerd.log"
        self._proc: subprocess.Popen | None = None
        self._made_run_docker = not RUN_DOCKER.exists()  # dockerd makes /run/docker/plugins

    def env(self, **extra: str) -> dict[str, str]:
        """What a docker or docker-compose command of this engine runs with."""
        return {"PATH": os.environ.get("PATH", "/usr/sbin:/usr/bin:/sbin:/bin"),
                "HOME": str(self.home), "DOCKER_HOST": self.host, "DOCKER_BUILDKIT": "0",
                **extra}

    def __enter__(self) -> Engine:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: type[BaseException] | BaseException | TracebackType | None) -> None:
        self.close()

    def _start(self) -> None:
        with open(self.log, "wb") as log:
            self._proc = subprocess.Popen(
                ["nice", "-n", "10", "dockerd", "--host", self.host,
                 "--data-root", str(self.folder / "data"), "--exec-root", str(self.folder / "exec"),
                 "--pidfile", str(self.folder / "docker.pid"),
                 "--iptables=false", "--ip-masq=false", "--bridge=none"],
                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)

        def ready() -> bool:
            if self._proc is not None and self._proc.poll() is not None:
                raise RuntimeError(f"dockerd exited ({self._proc.returncode}):\n{self.tail()}")
            return self.socket.exists() and self.run("info", check=False).returncode == 0
        wait_for(ready, START_S, lambda: f"dockerd to answer on {self.socket}\n{self.tail()}", poll_s=0.2)

    def tail(self, chars: int = 3000) -> str:
        return self.log.read_text(errors="replace")[-chars:] if self.log.exists() else ""

    def run(self, *args: str, check: bool = True, timeout_s: float = 120.0,
            input: bytes | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
        """``docker ARGS`` against this engine."""
        return self.command(["docker", *args], check=check, timeout_s=timeout_s, input=input, cwd=cwd)

    def command(self, argv: Sequence[str], *, check: bool = True, timeout_s: float = 120.0,
                input: bytes | None = None, cwd: Path | None = None,
                env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
        """Any command (``docker-compose`` ...) with this engine's environment."""
        done = subprocess.run(list(argv), capture_output=True, timeout=timeout_s, input=input,
                              cwd=cwd, env=env or self.env())
        if check and done.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}):\n"
                               f"{done.stdout.decode(errors='replace')[-3000:]}\n"
                               f"{done.stderr.decode(errors='replace')[-3000:]}")
        return done

    def import_base(self) -> None:
        """deploy/Dockerfile's base (:data:`BASE_TAG`): the cached root filesystem, with this
        machine's certificate authorities for pip (what pip trusts here, a proxy's included)."""
        rootfs = "lunaris-test/bookworm-rootfs"
        self.run("import", str(base_rootfs()), rootfs, timeout_s=300)
        context = io.BytesIO()
        with tarfile.open(fileobj=context, mode="w") as tar:
            def add(name: str, data: bytes) -> None:
                info = tarfile.TarInfo(name)
                info.size, info.mode = len(data), 0o644
                tar.addfile(info, io.BytesIO(data))
            steps = [f"FROM {rootfs}", "ENV LANG=C.UTF-8", 'CMD ["python3"]']
            if (ca := Path(HOST_CA)).exists():  # else Debian's own, in the root filesystem
                add("ca-certificates.crt", ca.read_bytes())
                add("pip.conf", f"[global]\ncert = {HOST_CA}\n".encode())
                steps += [f"COPY ca-certificates.crt {HOST_CA}", "COPY pip.conf /etc/pip.conf"]
            add("Dockerfile", "\n".join(steps).encode() + b"\n")
        self.run("build", "-t", BASE_TAG, "-", input=context.getvalue(), timeout_s=300)

    def close(self) -> None:
        """Containers, networks and volumes removed, the daemon stopped, its folder deleted."""
        try:
            if self._proc is not None and self._proc.poll() is None:
                ids = self.run("ps", "-aq", check=False, timeout_s=60).stdout.split()
                if ids:
                    self.run("rm", "-f", "-v", *(i.decode() for i in ids), check=False, timeout_s=120)
                self.run("network", "prune", "-f", check=False, timeout_s=60)
                self.run("volume", "prune", "-f", check=False, timeout_s=60)
        finally:
            self._stop_daemon()
            _unmount_under(self.folder)
            shutil.rmtree(self.folder, ignore_errors=True)
            if self._made_run_docker:
                for empty in (RUN_DOCKER / "plugins", RUN_DOCKER):
                    try:
                        empty.rmdir()  # only when empty: another daemon may have come since
                    except OSError:
                        pass

    def _stop_daemon(self) -> None:
        if self._proc is None:
            return
        if self._proc.poll() is None:
            os.killpg(self._proc.pid, signal.SIGTERM)  # dockerd stops its containerd
            try:
                self._proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(self._proc.pid, signal.SIGKILL)
                self._proc.wait(timeout=30)
        # a containerd-shim (its own session) outlives a daemon that could not remove its
        # containers: every process still naming the engine's folder goes, by its pid
        for pid in self._leftovers():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        wait_for(lambda: not self._leftovers(), 30, "the engine's processes to exit", poll_s=0.1)

    def _leftovers(self) -> list[int]:
        mine = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) != os.getpid():
                try:
                    cmdline = (entry / "cmdline").read_bytes()
                except OSError:
                    continue
                if str(self.folder).encode() in cmdline:
                    mine.append(int(entry.name))
        return mine
