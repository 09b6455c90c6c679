"""A Zenoh client driven line by line: a test's hands and eyes on another machine.

``python -m tests.deploy.remote --config client-<identity>.json5`` opens a session under one
identity (on a machine of tests/netns.py, through ``ip netns exec``), then reads commands,
one JSON object a line, on stdin and answers on stdout, one JSON object a line. Times are
``time.monotonic()``: the same clock in every process of the host, whatever its namespace.

    {"op": "sub", "id": "d", "key": "diagnostics", "decode": "diagnostics"}   subscribe
    {"op": "pub", "key": K}                 declare a publisher (as the console writes)
    {"op": "put", "key": K, "payload": P, "id": 3}   -> {"op": "sent", "id": 3, "t": ...}
    {"op": "delete", "key": K, "id": 4}     -> {"op": "sent", ...}
    {"op": "get", "selector": S, "id": 5}   -> {"op": "replies", "id": 5, "ok": [...], "err": [...]}
    {"op": "alive", "key": K, "id": 6}      -> {"op": "tokens", "id": 6, "keys": [...]}
    {"op": "matching", "key": K, "id": 7}   -> {"op": "matched", "id": 7, "matching": bool}
    {"op": "quit"}

and, for every sample of a subscription, ``{"op": "sample", "id": ..., "key": ..., "t": ...,
"kind": "put"|"delete", "payload": ...}`` (decoded: ``json``, ``diagnostics`` (the statuses of
a DiagnosticArray in CDR) or ``text``). ``{"op": "ready"}`` says the session is open.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

import zenoh

from common.connection import make_config

_out = threading.Lock()


def say(**fields: Any) -> None:
    line = json.dumps(fields)
    with _out:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def decode(how: str, payload: bytes) -> Any:
    if how == "json":
        try:
            return json.loads(payload) if payload else None
        except ValueError:
            return payload.decode(errors="replace")
    if how == "diagnostics":
        from tests import rosmsg
        msg = rosmsg.decode("diagnostic_msgs/msg/DiagnosticArray", payload)
        return [{"name": s.name, "message": s.message,
                 "level": s.level[0] if isinstance(s.level, bytes) else int(s.level)}
                for s in msg.status]
    return payload.decode(errors="replace")


def _on_sample(sid: str, how: str) -> Any:
    def on_sample(s: zenoh.Sample) -> None:
        t = time.monotonic()
        kind = "delete" if s.kind == zenoh.SampleKind.DELETE else "put"
        try:
            payload = decode(how, s.payload.to_bytes()) if kind == "put" else None
        except Exception as exc:  # noqa: BLE001 - said, not hidden
            payload = f"undecodable: {exc}"
        say(op="sample", id=sid, key=str(s.key_expr), t=t, kind=kind, payload=payload)
    return on_sample


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--config", required=True)
    p.add_argument("--connect", action="append")
    args = p.parse_args()
    session = zenoh.open(make_config("client", connect=args.connect, config_file=args.config))
    keep: list[Any] = []
    pubs: dict[str, zenoh.Publisher] = {}
    say(op="ready")
    for line in sys.stdin:
        if not line.strip():
            continue
        cmd = json.loads(line)
        op = cmd["op"]
        if op == "quit":
            break
        if op == "sub":
            keep.append(session.declare_subscriber(
                cmd["key"], _on_sample(cmd["id"], cmd.get("decode", "json"))))
            say(op="subscribed", id=cmd["id"])
        elif op == "pub":
            pubs[cmd["key"]] = session.declare_publisher(cmd["key"])
            say(op="declared", id=cmd.get("id"), key=cmd["key"])
        elif op in ("put", "delete"):
            key, pub = cmd["key"], pubs.get(cmd["key"])
            t = time.monotonic()
            if op == "put" and pub is not None:
                pub.put(cmd.get("payload", ""))
            elif op == "put":
                session.put(key, cmd.get("payload", ""))
            elif pub is not None:
                pub.delete()
            else:
                session.delete(key)
            say(op="sent", id=cmd.get("id"), t=t)
        elif op == "matching":
            say(op="matched", id=cmd.get("id"), matching=pubs[cmd["key"]].matching_status.matching)
        elif op == "get":
            ok, err = [], []
            for r in session.get(cmd["selector"], timeout=cmd.get("timeout", 5.0)):
                if r.ok is not None:
                    ok.append({"key": str(r.ok.key_expr),
                               "payload": decode("json", r.ok.payload.to_bytes())})
                else:
                    err.append(r.err.payload.to_bytes().decode(errors="replace"))
            say(op="replies", id=cmd.get("id"), ok=ok, err=err)
        elif op == "alive":
            found = [str(r.ok.key_expr) for r in session.liveliness().get(cmd["key"], timeout=5.0)
                     if r.ok is not None]
            say(op="tokens", id=cmd.get("id"), keys=sorted(found))
        else:
            say(op="error", message=f"unknown op {op!r}")
    keep.clear()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
