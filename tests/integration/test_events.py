"""Events are authenticated by their key and say who acted (SPEC §12a; issue 23.6; D1, D4).

Each service publishes its events on ``lunaris/<rover>/event/<service>``; the faults service
journals them and relays each, unchanged, on ``lunaris/<rover>/event``. An event whose
``source`` is not the service its key names is refused and said in a ``critical`` event.
Found: any identity could publish an event for any rover with any source and kind, and the
journal took it (``lunaris-bridge`` wrote a ``fault_cleared`` claiming source ``battery``).

A write may carry the attachment ``actor=crew|instructor|scenario``; the events answering it
carry that actor (none: ``instructor``), the twin's own (derived faults) ``actor: twin``.
"""

from __future__ import annotations

import json

import pytest

from common import keys
from common.connection import write
from common.messages import Event, encode
from tests.harness import Probe, wait_for

pytestmark = pytest.mark.timeout(120)

R = "mapp-1"
TWIN = ("clock", "battery", "loads", "power", "solar", "faults")


@pytest.fixture
def twin(twin_factory, probe_solo, mapp_file):
    probe_solo.watch("lunaris/**")
    twin_factory([mapp_file], services=TWIN)
    probe_solo.wait_services(R, TWIN)
    return probe_solo


def on(p: Probe, key: str, predicate=lambda e: True) -> list[dict]:
    return [e for e in p.samples(key) if isinstance(e, dict) and predicate(e)]


def answer(p: Probe, key: str, payload: bytes | None, actor: str | None = None,
           kinds=("fault_injected", "fault_cleared", "command", "input", "rejected")) -> dict:
    """Write (with ``actor``) and return the event of the rover that answers this very write."""
    seen = len(p.events(R))
    write(p.session, key, payload, actor=actor)
    return p.wait_event(R, lambda e: e["key"] == key and e["kind"] in kinds
                        and p.events(R).index(e) >= seen)


def test_each_service_publishes_on_its_own_key_and_the_journal_relays_it_unchanged(twin):
    p = twin
    key = keys.fault(R, "battery", "heating")
    write(p.session, key, b"3")
    own = wait_for(lambda: on(p, keys.event_of(R, "battery"), lambda e: e["key"] == key), 10,
                   "the battery's event on its own key")[0]
    assert own["source"] == "battery" and own["kind"] == "fault_injected"
    relayed = wait_for(lambda: on(p, keys.event(R), lambda e: e["key"] == key), 10,
                       "the journal's relay")[0]
    assert relayed == own  # unchanged: the same source_id and seq, the same words
    (journal,) = p.get_json(keys.faults_journal(R))
    assert [e for e in journal if e["key"] == key] == [own]
    # nothing but the faults service publishes on the rover's event key, its own events
    # relayed there too (the journal's opening, once the first tick has said the session)
    wait_for(lambda: on(p, keys.event(R), lambda e: e["source"] == "faults"), 10,
             "the faults service's own event relayed")
    assert not [k for k in p.history if k.startswith(keys.event(R) + "/")
                and any(e.get("source") != k.rsplit("/", 1)[1] for e in p.samples(k))]
    write(p.session, key, None)


def test_a_forged_event_is_refused_and_said_never_journalled(twin):
    p = twin
    forged = Event(t_s=1.0, severity="info", source="battery", kind="fault_cleared",
                   key=keys.fault(R, "battery", "heating"), message="cleared battery/heating",
                   source_id="f00d", seq=1)
    p.session.put(keys.event_of(R, "bridge"), encode(forged))  # the bridge claiming the battery
    said = p.wait_event(R, lambda e: e["kind"] == "rejected" and e["severity"] == "critical")
    assert said["source"] == "faults" and said["key"] == keys.event_of(R, "bridge")
    assert "forged" in said["message"] and "'battery'" in said["message"]
    assert "$." not in said["message"]
    (journal,) = p.get_json(keys.faults_journal(R))
    assert not [e for e in journal if e.get("source_id") == "f00d"]
    assert not on(p, keys.event(R), lambda e: e.get("source_id") == "f00d")  # never relayed
    # A payload that is no event at all is bad input like any other: refused once, in words.
    p.session.put(keys.event_of(R, "battery"), b"maybe")
    bad = p.wait_event(R, lambda e: e["kind"] == "rejected" and e["key"] == keys.event_of(R, "battery"))
    assert bad["source"] == "faults"


def test_events_say_who_acted(twin):
    p = twin
    rail = keys.cmd_rail(R, "5V_CH2")
    by_crew = answer(p, rail, json.dumps({"on": False}).encode(), actor="crew")
    assert (by_crew["kind"], by_crew["actor"]) == ("command", "crew")
    by_default = answer(p, rail, json.dumps({"on": True}).encode())
    assert (by_default["kind"], by_default["actor"]) == ("command", "instructor")
    short = keys.fault(R, "load/nav_camera", "short")
    by_scenario = answer(p, short, b"", actor="scenario")
    assert (by_scenario["kind"], by_scenario["actor"]) == ("fault_injected", "scenario")
    tripped = p.wait_event(R, lambda e: e["kind"] == "fault_raised" and e["key"].endswith("5V_CH2/tripped"))
    assert tripped["actor"] == "twin"  # the twin's protection, whoever shorted the load
    reset = answer(p, rail, json.dumps({"reset": True}).encode(), actor="crew")  # held for a tick
    assert (reset["kind"], reset["actor"]) == ("command", "crew")
    bad_sun = answer(p, keys.input_sun_angle(R), b"400", actor="crew")
    assert (bad_sun["kind"], bad_sun["actor"]) == ("rejected", "crew")
    sun = answer(p, keys.input_sun_angle(R), b"40", actor="crew")
    assert (sun["kind"], sun["actor"]) == ("input", "crew")
    cleared = answer(p, short, None, actor="instructor")
    assert (cleared["kind"], cleared["actor"]) == ("fault_cleared", "instructor")


def test_a_write_naming_an_unknown_actor_is_refused(twin):
    p = twin
    key = keys.fault(R, "battery", "heating")
    seen = len(p.events(R))
    p.session.put(key, b"5", attachment=b"actor=twin")
    refused = p.wait_event(R, lambda e: e["key"] == key and p.events(R).index(e) >= seen)
    assert refused["kind"] == "rejected" and "names no actor" in refused["message"], refused
    (faults,) = p.get_json(keys.faults(R))
    assert key not in {f["key"] for f in faults}
    with pytest.raises(ValueError):
        write(p.session, key, b"5", actor="twin")


def test_events_are_seen_without_the_faults_service(twin_factory, probe_solo, mapp_file):
    """A tool that must not depend on the journal reads each service's own key."""
    p = probe_solo
    p.watch("lunaris/**")
    twin_factory([mapp_file], services=("clock", "solar"))
    p.wait_services(R, ("clock", "solar"))
    key = keys.input_sun_angle(R)
    write(p.session, key, b"33", actor="crew")
    ev = p.wait_event(R, lambda e: e["key"] == key and e["kind"] == "input")
    assert ev["source"] == "solar" and ev["actor"] == "crew"
    assert not p.samples(keys.event(R))  # nobody relays: no faults service
