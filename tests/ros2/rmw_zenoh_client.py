"""An independent rmw_zenoh client (``zenoh-ros2-sdk`` from PyPI), knowing nothing of Lunaris.

``python rmw_zenoh_client.py PORT DOMAIN MSGDEFS``: connects to the router on
``127.0.0.1:PORT`` with the session configuration named by ``ZENOH_SESSION_CONFIG_URI``, takes
every message definition from the folder ``MSGDEFS`` (and fetches nothing: a definition
missing there is an error), lists the topics of ``DOMAIN`` from the liveliness tokens as
``ros2 topic list`` does, subscribes to every published one and prints JSON lines:

- ``{"topics": {topic: [types]}, "tokens": [publisher tokens]}`` once;
- ``{"topic": ..., "msg": {...}}`` for each message, decoded by the SDK;
- ``{"topic": ..., "attachment": {"sequence", "gid"}}`` for each sample's attachment.

Each stdin line ``{"topic": ..., "type": ..., "msg": {...}}`` is published by an SDK publisher;
a line ``{"call": "/service", "type": "std_srvs/srv/SetBool", "request": {...}}`` calls the
service with an SDK service client (5 s) and prints ``{"call": ..., "response": {...} or null}``.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from typing import Any

import numpy
import zenoh_ros2_sdk as sdk
from zenoh_ros2_sdk import message_registry

_out = threading.Lock()


def emit(item: dict) -> None:
    with _out:
        print(json.dumps(item), flush=True)


def plain(value: Any) -> Any:
    if hasattr(value, "__dataclass_fields__"):
        return {k: plain(getattr(value, k)) for k in value.__dataclass_fields__
                if k != "__msgtype__" and not k.isupper()}
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


def no_fetching(*args: Any, **kwargs: Any) -> None:
    raise RuntimeError(f"a message definition was not found locally: {args} (nothing is fetched)")


def main() -> None:
    port, domain, msgdefs = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    message_registry.get_repository_for_package = no_fetching  # the SDK may not go online
    sdk.get_registry(msgdefs)
    session = sdk.ZenohSession.get_instance("127.0.0.1", port)
    deadline = time.monotonic() + 20.0
    topics: list[tuple[str, list[str]]] = []
    while time.monotonic() < deadline:
        topics = sdk.get_topic_names_and_types(domain_id=domain, router_port=port, timeout=1.0)
        if any(t == "/battery_state" for t, _ in topics):
            break
        time.sleep(0.2)
    tokens = [str(r.ok.key_expr) for r in session.session.liveliness().get(
        f"@ros2_lv/{domain}/**", timeout=2.0) if r.ok is not None]
    emit({"topics": dict(topics), "tokens": tokens})
    published = {t.split("/")[9].replace("%", "/") for t in tokens if t.split("/")[5] == "MP"}

    def on_raw(s: Any) -> None:
        att = s.attachment.to_bytes() if s.attachment is not None else b""
        topic = "/" + "/".join(str(s.key_expr).split("/")[1:-2])
        emit({"topic": topic, "attachment": {"sequence": int.from_bytes(att[:8], "little"),
                                             "gid": att[17:].hex(), "length": len(att)}})

    keep = [session.session.declare_subscriber(f"{domain}/**", on_raw)]
    for topic, types in topics:
        if topic in published:
            keep.append(sdk.ROS2Subscriber(
                topic, types[0], lambda m, t=topic: emit({"topic": t, "msg": plain(m)}),
                domain_id=domain, router_port=port))
    publishers: dict[str, Any] = {}
    clients: dict[str, Any] = {}
    emit({"ready": True})
    for line in sys.stdin:
        cmd = json.loads(line)
        if "call" in cmd:
            client = clients.get(cmd["call"])
            if client is None:
                # the SDK cannot read Trigger.srv's empty request: its definitions given as rosidl
                # generates them (research notes, zenoh-ros2-sdk 0.1.8)
                empty = cmd["type"] == "std_srvs/srv/Trigger"
                client = clients[cmd["call"]] = sdk.ROS2ServiceClient(
                    cmd["call"], cmd["type"], domain_id=domain, router_port=port, timeout=5.0,
                    **({"request_definition": "uint8 structure_needs_at_least_one_member",
                        "response_definition": "bool success\nstring message"} if empty else {}))
            response = client.call(**cmd.get("request", {}))
            emit({"call": cmd["call"], "key": client.keyexpr,
                  "response": None if response is None else plain(response)})
            continue
        pub = publishers.get(cmd["topic"])
        if pub is None:
            pub = publishers[cmd["topic"]] = sdk.ROS2Publisher(
                cmd["topic"], cmd["type"], domain_id=domain, router_port=port)
        fields = dict(cmd["msg"])
        if cmd["type"].endswith("MultiArray"):  # the nested layout as the SDK's type store has it
            pub.publish(layout=session.store.types["std_msgs/msg/MultiArrayLayout"](
                dim=[], data_offset=0), data=numpy.array(fields["data"], dtype=numpy.float64))
        else:
            pub.publish(**fields)
    del keep


if __name__ == "__main__":
    main()
