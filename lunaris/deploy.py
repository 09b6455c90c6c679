"""``lunaris deploy acl|secrets|check|compose``: who may do what in a deployment, and its secrets.

- ``acl`` writes ``deploy/zenohd.json5``, the router's configuration with its access control
  (:mod:`lunaris.deploy_acl`); ``tests/deploy`` fails when the committed file is stale.
  ``--secrets-dir`` points it at the secrets' folder of a machine, to run it outside Docker.
- ``secrets DIR`` makes the passwords, client configurations and certificates, ``check DIR``
  refuses what cannot be trusted (:mod:`lunaris.deploy_secrets`).
- ``--site FILE``: a deployment of several machines, each with a router of its own, from one
  description (``deploy/site.yaml``, :mod:`lunaris.deploy_site`): every router's identity,
  certificate, dictionary and configuration, made, rotated and checked
  (:mod:`lunaris.deploy_routers`); ``compose --site`` writes its Docker Compose file
  (:mod:`lunaris.deploy_compose`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lunaris.deploy_acl import REPO, ROUTER_FILE, ROUTER_SECRETS, acl, render_router_config, router_config
from lunaris.deploy_dashboard import FLEET_FILES, fleet_names
from lunaris.deploy_secrets import (
    MIN_PASSWORD_LEN,
    check_secrets,
    client_config,
    make_secrets,
    password_problems,
)
from lunaris.deploy_site import IDENTITIES, SERVICES
from services.bridge import DEFAULT_MAPPING, load_mapping

__all__ = ["IDENTITIES", "MIN_PASSWORD_LEN", "SERVICES", "acl", "add_arguments", "check_secrets",
           "client_config", "main", "make_secrets", "password_problems", "render_router_config",
           "router_config"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    site_help = ("a site of several machines (deploy/site.yaml): its routers, their links and what "
                 "runs where")
    a = sub.add_parser("acl", help="write the router configuration with its access control")
    a.add_argument("--bridge-config", metavar="FILE", help="bridge mapping (default: the shipped one)")
    a.add_argument("--rover", action="append", metavar="FILE",
                   help=f"the deployment's rovers, in order (default {' '.join(FLEET_FILES)})")
    a.add_argument("--output", metavar="PATH",
                   help=f"the file to write (default {ROUTER_FILE.relative_to(REPO)}); with --site "
                        "the site's secrets folder, where each router's configuration goes "
                        "(default deploy/secrets)")
    a.add_argument("--secrets-dir", metavar="DIR",
                   help="where the router finds its secrets when it runs (default: the "
                        f"container's {ROUTER_SECRETS}): a folder of its machine, to run it "
                        "outside Docker (with --site: the site's secrets folder)")
    a.add_argument("--site", metavar="FILE", help=site_help)
    a.add_argument("--check", action="store_true", help="exit 1 if a configuration is not up to date")
    s = sub.add_parser("secrets", help="make passwords, client configurations and certificates")
    s.add_argument("dir", metavar="DIR", help="where to write them (deploy/secrets)")
    s.add_argument("--host", action="append", metavar="NAME",
                   help="a name or address of the router in its certificate (default: router, "
                        "localhost, 127.0.0.1; repeat)")
    s.add_argument("--connect", default="tls/router:7447", metavar="ENDPOINT",
                   help="the endpoint the clients connect to (default tls/router:7447)")
    s.add_argument("--no-tls", action="store_true", help="plain TCP: no certificates")
    s.add_argument("--rotate", action="append", metavar="ID",
                   help="give only this identity a new password (repeat); a router's identity "
                        "(router-NAME, with --site) gets a new key and certificate too")
    s.add_argument("--rover", action="append", metavar="FILE",
                   help="the deployment's rovers, in order: one zenoh-bridge-ros2dds file each "
                        f"(default {' '.join(FLEET_FILES)})")
    s.add_argument("--bridge-config", metavar="FILE", help="bridge mapping (default: the shipped one)")
    s.add_argument("--site", metavar="FILE", help=site_help + "; makes what is missing, keeps the rest")
    s.add_argument("--secrets-dir", metavar="DIR",
                   help="with --site: where the routers find their folders when they run outside "
                        f"Docker (DIR/<router>; default: the container's {ROUTER_SECRETS})")
    o = sub.add_parser("compose", help="write the Docker Compose file of a site (one profile per "
                                       "machine) from its site file")
    o.add_argument("--site", metavar="FILE", required=True, help=site_help)
    o.add_argument("--output", metavar="PATH",
                   help="the file to write, in the repository the images are built from "
                        "(default docker-compose.site.yml)")
    o.add_argument("--secrets", metavar="DIR", default="deploy/secrets",
                   help="the site's secrets folder, relative to the repository (default deploy/secrets)")
    o.add_argument("--check", action="store_true", help="exit 1 if the file is not up to date")
    c = sub.add_parser("check", help="refuse secrets that cannot be trusted (exit 1)")
    c.add_argument("dir", metavar="DIR")
    c.add_argument("--no-tls", action="store_true")
    c.add_argument("--site", metavar="FILE", help=site_help)
    c.add_argument("--router", metavar="NAME",
                   help="with --site: DIR is this router's folder alone (what its machine holds)")


_SITE_ONLY = ("host", "connect", "no_tls", "rover", "bridge_config")


def _site_conflicts(args: argparse.Namespace) -> list[str]:
    """Options a site file decides (its hosts, endpoints, rovers, mapping)."""
    defaults = {"connect": "tls/router:7447"}
    return [f"--{o.replace('_', '-')}" for o in _SITE_ONLY
            if getattr(args, o, None) not in (None, False, defaults.get(o))]


def main(args: argparse.Namespace) -> int:
    if getattr(args, "site", None) is not None:
        return _main_site(args)
    if args.action == "acl":
        mf = load_mapping(args.bridge_config or DEFAULT_MAPPING)
        secrets_dir = ROUTER_SECRETS if args.secrets_dir is None else str(Path(args.secrets_dir).resolve())
        text = render_router_config(mf, fleet_names(args.rover or FLEET_FILES), secrets_dir)
        out = Path(args.output or ROUTER_FILE)
        if args.check:
            if not out.is_file() or out.read_text() != text:
                print(f"{out} is stale: run lunaris deploy acl", file=sys.stderr)
                return 1
            return 0
        out.write_text(text)
        print(f"wrote {out}")
        return 0
    if args.action == "secrets":
        if args.secrets_dir is not None:
            print("lunaris deploy secrets: --secrets-dir goes with --site (one router: "
                  "lunaris deploy acl --secrets-dir)", file=sys.stderr)
            return 2
        hosts = args.host or ["router", "localhost", "127.0.0.1"]
        try:
            written = make_secrets(Path(args.dir), hosts, args.connect, not args.no_tls, args.rotate,
                                   fleet_names(args.rover or FLEET_FILES),
                                   load_mapping(args.bridge_config or DEFAULT_MAPPING))
        except (ValueError, RuntimeError, OSError) as exc:
            print(f"lunaris deploy secrets: {exc}", file=sys.stderr)
            return 2
        print(f"wrote {', '.join(written)} in {args.dir} (keep it private: chmod 700)")
        if args.rotate:
            print("restart the router and the containers of the rotated identities")
        return 0
    if args.router is not None:
        print("lunaris deploy check: --router goes with --site", file=sys.stderr)
        return 2
    return _report(check_secrets(Path(args.dir), not args.no_tls), args.dir)


def _report(problems: list[str], where: str) -> int:
    for problem in problems:
        print(f"lunaris deploy check: {problem}", file=sys.stderr)
    if problems:
        print("lunaris deploy check: REFUSED: the deployment does not start with these secrets",
              file=sys.stderr)
        return 1
    print(f"lunaris deploy check: the secrets in {where} are fit to use")
    return 0


def _main_site(args: argparse.Namespace) -> int:
    from lunaris.deploy_routers import (
        check_router_folder,
        check_site_secrets,
        folder_contents,
        make_site_secrets,
        site_changes,
        write_router_configs,
    )
    from lunaris.deploy_site import load_site

    command = f"lunaris deploy {args.action}"
    conflicts = _site_conflicts(args)
    if conflicts:
        print(f"{command}: {', '.join(conflicts)}: the site file decides (--site)", file=sys.stderr)
        return 2
    try:
        site = load_site(args.site)
        if args.action == "check":
            if args.router is not None:
                if args.router not in {r.name for r in site.routers}:
                    raise ValueError(f"{args.site} has no router {args.router!r}")
                return _report(check_router_folder(Path(args.dir), site, args.router), args.dir)
            return _report(check_site_secrets(Path(args.dir), site), args.dir)
        if args.action == "compose":
            from lunaris.deploy_compose import COMPOSE_FILE, write_site_compose
            out = Path(args.output) if args.output else COMPOSE_FILE
            current = write_site_compose(site, out, args.check, args.secrets)
            if args.check:
                if not current:
                    print(f"{out} is stale: run lunaris deploy compose --site {args.site}",
                          file=sys.stderr)
                return 0 if current else 1
            print(f"{out} is up to date" if current else f"wrote {out}")
            return 0
        if args.action == "secrets":
            before = folder_contents(Path(args.dir), site)
            written = make_site_secrets(Path(args.dir), site, args.rotate, args.secrets_dir)
            if not any(before.values()):  # made now: every folder is new
                print(f"wrote {', '.join(written)} in {args.dir} (keep it private; copy each "
                      "router's folder to its machine only)")
                return 0
            for line in site_changes(site, before, folder_contents(Path(args.dir), site)):
                print(line)
            return 0
        folder = Path(args.output or REPO / "deploy" / "secrets")
        stale = write_router_configs(folder, site, args.secrets_dir, check=args.check)
        if args.check:
            for name in stale:
                print(f"{folder / name} is stale: run lunaris deploy acl --site {args.site}",
                      file=sys.stderr)
            return 1 if stale else 0
        print(f"wrote {', '.join(stale)} in {folder}")
        return 0
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"{command}: {exc}", file=sys.stderr)
        return 2
