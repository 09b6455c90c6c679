"""The faults in effect on the components one service owns: the one record of them.

A fault's whole life happens in the service that owns its component (SPEC §6): the
battery service owns ``fault/battery/**``, the loads service ``fault/load/**`` and so
on. Its :class:`FaultBook`

- validates an injection or clearing (the component's name, the kind, the parameters,
  decoded once into the kind's typed Struct, :data:`common.faults.Fault`), hands the model
  the faults now in effect on that component (``apply(rover, name, faults)``: the model
  applies them and keeps no record of its own), and journals it as an event;
- raises and resolves the faults the models derive themselves, on transitions;
- persists the injected faults, so a restarted service re-applies them (a saved fault that
  is damaged is skipped and said aloud, the others re-applied);
- publishes ``lunaris/<rover>/faults/active/<service>`` on every change (cached for late
  joiners: the bridge's ``/diagnostics``, ``lunaris watch``, the console) and answers a
  query on that key from the book itself, which is what ``get lunaris/<rover>/faults``
  gathers (see ``services/faults``).

Nothing else keeps a list of active faults; the others are views of these.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from typing import Any

import msgspec
import zenoh

from common import keys
from common.faults import Fault, FaultKey, params_from_dict, parse_fault_key, parse_params
from common.host import Host, Sample
from common.messages import ActiveFault, ActiveFaults, BadInput, Severity, encode
from common.state_store import Damaged, not_finite

__all__ = ["FaultApply", "FaultBook", "saved_fault"]

# rover, the component's name (None for battery and umbilical), every fault in effect on it
FaultApply = Callable[[str, str | None, tuple[Fault, ...]], None]
Names = Callable[[str], Iterable[str]]


def _target(path: str) -> tuple[str, str | None]:
    """The component a fault's path names: ``load/nav_camera/short`` -> ``(load, nav_camera)``,
    ``battery/heating`` -> ``(battery, None)``."""
    parts = path.split("/")
    return parts[0], (parts[1] if len(parts) == 3 else None)


def saved_fault(raw: Any) -> tuple[ActiveFault, FaultKey, Fault]:
    """A saved injected fault (a record of :meth:`FaultBook._save`, or of a snapshot), checked
    as an injection is: ValueError naming what is wrong (its key, a parameter's type or
    range, a number that is not finite)."""
    try:
        fault = msgspec.convert(raw, ActiveFault)
    except msgspec.ValidationError as exc:
        raise ValueError(str(exc)) from None
    bad = not_finite(fault.params) or (None if not_finite(fault.since_t_s) is None else "since_t_s")
    if bad:
        raise ValueError(f"{bad} is not a finite number")
    try:
        _, parts = keys.split(fault.key)
        if parts[:1] != ["fault"]:
            raise BadInput(f"{fault.key} is not a fault key")
        fk = parse_fault_key(parts[1:])
        return fault, fk, params_from_dict(fk, fault.params)
    except (BadInput, ValueError) as exc:
        raise ValueError(str(exc)) from None


class FaultBook:
    def __init__(self, rt: Host):
        self.rt = rt
        self.injected: dict[str, dict[str, tuple[ActiveFault, Fault]]] = {r: {} for r in rt.rovers}
        self.derived: dict[str, dict[str, ActiveFault]] = {r: {} for r in rt.rovers}
        self._appliers: dict[str, FaultApply] = {}
        self._declared = False

    # -- injected faults ---------------------------------------------------------------------

    def own(self, component: str, names: Names | None, apply: FaultApply) -> None:
        """Own the faults of one component type (``battery``, ``load`` ...). ``names(rover)``
        lists the instances of a named type; ``apply(rover, name, faults)`` gives the model
        every fault in effect on one instance, after each injection or clearing."""
        self._declare()
        self._appliers[component] = apply

        def on_fault(s: Sample) -> None:
            fk = parse_fault_key(s.parts[1:])
            if names is not None and fk.name not in set(names(s.rover)):
                known = ", ".join(sorted(names(s.rover))) or "none"
                raise BadInput(f"rover {s.rover} has no {component} {fk.name!r} (known: {known})")
            if s.deleted:
                self._clear(s.rover, s.key, fk)
            else:
                self._inject(s.rover, s.key, fk, parse_params(fk, s.payload))

        # The owner answers for every key of its component, well formed or not.
        self.rt.subscribe(keys.fault_prefix("*", component), on_fault, urgent=True)

    def in_effect(self, rover: str, component: str, name: str | None) -> tuple[Fault, ...]:
        """The injected faults in effect on one component (``load``, ``nav_camera``), in the
        order they were first injected: what its model is given."""
        return tuple(params for path, (_, params) in self.injected[rover].items()
                     if _target(path) == (component, name))

    def _apply(self, rover: str, fk: FaultKey) -> None:
        self._appliers[fk.component](rover, fk.name, self.in_effect(rover, fk.component, fk.name))

    def _inject(self, rover: str, key: str, fk: FaultKey, params: Fault) -> None:
        active = self.injected[rover]
        previous = active.get(fk.path)
        # Injecting again replaces the parameters; the fault has been active since the first.
        since = previous[0].since_t_s if previous else self.rt.t_s[rover]
        as_dict = msgspec.structs.asdict(params)
        # The record goes out before the effect: whoever sees the effect (a load shorted, the
        # rail it trips) finds the fault listed, and the dashboard hears of the fault first.
        active[fk.path] = (ActiveFault(key, as_dict, since, "injected"), params)
        self._publish(rover)
        with self.rt.events_after() as first:  # the injection before the alarms its effect raised
            try:
                self._apply(rover, fk)
            except BaseException:
                if previous is None:
                    del active[fk.path]
                else:
                    active[fk.path] = previous
                self._publish(rover)
                raise
            verb = "replaced" if previous else "injected"
            first.append(((rover, "warning", "fault_injected", key,
                           f"{verb} {fk.path} {json.dumps(as_dict)}", as_dict), {}))
            self._save()  # on the disk before its event answers the write (SPEC 13e)

    def _clear(self, rover: str, key: str, fk: FaultKey) -> None:
        active = self.injected[rover]
        if fk.path not in active:
            raise BadInput(f"no active fault {fk.path} to clear")
        cleared = active.pop(fk.path)
        with self.rt.events_after() as first:  # cleared, then the alarms it ends resolved
            try:
                self._apply(rover, fk)
            except BaseException:
                active[fk.path] = cleared
                raise
            self._publish(rover)
            first.append(((rover, "info", "fault_cleared", key, f"cleared {fk.path}"), {}))
            self._save()  # on the disk before its event answers the write (SPEC 13e)

    def clear_all(self, rover: str) -> None:
        """Clear every injected fault of a rover (a session reset), each journalled."""
        for path, (fault, _) in list(self.injected[rover].items()):
            self._clear(rover, fault.key, parse_fault_key(path.split("/")))

    def injected_faults(self, rover: str) -> list[ActiveFault]:
        return [f for f, _ in self.injected[rover].values()]

    def reinject(self, rover: str, fault: ActiveFault) -> None:
        """Inject a fault as it was saved (a snapshot restored), journalled like any other."""
        _, parts = keys.split(fault.key)
        fk = parse_fault_key(parts[1:])
        self._inject(rover, fault.key, fk, params_from_dict(fk, fault.params))

    def restore(self) -> None:
        """Re-apply the injected faults persisted by an earlier run of this service. A saved
        fault that is damaged (its parameters of the wrong type or out of range, the file
        unreadable) is skipped, said in a ``critical`` event, and the file moved aside; the
        intact ones are re-applied."""
        rt = self.rt
        try:
            saved = rt.store.load("faults")
        except Damaged as exc:
            for rover in sorted(self.injected):
                rt.state_damaged(rover, f"{rt.name} injected faults of {rover} damaged "
                                 f"({exc.reason}): none re-applied (inject them again); "
                                 f"{exc.where()}", params={"what": "faults", "reason": exc.reason})
            self._publish_all()
            return
        if saved is None:
            return
        bad: list[tuple[str, str, str]] = []  # (rover, path or "", reason)
        if not isinstance(saved, dict):
            bad = [(r, "", f"the file holds {type(saved).__name__}, not a mapping of rovers")
                   for r in sorted(self.injected)]
            saved = {}
        for rover, faults in saved.items():
            if rover not in self.injected:
                continue
            if not isinstance(faults, dict):
                bad.append((rover, "", f"a {type(faults).__name__} where a mapping of faults was "
                                       "expected"))
                continue
            touched: dict[tuple[str, str | None], FaultKey] = {}
            for path, raw in faults.items():
                try:
                    fault, fk, params = saved_fault(raw)
                    if fk.path != path:
                        raise ValueError(f"saved under {path} but its key is {fault.key}")
                except Exception as exc:  # anything the owner refuses: damaged, skipped
                    bad.append((rover, str(path), str(exc) or type(exc).__name__))
                    continue
                if fk.component not in self._appliers:
                    continue
                self.injected[rover][path] = (fault, params)
                touched[(fk.component, fk.name)] = fk
            for fk in touched.values():  # each component once, given all of its faults
                try:
                    self._apply(rover, fk)
                except Exception as exc:  # the model refuses them: skipped, said aloud
                    for path in [p for p in self.injected[rover]
                                 if _target(p) == (fk.component, fk.name)]:
                        del self.injected[rover][path]
                        bad.append((rover, path, str(exc) or type(exc).__name__))
                    self._apply(rover, fk)
        if bad:
            moved = rt.store.set_aside("faults")
            where = f"the file was moved to {moved.name}" if moved else "the file is left where it is"
            for rover, path, reason in bad:
                what = f"saved fault {path} of {rover}" if path else f"injected faults of {rover}"
                kept = ", ".join(sorted(self.injected[rover])) or "none"
                rt.state_damaged(rover, f"{rt.name} {what} damaged ({reason}): skipped (inject it "
                                 f"again); re-applied: {kept}; {where}",
                                 params={"what": "faults", "fault": path, "reason": reason})
            self._save()
        self._publish_all()

    # -- derived faults ----------------------------------------------------------------------

    def sync_derived(self, rover: str, component: str,
                     active: dict[str, tuple[Severity, str]]) -> None:
        """Raise and resolve derived faults on transitions. ``active`` maps a fault name to
        ``(severity, message)`` for every derived fault of ``component`` (``battery``,
        ``rail/12V``) that holds now."""
        self._declare()
        registry = self.derived[rover]
        prefix = f"{component}/"
        changed = False
        for name, (severity, message) in active.items():
            path = prefix + name
            if path not in registry:
                key = keys.derived_fault(rover, component, name)
                registry[path] = ActiveFault(key, {}, self.rt.t_s[rover], "derived", severity)
                changed = True
                self.rt.event(rover, severity, "fault_raised", key, message)
        for path in [p for p in registry if p.startswith(prefix)]:
            if path[len(prefix):] not in active:
                fault = registry.pop(path)
                changed = True
                self.rt.event(rover, "info", "fault_resolved", fault.key, f"resolved {path}")
        if changed:
            self._publish(rover)

    # -- the record --------------------------------------------------------------------------

    def active(self, rover: str) -> list[ActiveFault]:
        faults = [f for f, _ in self.injected[rover].values()] + list(self.derived[rover].values())
        return sorted(faults, key=lambda f: (f.since_t_s, f.key))

    def _save(self) -> None:
        self.rt.save_state("faults", {
            r: {p: msgspec.structs.asdict(f) for p, (f, _) in fs.items()}
            for r, fs in self.injected.items()})

    def publish(self, rover: str) -> None:
        self._publish(rover)

    def _publish(self, rover: str) -> None:
        self.rt.publish(keys.faults_active(rover, self.rt.name), self._message(rover), reliable=True)

    def _message(self, rover: str) -> ActiveFaults:
        return ActiveFaults(t_s=self.rt.t_s[rover], service=self.rt.name, faults=self.active(rover),
                            epoch=self.rt.epoch[rover], session=self.rt.session_id[rover])

    def _publish_all(self) -> None:
        for rover in sorted(self.injected):
            self._publish(rover)

    def _declare(self) -> None:
        if self._declared:
            return
        self._declared = True

        def on_query(q: zenoh.Query) -> None:
            with q:
                for rover in sorted(self.injected):
                    key = keys.faults_active(rover, self.rt.name)
                    if zenoh.KeyExpr(key).intersects(q.key_expr):
                        q.reply(key, encode(self._message(rover)),
                                encoding=zenoh.Encoding.APPLICATION_JSON)

        self.rt.queryable(keys.faults_active("*", self.rt.name), on_query)
