"""``lunaris fault inject|clear|list``: fault control with a readable confirmation (SPEC §6, §8).

``inject ROVER COMPONENT KIND [VALUE]`` puts ``lunaris/<rover>/fault/<component>/<kind>``,
``clear ROVER COMPONENT KIND`` deletes it. The tool subscribes to the rover's
``event`` key *before* it writes, then waits for the event that answers the key
(``fault_injected`` / ``fault_cleared``, or ``rejected``) and prints it.

Exit status: 0 accepted; 1 rejected (by the twin, or refused before sending
because the input cannot be valid); 2 no answer (no router, unknown rover,
nothing answered within ``--timeout``).
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import time

import msgspec
import zenoh

from common import keys
from common.connection import add_connection_args, write
from common.faults import CATALOGUE, FaultKey, parse_fault_key, parse_params
from common.messages import BadInput, Event, decode
from lunaris.tooling import ToolError, open_session, require_rover

__all__ = ["add_arguments", "format_event", "main", "parse_value", "send_fault"]

ACCEPTED = {"inject": "fault_injected", "clear": "fault_cleared"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    common = argparse.ArgumentParser(add_help=False)
    add_connection_args(common)
    common.add_argument("--timeout", type=float, default=3.0, metavar="S",
                        help="how long to wait for the twin's answer (default 3 s)")
    common.add_argument("--json", action="store_true", help="print the answer as JSON")
    common.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="how long to wait for the router (default 10 s)")
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    components = "battery, umbilical, load/<name>, rail/<name>, solar/<panel> or radio/<name>"
    kinds = "; ".join(f"{c}: {', '.join(k)}" for c, k in CATALOGUE.items())

    inject = sub.add_parser("inject", parents=[common], help="inject a fault",
                            description=f"Inject a fault. Kinds - {kinds}.")
    inject.add_argument("rover", help="rover id, e.g. mapp-1")
    inject.add_argument("component", help=components)
    inject.add_argument("kind", help="fault kind")
    inject.add_argument("value", nargs="?", default=None,
                        help='a number for one-parameter kinds, or a JSON object ({"heat_w": 40})')
    inject.add_argument("--no-check", action="store_true",
                        help="send without checking the rover, key and value first")

    clear = sub.add_parser("clear", parents=[common], help="clear a fault")
    clear.add_argument("rover")
    clear.add_argument("component", help=components)
    clear.add_argument("kind")
    clear.add_argument("--no-check", action="store_true", help="send without checking first")

    ls = sub.add_parser("list", parents=[common], help="list the active faults of a rover")
    ls.add_argument("rover")
    ls.add_argument("--journal", type=int, nargs="?", const=20, default=0, metavar="N",
                    help="also show the last N events of the journal (default 20)")


# -- the pieces the scenario player reuses --------------------------------------------------


def parse_value(text: str | None) -> bytes:
    """The payload for VALUE: a JSON number or object, re-encoded compactly; empty for None."""
    if text is None:
        return b""
    try:
        value = json.loads(text)
    except ValueError:
        raise ToolError(f"VALUE must be a number or a JSON object, got {text!r}", 1) from None
    if isinstance(value, bool) or not isinstance(value, int | float | dict):
        raise ToolError(f"VALUE must be a number or a JSON object, got {text!r}", 1)
    return json.dumps(value).encode()


def fault_key(rover: str, component: str, kind: str, check: bool = True) -> tuple[str, FaultKey | None]:
    """The key of a fault; with ``check`` the component and kind must be in the catalogue."""
    key = keys.fault(rover, component.strip("/"), kind)
    if not check:
        return key, None
    try:
        return key, parse_fault_key([*component.strip("/").split("/"), kind])
    except BadInput as exc:
        raise ToolError(f"{exc}", 1) from None


def send_fault(session: zenoh.Session, rover: str, key: str, payload: bytes | None,
               timeout_s: float, accepted: str | None = None) -> Event | None:
    """Put (``payload`` bytes) or delete (``payload`` None) a fault key and return the event
    that answers it, or None when nothing answers within ``timeout_s``. ``accepted`` is the
    event kind that accepts the write, for keys other than faults (``input``).

    The event subscriber is declared, and a round trip to the router made, before the
    write, so the answer cannot be missed.
    """
    wanted = {"rejected", accepted or ACCEPTED["clear" if payload is None else "inject"]}
    answers: queue.SimpleQueue[Event] = queue.SimpleQueue()

    def on_event(s: zenoh.Sample) -> None:
        try:
            ev = decode(s.payload.to_bytes(), Event)
        except msgspec.DecodeError:
            return
        if ev.key == key and ev.kind in wanted:
            answers.put(ev)

    sub = session.declare_subscriber(keys.event(rover), on_event)
    try:
        # The router handles a client's messages in order: once this query is answered it
        # has our subscription, so the answer to the write below will reach us.
        list(session.liveliness().get(keys.service(rover, "*"), timeout=min(2.0, timeout_s)))
        write(session, key, payload)
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            try:
                return answers.get(timeout=min(remaining, 0.2))
            except queue.Empty:
                continue
    finally:
        sub.undeclare()


def format_event(ev: Event) -> str:
    verdict = "rejected" if ev.kind == "rejected" else "accepted"
    return f"{verdict}: {ev.kind} at t={ev.t_s:.1f} s [{ev.source}] {ev.message}  ({ev.key})"


# -- the command ----------------------------------------------------------------------------


def main(args: argparse.Namespace) -> int:
    try:
        if args.action == "list":
            return _list(args)
        return _write(args)
    except ToolError as exc:
        print(f"lunaris fault: {exc}", file=sys.stderr)
        return exc.code


def _write(args: argparse.Namespace) -> int:
    check = not args.no_check
    key, fk = fault_key(args.rover, args.component, args.kind, check)
    payload: bytes | None = None
    if args.action == "inject":
        payload = parse_value(args.value) if check or args.value is None else args.value.encode()
        if fk is not None:
            try:
                parse_params(fk, payload)
            except BadInput as exc:
                raise ToolError(f"{fk.component} {fk.kind}: {exc}", 1) from None
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    try:
        if check:
            require_rover(session, args.rover)
        ev = send_fault(session, args.rover, key, payload, args.timeout)
    finally:
        session.close()
    if ev is None:
        what = "injection" if payload is not None else "clearing"
        print(f"no answer within {args.timeout:g} s to the {what} of {key}: "
              f"is the service that owns it running?", file=sys.stderr)
        return 2
    if args.json:
        print(msgspec.json.encode(ev).decode())
    else:
        print(format_event(ev))
    return 1 if ev.kind == "rejected" else 0


def _list(args: argparse.Namespace) -> int:
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    try:
        active = _get_json(session, keys.faults(args.rover), args.timeout)
        journal = (_get_json(session, f"{keys.faults_journal(args.rover)}?last={args.journal}", args.timeout)
                   if args.journal else [])
    finally:
        session.close()
    if active is None:
        print(f"no answer from the faults service of {args.rover!r} within {args.timeout:g} s "
              "(unknown rover, or the faults service is not running)", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({"active": active, "journal": (journal or [])[-args.journal:]}))
        return 0
    prefix = keys.rover_prefix(args.rover) + "/"
    if not active:
        print(f"{args.rover}: no active faults")
    else:
        print(f"{args.rover}: {len(active)} active fault(s)")
        print(f"  {'since t_s':>10}  {'severity':<9} {'origin':<8} {'fault':<36} params")
        for f in active:
            name = f["key"].removeprefix(prefix).removeprefix("fault/")
            params = json.dumps(f.get("params") or {}) if f.get("params") else ""
            print(f"  {f['since_t_s']:10.1f}  {f.get('severity', ''):<9} {f['origin']:<8} "
                  f"{name:<36} {params}")
    if args.journal:
        events = (journal or [])[-args.journal:]
        print(f"last {len(events)} event(s):")
        for e in events:
            print(f"  {e['t_s']:10.1f}  {e['severity']:<9} {e['kind']:<15} [{e['source']}] {e['message']}")
    return 0


def _get_json(session: zenoh.Session, selector: str, timeout_s: float) -> list | None:
    """The JSON list answered for ``selector`` (replies merged), None if nobody answered."""
    out: list | None = None
    for reply in session.get(selector, timeout=timeout_s):
        if reply.ok is None:
            continue
        out = (out or []) + json.loads(reply.ok.payload.to_bytes())
    return out
