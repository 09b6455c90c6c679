"""A crew dashboard as a plain ROS 2 node (rclpy), knowing nothing of Lunaris.

``python dashboard.py TOPIC=pkg/msg/Type ...`` subscribes to each topic (reliable,
transient-local, keep-last 1: it gets the last value when it joins) and prints every message
as one JSON line ``{"topic": ..., "t": <monotonic s>, "msg": {...fields}}``. Each JSON line
read on stdin, ``{"topic": ..., "type": "pkg/msg/Type", "msg": {...}}``, is published on that
topic (reliable, volatile); a line ``{"call": "/service", "type": "pkg/srv/Type", "request":
{...}}`` calls that service (waiting up to 10 s for it) and prints ``{"topic": "/service",
"t": ..., "msg": {...response fields}}``, or ``"msg": null`` when no answer came within
10 s. A line ``{"subscribe": false}`` destroys every subscription (the crew's dashboard gone
from the graph), ``{"subscribe": true}`` makes them again; each prints
``{"topic": "subscribed", "t": ..., "msg": true|false}`` when done. The ROS 2 environment (``ROS_DOMAIN_ID``,
``FASTDDS_BUILTIN_TRANSPORTS``) is the caller's. Prints ``ready`` once its entities exist.
"""

from __future__ import annotations

import importlib
import json
import math
import sys
import threading
import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
_out = threading.Lock()


def message_class(typename: str) -> Any:
    pkg, kind, name = typename.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def as_plain(value: Any) -> Any:
    if hasattr(value, "get_fields_and_field_types"):
        return {f: as_plain(getattr(value, f)) for f in value.get_fields_and_field_types()}
    if isinstance(value, (list, tuple)) or type(value).__name__ in ("array", "ndarray"):
        return [as_plain(v) for v in value]
    if isinstance(value, bytes):  # a ROS `byte` (DiagnosticStatus.level) arrives as bytes
        return value[0] if len(value) == 1 else list(value)
    if isinstance(value, float) and math.isnan(value):
        return None
    if hasattr(value, "item"):  # numpy scalars
        return value.item()
    return value


def fill(msg: Any, fields: dict) -> Any:
    for name, value in fields.items():
        current = getattr(msg, name)
        if isinstance(value, dict):
            fill(current, value)
        else:
            setattr(msg, name, value)
    return msg


def call(node: Node, clients: dict[str, Any], cmd: dict) -> None:
    """Call a service as a dashboard's button does, and print its response."""
    name = cmd["call"]
    cls = message_class(cmd["type"])
    client = clients.get(name)
    if client is None:
        client = clients[name] = node.create_client(cls, name)
    response = None
    if not client.wait_for_service(timeout_sec=10.0):
        print(f"{name}: no such service within 10 s", file=sys.stderr, flush=True)
    else:
        future = client.call_async(fill(cls.Request(), cmd.get("request", {})))
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if done.wait(10.0):
            response = as_plain(future.result())
        else:
            print(f"{name}: no response within 10 s", file=sys.stderr, flush=True)
    line = json.dumps({"topic": name, "t": time.monotonic(), "msg": response})
    with _out:
        print(line, flush=True)


def subscribe(node: Node) -> list[Any]:
    subs = []
    for arg in sys.argv[1:]:
        topic, typename = arg.split("=")

        def show(msg: Any, topic: str = topic) -> None:
            line = json.dumps({"topic": topic, "t": time.monotonic(), "msg": as_plain(msg)})
            with _out:
                print(line, flush=True)
        subs.append(node.create_subscription(message_class(typename), topic, show, LATCHED))
    return subs


def main() -> None:
    rclpy.init()
    node = Node("crew_dashboard")
    subs = subscribe(node)
    publishers: dict[str, Any] = {}
    clients: dict[str, Any] = {}
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    with _out:
        print("ready", flush=True)
    for line in sys.stdin:
        cmd = json.loads(line)
        if "subscribe" in cmd:
            for sub in subs:
                node.destroy_subscription(sub)
            subs = subscribe(node) if cmd["subscribe"] else []
            with _out:
                print(json.dumps({"topic": "subscribed", "t": time.monotonic(),
                                  "msg": bool(subs)}), flush=True)
            continue
        if "call" in cmd:
            call(node, clients, cmd)
            continue
        cls = message_class(cmd["type"])
        pub = publishers.get(cmd["topic"])
        if pub is None:
            pub = publishers[cmd["topic"]] = node.create_publisher(cls, cmd["topic"], COMMAND)
            deadline = time.monotonic() + 10.0  # wait until the bridge's subscription is matched
            while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(0.02)
        pub.publish(fill(cls(), cmd["msg"]))
    # A clean exit: the executor stopped and its thread gone before rclpy shuts down (a
    # thread still spinning at exit ends in "terminate called without an active exception",
    # an unclean death to Fast DDS' shared memory).
    executor.shutdown()
    spinner.join(timeout=5.0)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
