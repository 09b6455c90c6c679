"""``lunaris fault inject|clear|arm|disarm|list``: fault control with a readable confirmation
(SPEC §6, §8, 13b).

``inject ROVER COMPONENT KIND [VALUE]`` puts ``lunaris/<rover>/fault/<component>/<kind>``,
``clear ROVER COMPONENT KIND`` deletes it, through the client's writer
(:mod:`lunaris.confirm`), which prints the event that answers it (``fault_injected`` /
``fault_cleared``, or ``rejected``) or why it was not applied. ``list ROVER`` asks the faults
service for the faults in effect (``get lunaris/<rover>/faults``): it gathers them from their
owners, and says which owner did not answer; the list then says so, and exits 2, rather than
claim fewer faults.

Exit status: 0 accepted (listed in full); 1 rejected (by the twin, or refused before sending
because the input cannot be valid); 2 not applied (no router, unknown rover, the owner out of
reach, nothing answered within ``--timeout``), or a list with owners missing.

``arm ROVER COMPONENT KIND [VALUE] (--at T | --in S | --when COND) [--warn S]`` puts
``lunaris/<rover>/faults/armed/<component>/<kind>``: the faults service fires the fault at sim
time ``T``, ``S`` seconds of sim time from now, or ``--warn`` seconds after ``COND`` (the
scenario language) first holds, with a warning ``--warn`` seconds before (default 10);
``disarm`` cancels it. Each is answered by ``fault_armed`` / ``fault_cancelled`` or
``rejected``. ``list`` shows the armed faults (``get lunaris/<rover>/faults/armed``) after
the faults in effect.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap

import zenoh

from common import keys
from common.connection import add_connection_args
from common.faults import CATALOGUE, NAMED_COMPONENTS, NoParams, parameters, parse_fault_key
from common.messages import BadInput
from common.writes import Write, answer_of
from lunaris.client import ANSWER_S, Mirror, ToolError, close_session, humane, open_session, shown
from lunaris.confirm import confirm, plan, tool_main

__all__ = ["add_arguments", "catalogue_help", "main", "parse_value"]


def catalogue_help(width: int = 79) -> str:
    """Every fault kind in an instructor's words, for ``inject --help``: what to type, what
    it does, and what its value means, from the catalogue (:mod:`common.faults`)."""
    out = ["faults (COMPONENT KIND, then VALUE where the kind takes one):"]
    wrap = textwrap.TextWrapper(width=width, initial_indent="      ", subsequent_indent="      ")
    for component, kinds in CATALOGUE.items():
        part = f"{component}/<{'panel' if component == 'solar' else 'name'}>" \
            if component in NAMED_COMPONENTS else component
        for kind, spec in kinds.items():
            params = parameters(spec.params)
            value = "" if not params else " VALUE" if params[0].default is None else " [VALUE]"
            out.append(f"  {part} {kind}{value}")
            out.append(wrap.fill(f"{spec.name}: {spec.effect}."))
            out += [wrap.fill(f"{'VALUE' if len(params) == 1 else p.name}: {p.label} "
                              f"[{p.unit}] - {p.hint}") for p in params]
    out.append("\nexample: lunaris fault inject mapp-1 battery heating 40")
    return "\n".join(out)


def add_arguments(p: argparse.ArgumentParser) -> None:
    common = argparse.ArgumentParser(add_help=False)
    add_connection_args(common)
    common.add_argument("--timeout", type=float, default=ANSWER_S, metavar="S",
                        help=f"how long to wait for the twin's answer (default {ANSWER_S:g} s)")
    common.add_argument("--json", action="store_true", help="print the answer as JSON")
    common.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="how long to wait for a router that does not answer (default 10 s)")
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    components = "battery, umbilical, load/<name>, rail/<name>, solar/<panel> or radio/<name>"
    inject = sub.add_parser("inject", parents=[common], help="inject a fault",
                            description="Inject a fault: one of those listed below, on a "
                                        "component of the rover.", epilog=catalogue_help(),
                            formatter_class=argparse.RawDescriptionHelpFormatter)
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

    arm = sub.add_parser("arm", parents=[common], help="arm a fault for a time or a condition",
                         description="Arm a fault (one of those of `inject --help`) to fire at a "
                                     "sim time, some seconds of sim time from now, or when a "
                                     "condition holds, with a warning before it fires. The "
                                     "faults service fires it as your injection; `disarm` "
                                     "cancels it until then.",
                         epilog='example: lunaris fault arm mapp-1 battery heating 40 --when '
                                '"battery.soc < 0.5" --warn 30',
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    arm.add_argument("rover", help="rover id, e.g. mapp-1")
    arm.add_argument("component", help=components)
    arm.add_argument("kind", help="fault kind")
    arm.add_argument("value", nargs="?", default=None,
                     help='a number for one-parameter kinds, or a JSON object ({"heat_w": 40})')
    trigger = arm.add_mutually_exclusive_group(required=True)
    trigger.add_argument("--at", type=float, dest="at_t_s", metavar="T",
                         help="fire at the rover's sim time T [s]")
    trigger.add_argument("--in", type=float, dest="in_s", metavar="S",
                         help="fire S seconds of sim time from now")
    trigger.add_argument("--when", metavar="COND",
                         help='fire --warn seconds after COND first holds ("battery.soc < 0.5"; '
                              "the scenario language)")
    arm.add_argument("--warn", type=float, default=10.0, dest="warn_s", metavar="S",
                     help="warn S seconds of sim time before it fires (default 10)")

    disarm = sub.add_parser("disarm", parents=[common], help="cancel an armed fault")
    disarm.add_argument("rover")
    disarm.add_argument("component", help=components)
    disarm.add_argument("kind")

    ls = sub.add_parser("list", parents=[common],
                        help="list the active faults of a rover, and those armed")
    ls.add_argument("rover")
    ls.add_argument("--journal", type=int, nargs="?", const=20, default=0, metavar="N",
                    help="also show the last N events of the journal (default 20)")


# -- the command ----------------------------------------------------------------------------


def parse_value(text: str | None) -> bytes:
    """The payload for VALUE: a JSON number or object, re-encoded compactly; empty for None."""
    if text is None:
        return b""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:  # bytes that are not text, as the shell passed them
        raise ToolError("VALUE must be a number or a JSON object, and what was given is not even "
                        "text (bytes that are not UTF-8)", 1) from None
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        raise ToolError(f"VALUE must be a number or a JSON object, got {shown(text)}", 1) from None
    if isinstance(value, bool) or not isinstance(value, int | float | dict):
        raise ToolError(f"VALUE must be a number or a JSON object, got {shown(text)}", 1)
    return json.dumps(value).encode()


def main(args: argparse.Namespace) -> int:
    run = {"list": _list, "arm": _arm, "disarm": _arm}.get(args.action, _write)
    return tool_main("fault", run, args)


def _arm(args: argparse.Namespace) -> int:
    """``arm`` and ``disarm``: planned as the faults service checks them (the key, the value as
    ``inject`` takes it, the trigger and its condition), then sent and confirmed."""
    component = args.component.strip("/")
    tail = f"faults/armed/{component}/{args.kind}"
    disarm = plan(args.rover, tail, None)  # the key: a component and kind of the catalogue
    if args.action == "disarm":
        return confirm(args, "fault", disarm)
    body = {"value": None if args.value is None else json.loads(parse_value(args.value)),
            "at_t_s": args.at_t_s, "in_s": args.in_s, "when": args.when, "warn_s": args.warn_s}
    try:
        write = plan(args.rover, tail, json.dumps(body).encode())
    except ToolError as exc:
        raise ToolError(f"{component} {args.kind}: {exc}", 1) from None
    return confirm(args, "fault", write)


def _write(args: argparse.Namespace) -> int:
    component = args.component.strip("/")
    tail = f"fault/{component}/{args.kind}"
    if args.no_check:  # sent as given: the twin answers for it
        payload = None if args.action == "clear" else (args.value or "").encode()
        try:
            accepted, owner = answer_of(tail.split("/"), payload is None)
        except BadInput:  # no owner: the gatekeeper (the faults service) rejects it
            accepted, owner = ("fault_cleared" if payload is None else "fault_injected"), "faults"
        write = Write(keys.under(args.rover, tail), payload, accepted, owner)
    else:
        write = plan(args.rover, tail, None)  # the key: a component and kind of the catalogue
        kind = parse_fault_key(tail.split("/")[1:])
        if args.action == "inject" and args.value is not None and \
                CATALOGUE[kind.component][kind.kind].params is NoParams:
            raise ToolError(f"{component} {args.kind} takes no parameters: leave VALUE out (lunaris "
                            f"fault inject {args.rover} {component} {args.kind})", 1)
        if args.action == "inject":
            payload = parse_value(args.value)
            try:
                write = plan(args.rover, tail, payload)
            except ToolError as exc:  # the parameters
                raise ToolError(f"{component} {args.kind}: {exc}", 1) from None
    return confirm(args, "fault", write)


def _list(args: argparse.Namespace) -> int:
    session = open_session(args, wait_s=args.wait, on_waiting=lambda: print(
        "waiting for the Zenoh router ...", file=sys.stderr, flush=True))
    mirror = Mirror(args.rover, families=("clock",), events=False)
    try:
        mirror.start(session)
        active, missing = _get_faults(session, keys.faults(args.rover), args.timeout)
        journal, _ = (_get_faults(session, f"{keys.faults_journal(args.rover)}?last={args.journal}",
                                  args.timeout) if args.journal else ([], []))
        armed, _ = _get_faults(session, keys.faults_armed(args.rover), args.timeout)
        link = mirror.link(args.rover)
    finally:
        mirror.close()
        close_session(session)
    if active is None:
        why = "; ".join(missing) or (f"no answer from the faults service of {args.rover!r} within "
                                     f"{args.timeout:g} s (unknown rover, or the faults service is "
                                     "not running)")
        print(f"lunaris fault: {why}", file=sys.stderr)
        return 2
    if link.state == "lost":
        missing.append(f"the link to {args.rover} is lost ({link.reason}): faults in effect behind "
                       "it may not be listed")
    if args.json:
        print(json.dumps({"active": active, "armed": armed or [],
                          "journal": (journal or [])[-args.journal:], "missing": missing}))
        return 2 if missing else 0
    prefix = keys.rover_prefix(args.rover) + "/"
    if not active and not missing:
        print(f"{args.rover}: no active faults")
    elif not active:
        print(f"{args.rover}: no fault listed, but NOT every owner answered: the faults in effect "
              "on the components of those listed below are unknown")
    else:
        print(f"{args.rover}: {len(active)} active fault(s)"
              + (", but NOT every owner answered: more may be in effect" if missing else ""))
        print(f"  {'since t_s':>10}  {'severity':<9} {'origin':<8} {'fault':<36} params")
        for f in active:
            name = f["key"].removeprefix(prefix).removeprefix("fault/")
            params = json.dumps(f.get("params") or {}) if f.get("params") else ""
            print(f"  {f['since_t_s']:10.1f}  {f.get('severity', ''):<9} {f['origin']:<8} "
                  f"{name:<36} {params}")
    for why in missing:
        print(f"  not listed: {why}")
    _print_armed(args.rover, armed)
    if args.journal:
        events = (journal or [])[-args.journal:]
        print(f"last {len(events)} event(s):")
        for e in events:
            actor = e.get("actor") or "twin"  # who acted: the crew's calls apart from the rest
            by = "" if actor == "twin" else f", by the {actor}"
            print(f"  {e['t_s']:10.1f}  {e['severity']:<9} {e['kind']:<15} [{e['source']}{by}] "
                  f"{e['message']}")
    return 2 if missing else 0


def _print_armed(rover: str, armed: list | None) -> None:
    """The armed faults, one a line: what fires, when, and its warning."""
    if armed is None:
        print(f"{rover}: armed faults unknown (the faults service did not answer)")
        return
    if not armed:
        return
    print(f"{rover}: {len(armed)} armed fault(s)")
    print(f"  {'armed t_s':>10}  {'fault':<36} {'fires':<34} warning")
    for a in armed:
        value = "" if a.get("value") is None else " " + json.dumps(a["value"])
        if a.get("when") is not None:
            fires = (f"at t={a['due_t_s']:.1f} s ({a['when']} held)" if a.get("due_t_s") is not None
                     else f"when {a['when']}")
        else:
            fires = f"at t={a['due_t_s']:.1f} s"
        warned = (f"given at t={a['warned_t_s']:.1f} s" if a.get("warned_t_s") is not None
                  else f"{a['warn_s']:g} s before")
        print(f"  {a['armed_t_s']:10.1f}  {a['fault'] + value:<36} {fires:<34} {warned}"
              f"  (by the {a.get('actor', 'instructor')})")


def _get_faults(session: zenoh.Session, selector: str, timeout_s: float) -> tuple[list | None, list[str]]:
    """The JSON lists answered for ``selector`` (replies merged; None if no list came) and the
    errors replied (an owner that did not answer, in the faults service's words)."""
    out: list | None = None
    errors: list[str] = []
    for reply in session.get(selector, timeout=timeout_s, consolidation=zenoh.ConsolidationMode.NONE):
        if reply.ok is not None:
            out = (out or []) + json.loads(reply.ok.payload.to_bytes())
        elif reply.err is not None:
            errors.append(humane(reply.err.payload.to_bytes().decode("utf-8", "replace")))
    return out, errors
