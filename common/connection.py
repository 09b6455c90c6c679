"""How every Lunaris process reaches Zenoh: one set of options, one Config builder.

``--connect ENDPOINT`` / ``--listen ENDPOINT`` or ``LUNARIS_ZENOH_CONFIG`` naming
a Zenoh JSON5 file (credentials, TLS). Whatever the source, multicast scouting
is switched off (SPEC §11: endpoints are always explicit), timestamping is
on (the advanced publishers' caches need it) and each link's send queues hold a
fleet's tick (:data:`TX_QUEUE_SIZE`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
from pathlib import Path

import zenoh

__all__ = ["DEFAULT_ENDPOINT", "TX_QUEUE_SIZE", "ConnectionConfigError", "add_connection_args",
           "config_from_args", "is_demo_password", "make_config", "write"]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
CONFIG_ENV = "LUNARIS_ZENOH_CONFIG"
# Batches of 64 kB a link may queue per priority before a sample sent with
# CongestionControl.DROP (telemetry) is dropped; Zenoh's default is 2. A fleet's tick is a
# burst: at 100 rovers the PDM publishes ~700 samples (~175 kB) at once and the router
# forwards ~1,100 to each bridge shard. With 2 batches, whenever a link's thread waited for a
# core, PDM summaries and rail states of 20-36 rovers at a time were lost (each rover 5 of
# 600 ticks in a minute, measured by a subscriber of its own); with 16, the most Zenoh allows
# (allocated only when used), none. Telemetry (DATA) and what goes ahead of it (PRIORITY).
TX_QUEUE_SIZE = {"data_high": 16, "data": 16}


class ConnectionConfigError(ValueError):
    """A connection setting that cannot work (a configuration file that does not exist)."""


def add_connection_args(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("connection")
    group.add_argument("--connect", action="append", metavar="ENDPOINT",
                       help=f"router endpoint to connect to (default {DEFAULT_ENDPOINT})")
    group.add_argument("--listen", action="append", metavar="ENDPOINT",
                       help="endpoint to listen on")
    group.add_argument("--config", metavar="FILE",
                       help=f"Zenoh JSON5 configuration (default: ${CONFIG_ENV})")


def make_config(
    mode: str = "client",
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    config_file: str | os.PathLike | None = None,
) -> zenoh.Config:
    """A Zenoh configuration for a Lunaris process.

    ``config_file`` (or ``$LUNARIS_ZENOH_CONFIG``) is the base; explicit ``connect``
    and ``listen`` endpoints override its endpoints. A client with no endpoint at all
    connects to :data:`DEFAULT_ENDPOINT`.
    """
    config_file = config_file or os.environ.get(CONFIG_ENV) or None
    if config_file:
        path = Path(config_file)
        if not path.is_file():
            raise ConnectionConfigError(f"Zenoh configuration {str(path)!r} does not exist")
        conf = zenoh.Config.from_file(str(path))
        _refuse_demo_password(conf, path)
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(mode))
        if mode == "client" and not connect:
            connect = [DEFAULT_ENDPOINT]
    if config_file and mode == "router":
        conf.insert_json5("mode", json.dumps(mode))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    elif not config_file and mode == "client":
        conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("timestamping/enabled", "true")
    for priority, batches in TX_QUEUE_SIZE.items():
        conf.insert_json5(f"transport/link/tx/queue/size/{priority}", str(batches))
    if mode == "client":
        # Wait for a router that is not up yet, and keep retrying after it goes away.
        conf.insert_json5("connect/timeout_ms", "-1")
        conf.insert_json5("connect/exit_on_failure", "false")
    return conf


def config_from_args(args: argparse.Namespace, mode: str = "client") -> zenoh.Config:
    return make_config(mode, connect=args.connect, listen=args.listen, config_file=args.config)


DEMO_MARK = "CHANGE-ME"
_DEMO = re.compile(r"(^|[^a-z0-9])demo|change-?me", re.IGNORECASE)


def is_demo_password(password: str) -> bool:
    """A password marked as a shipped demo one, in any case: ``demo-...``, ``Demo-...``,
    ``...-demo-...``, anything holding ``CHANGE-ME``."""
    return _DEMO.search(password) is not None


def _refuse_demo_password(conf: zenoh.Config, path: Path) -> None:
    """A shipped demo password is public: a client configuration holding one is refused."""
    try:
        password = json.loads(conf.get_json("transport/auth/usrpwd/password"))
    except (zenoh.ZError, ValueError):
        return
    if isinstance(password, str) and is_demo_password(password):
        raise ConnectionConfigError(
            f"{path} holds a shipped demo password: make the deployment's secrets with "
            "`lunaris deploy secrets DIR` and use its client configurations")


# What must never wait behind telemetry: instructor writes, events, the faults in effect.
# Zenoh queues each priority apart on a link and sends the higher first.
PRIORITY = zenoh.Priority.DATA_HIGH


def write(session: zenoh.Session, key: str, payload: bytes | str | None) -> None:
    """An input, command or fault: a put (``payload``) or a delete (None), never dropped.

    Zenoh drops a put under congestion unless it is sent with ``CongestionControl.BLOCK``;
    a burst of instructor actions must arrive whole, so every Lunaris tool writes this way.
    It goes at ``PRIORITY``, ahead of a fleet's telemetry queued on the same links.
    """
    if payload is None:
        session.delete(key, congestion_control=zenoh.CongestionControl.BLOCK, priority=PRIORITY)
    else:
        session.put(key, payload, encoding=zenoh.Encoding.APPLICATION_JSON,
                    congestion_control=zenoh.CongestionControl.BLOCK, priority=PRIORITY)
