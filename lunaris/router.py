"""``lunaris router``: a standalone embedded Zenoh router (a Python session in router mode).

It logs as ``zenohd`` does: ``RUST_LOG`` chooses what (default: errors only), e.g.
``RUST_LOG=info,zenoh::net::routing::interceptor::access_control=trace`` shows every
decision of the access control."""

from __future__ import annotations

import argparse
import signal
import threading

import zenoh

from common.connection import DEFAULT_ENDPOINT, add_connection_args, make_config

__all__ = ["add_arguments", "main", "open_router"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_args(p)


def open_router(listen: list[str] | None, connect: list[str] | None = None,
                config_file: str | None = None) -> zenoh.Session:
    return zenoh.open(make_config("router", connect=connect,
                                  listen=listen or (None if config_file else [DEFAULT_ENDPOINT]),
                                  config_file=config_file))


def main(args: argparse.Namespace) -> int:
    zenoh.init_log_from_env_or("error")
    listen = args.listen or ([] if args.config else [DEFAULT_ENDPOINT])
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with open_router(args.listen, args.connect, args.config):
        print(f"lunaris router: listening on {', '.join(listen) or 'the configured endpoints'}",
              flush=True)
        stop.wait()
    return 0
