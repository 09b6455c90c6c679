"""The router's roles (SPEC §9), exercised on deploy/zenohd.json5 itself, over TLS.

Every "not received" check has a positive control: after the denied operations an allowed
one goes the same way, and the test waits for the allowed one before it asserts that the
denied ones never arrived. A round trip of the denied client to the router (a query) sits
in between, so the router has dealt with the denied message before the allowed one is
even sent.

Allowed writes go through declared publishers, as the services and the console send:
Zenoh's client sends a declared publisher's samples only once the router told it of a
matching subscriber, so a rule that hides a subscriber from the writer shows here (a plain
``put`` is always sent and would hide it). Forged writes are plain puts: the worst case.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import zenoh
import zenoh.ext as zext

from common import keys
from lunaris.deploy import IDENTITIES, SERVICES, render_router_config, router_config
from lunaris.deploy_dashboard import FLEET_FILES, fleet_names
from services.bridge import DEFAULT_MAPPING, load_mapping, open_keyexpr
from tests.deploy.conftest import (
    DEPLOY,
    REPO,
    Collector,
    Router,
    running_router,
    service_env,
    stop_process,
    wait_for,
)

ROVER = "mapp-1"
INSTRUCTOR_KEYS = [keys.fault(ROVER, "battery", "heating"), keys.cmd_rail(ROVER, "12V"),
                   keys.input_sun_angle(ROVER), keys.clock_control(ROVER),
                   keys.control_reset(ROVER), keys.control_session(ROVER), keys.control_mark(ROVER),
                   keys.faults_armed_of(ROVER, "battery", "heating")]
# One key of every family a service publishes, and its owner.
OWNED = [(f.pattern(ROVER).replace("*", "x"), f.owner) for f in keys.FAMILIES
         if f.direction == "out" and f.owner != "*"]
OWNED += [(keys.faults_active(ROVER, s), s) for s in ("battery", "loads")]


def _barrier(session: zenoh.Session) -> None:
    """Return once the router has handled everything ``session`` sent before."""
    list(session.liveliness().get(keys.service(ROVER, "*"), timeout=5.0))


def _received(collector: Collector) -> list[tuple[str, bytes]]:
    return [(str(s.kind), s.payload.to_bytes()) for s in collector.items]


def _wait_subscribed(publisher: zenoh.Publisher, what: str) -> None:
    wait_for(lambda: publisher.matching_status.matching, what)


def test_the_committed_router_configuration_is_generated_from_the_code() -> None:
    assert (DEPLOY / "zenohd.json5").read_text() == render_router_config(load_mapping(DEFAULT_MAPPING))


# -- writing ---------------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("intruder", ["observer", "dashboard", "debrief", "lunaris-battery"])
def test_only_an_instructor_writes_faults_commands_inputs_time_and_sessions(
        router: Router, intruder: str) -> None:
    service = router.open("lunaris-faults")
    denied = router.open(intruder)
    got = Collector()
    for key in INSTRUCTOR_KEYS:
        service.declare_subscriber(key, got)
    for writer in ("instructor", "console"):
        allowed = router.open(writer)
        pubs = [allowed.declare_publisher(k) for k in INSTRUCTOR_KEYS]
        for pub in pubs:
            _wait_subscribed(pub, f"the {writer}'s publisher to see the service's subscriber")
        for key in INSTRUCTOR_KEYS:
            denied.put(key, b"intruder")
            denied.delete(key)
        _barrier(denied)
        for pub in pubs:
            pub.put(writer.encode())
        wait_for(lambda w=writer: [p for _, p in _received(got)].count(w.encode()) == len(INSTRUCTOR_KEYS),
                 f"the {writer}'s puts")
    assert b"intruder" not in [p for _, p in _received(got)]
    assert not [k for k, _ in _received(got) if k == "SampleKind.DELETE"]


@pytest.mark.timeout(60)
def test_the_faults_service_fires_an_armed_fault_as_an_injection_and_lists_them(router: Router) -> None:
    """An armed fault fired is the faults service's put on fault/... (SPEC 13b); its list of
    armed faults is its own to answer."""
    battery, faults = router.open("lunaris-battery"), router.open("lunaris-faults")
    got = Collector()
    battery.declare_subscriber(keys.fault_prefix(ROVER, "battery"), got)
    pub = faults.declare_publisher(keys.fault(ROVER, "battery", "heating"))
    _wait_subscribed(pub, "the faults service to see the battery's subscriber")
    router.open("lunaris-battery").put(keys.fault(ROVER, "battery", "heating"), b"forged")
    pub.put(b"40")
    wait_for(lambda: [p for _, p in _received(got)] == [b"40"], "the fired fault, and no other")
    listing = faults.declare_queryable(keys.faults_armed(ROVER), lambda q: q.reply(q.key_expr, b"[]"))
    forged = battery.declare_queryable(keys.faults_armed(ROVER), lambda q: q.reply(q.key_expr, b"[9]"))
    answers = [r.ok.payload.to_bytes() for r in router.open("instructor").get(
        keys.faults_armed(ROVER), consolidation=zenoh.ConsolidationMode.NONE, timeout=3.0)
        if r.ok is not None]
    assert answers == [b"[]"]
    del listing, forged


@pytest.mark.timeout(90)
def test_no_identity_forges_another_services_telemetry_tokens_or_answers(router: Router) -> None:
    """Every identity puts on every service's keys, announces every service and answers its
    queries; only the owner's get through."""
    reader = router.open("debrief")
    got = Collector()
    reader.declare_subscriber(keys.under(ROVER), got)
    sessions = {who: router.open(who) for who in IDENTITIES}
    tokens, queryables = [], []
    for who, session in sessions.items():
        for key, owner in OWNED:
            if who != f"lunaris-{owner}":
                session.put(key, f"forged by {who}")
        for service in SERVICES:
            if who != f"lunaris-{service}":
                tokens.append(session.liveliness().declare_token(keys.service(ROVER, service)))
                queryables.append(session.declare_queryable(
                    keys.snapshots_of(ROVER, service),
                    lambda q, who=who: q.reply(q.key_expr, json.dumps(f"forged by {who}"))))
        _barrier(session)
    owners = [sessions[f"lunaris-{owner}"].declare_publisher(key) for key, owner in OWNED]
    for pub, (_key, owner) in zip(owners, OWNED, strict=True):
        _wait_subscribed(pub, f"{owner} to see the reader's subscriber on lunaris/{ROVER}/**")
        pub.put(f"from {owner}")
    wait_for(lambda: len(_received(got)) >= len(OWNED), "every owner's sample")
    assert sorted(p.decode() for _, p in _received(got)) == sorted(f"from {o}" for _, o in OWNED)
    tokens_seen = [str(r.ok.key_expr) for r in reader.liveliness().get(
        keys.service(ROVER, "*"), timeout=5.0) if r.ok is not None]
    answers = [r.ok.payload.to_bytes() for r in reader.get(
        keys.snapshots_of(ROVER, "*"), consolidation=zenoh.ConsolidationMode.NONE, timeout=3.0)
        if r.ok is not None]
    assert tokens_seen == [] and answers == [], (tokens_seen, answers)
    owner = sessions["lunaris-battery"]
    token = owner.liveliness().declare_token(keys.service(ROVER, "battery"))
    wait_for(lambda: [str(r.ok.key_expr) for r in reader.liveliness().get(
        keys.service(ROVER, "*"), timeout=5.0) if r.ok is not None] == [keys.service(ROVER, "battery")],
        "the battery's own token")
    del token, tokens, queryables


def test_a_service_claims_its_rovers_and_no_other_identity_can(router: Router) -> None:
    """A starting service declares claim and owner tokens below its own ``service/<name>``
    (``Runtime.claim``: two clocks started at once must see each other's claim); only that
    service's identity may, or a forged claim could keep the real clock from starting."""
    reader = router.open("debrief")
    clock = router.open("lunaris-clock")
    forger = router.open("lunaris-battery")
    seen = lambda: sorted(str(r.ok.key_expr) for r in reader.liveliness().get(  # noqa: E731
        keys.service_claims(ROVER, "clock"), timeout=5.0) if r.ok is not None)
    forged = forger.liveliness().declare_token(keys.service_claim(ROVER, "clock", "f0rged"))
    claim = clock.liveliness().declare_token(keys.service_claim(ROVER, "clock", "c10ck"))
    owner = clock.liveliness().declare_token(keys.service_owner(ROVER, "clock", "c10ck"))
    wait_for(lambda: seen() == [keys.service_claim(ROVER, "clock", "c10ck"),
                                keys.service_owner(ROVER, "clock", "c10ck")],
             lambda: f"the clock's own claim and ownership, and no other (seen {seen()})")
    del forged, claim, owner


@pytest.mark.timeout(60)
def test_the_dashboard_sends_its_inbound_topic_and_nothing_else(router: Router) -> None:
    bridge = router.open("lunaris-bridge")
    dashboard = router.open("dashboard")
    inbound = Collector()
    # The deployment's fleet has two rovers: each dashboard topic carries the rover's
    # namespace (ros2dds) or ROS 2 domain (rmw_zenoh), the plain name on the dashboard's side.
    # A bridge serving both hears a topic of both on one key expression (its ros2dds one
    # here); a bridge serving one, on that rover's key (its rmw_zenoh one here).
    bridge.declare_subscriber(open_keyexpr(["mapp_1/curr_to_receiving_radio_m",
                                            "ltv_1/curr_to_receiving_radio_m"]), inbound)
    bridge.declare_subscriber("json/**", inbound)
    bridge.declare_subscriber("1/curr_to_receiving_radio_m/std_msgs::msg::dds_::Float64MultiArray_/*",
                              inbound)
    bridge.declare_subscriber(keys.under(ROVER), inbound)
    pub = dashboard.declare_publisher("mapp_1/curr_to_receiving_radio_m")
    _wait_subscribed(pub, "the dashboard's publisher to see the bridge's subscriber")
    # the json flavour is off: its inbound key is no topic of the dashboard's, nor is a key
    # outside the rovers' namespaces and domains, nor an rmw_zenoh key of another type
    for key in (keys.input_sun_angle(ROVER), keys.fault(ROVER, "battery", "heating"),
                "json/battery_state", "json/curr_to_receiving_radio_m",
                "json/mapp_1/curr_to_receiving_radio_m", "crew/curr_to_receiving_radio_m",
                "7/curr_to_receiving_radio_m/std_msgs::msg::dds_::Float64MultiArray_/h",
                "0/curr_to_receiving_radio_m/std_msgs::msg::dds_::String_/h"):
        dashboard.put(key, b"dashboard-forged")
    _barrier(dashboard)
    pub.put(b"dashboard")
    dashboard.put("1/curr_to_receiving_radio_m/std_msgs::msg::dds_::Float64MultiArray_/RIHS01_x",
                  b"rmw_zenoh")
    wait_for(lambda: len(_received(inbound)) >= 2, "the dashboard's rover positions")
    assert sorted(_received(inbound)) == [("SampleKind.PUT", b"dashboard"),
                                          ("SampleKind.PUT", b"rmw_zenoh")]


@pytest.mark.timeout(60)
def test_the_bridge_stops_the_rover_for_the_crew_and_cannot_drive_it(router: Router) -> None:
    """The crew's stop is a delete of the traverse, its rail controls puts: the bridge may make
    those, not a put of a traverse (an adversary with its credentials drove the LTV 187 m)."""
    drive, power = router.open("lunaris-drive"), router.open("lunaris-power")
    bridge, instructor = router.open("lunaris-bridge"), router.open("instructor")
    traverse, rail = Collector(), Collector()
    drive.declare_subscriber(keys.under(ROVER, "input/drive/traverse"), traverse)
    power.declare_subscriber(keys.cmd_rail(ROVER, "5V_CH2"), rail)
    _barrier(drive)
    _barrier(power)  # their subscriptions are the router's before anything is sent
    route = b'{"waypoints": [{"x_m": 200, "y_m": 50, "z_m": 0}], "speed_m_per_s": 0.5}'
    bridge.put(keys.under(ROVER, "input/drive/traverse"), route)
    bridge.delete(keys.under(ROVER, "input/drive/traverse"))
    bridge.put(keys.cmd_rail(ROVER, "5V_CH2"), b'{"on": false}')
    _barrier(bridge)
    instructor.put(keys.under(ROVER, "input/drive/traverse"), b"instructor")  # heard after the rest
    wait_for(lambda: len(_received(traverse)) >= 2 and _received(rail), "the writes let through")
    assert _received(traverse) == [("SampleKind.DELETE", b""), ("SampleKind.PUT", b"instructor")]
    assert _received(rail) == [("SampleKind.PUT", b'{"on": false}')]


def test_a_connection_that_never_signs_in_is_closed_soon() -> None:
    """A hundred TLS connections that never gave a password held every new session back 12 s
    (Zenoh's 100 pending, 10 s each): the router closes one within 3 s and lets 1,000 wait."""
    transport = router_config(load_mapping(DEFAULT_MAPPING), fleet_names(list(FLEET_FILES)))["transport"]
    assert transport["unicast"] == {"accept_timeout": 3000, "accept_pending": 1000}


# -- reading ---------------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("reader", ["observer", "instructor", "debrief", "console"])
def test_readers_receive_telemetry_live_and_as_late_joiners(router: Router, reader: str) -> None:
    key = keys.battery_state(ROVER)
    service = router.open("lunaris-battery")
    viewer = router.open(reader)
    pub = zext.declare_advanced_publisher(
        service, key, encoding=zenoh.Encoding.APPLICATION_JSON,
        cache=zext.CacheConfig(max_samples=1), publisher_detection=True)
    pub.put(json.dumps({"t_s": 1.0}))
    got = Collector()
    zext.declare_advanced_subscriber(
        viewer, key, got, history=zext.HistoryConfig(detect_late_publishers=True))
    # Joined after the sample was published: it comes from the publisher's cache,
    # through the advanced publisher's "@adv" queryable and liveliness token.
    wait_for(lambda: json.dumps({"t_s": 1.0}).encode() in [p for _, p in _received(got)],
             "the cached sample (late joiner)")
    probe = service.declare_publisher(key)
    _wait_subscribed(probe, "the service to see the reader's subscriber")
    pub.put(json.dumps({"t_s": 2.0}))
    wait_for(lambda: json.dumps({"t_s": 2.0}).encode() in [p for _, p in _received(got)],
             "the live sample")


@pytest.mark.timeout(60)
def test_the_crew_reads_effects_not_the_instructors_faults(router: Router) -> None:
    """The observer (the crew's identity) and the dashboard never see a fault put, the events
    that name it, the faults in effect or the journal; the debrief identity does, by choice."""
    instructor = router.open("instructor")
    battery = router.open("lunaris-battery")
    faults = router.open("lunaris-faults")
    seen = {who: Collector() for who in ("observer", "dashboard", "debrief")}
    readers = {who: router.open(who) for who in seen}
    for who, session in readers.items():  # the widest each may ask for
        session.declare_subscriber("**" if who == "dashboard" else keys.under(ROVER), seen[who])
    faults.declare_queryable(keys.faults(ROVER), lambda q: q.reply(q.key_expr, b"[]"))
    for session in readers.values():
        _barrier(session)
    writes = [(instructor, keys.fault(ROVER, "battery", "heating"), b"40"),
              (faults, keys.event(ROVER), b'{"kind": "fault_injected"}'),
              (battery, keys.faults_active(ROVER, "battery"), b'{"faults": []}'),
              (battery, keys.battery_state(ROVER), b'{"temperature_c": 30}')]  # the effect
    pubs = [session.declare_publisher(key) for session, key, _ in writes]
    for pub, (_, key, payload) in zip(pubs, writes, strict=True):
        _wait_subscribed(pub, f"the writer of {key} to see the debrief's subscriber")
        pub.put(payload)
    wait_for(lambda: len(seen["debrief"].items) >= 4, "the debrief identity's samples")
    wait_for(lambda: seen["observer"].items, "the observer's telemetry")
    assert [str(s.key_expr) for s in seen["observer"].items] == [keys.battery_state(ROVER)]
    assert seen["dashboard"].items == []
    asked = {who: [r.ok for r in s.get(keys.faults(ROVER), timeout=2.0) if r.ok is not None]
             for who, s in readers.items()}
    assert asked["observer"] == [] and asked["dashboard"] == [] and len(asked["debrief"]) == 1


@pytest.mark.timeout(90)
def test_a_scenarios_progress_is_the_instructors_and_hidden_from_the_crew(router: Router) -> None:
    """The scenario runner of the instructor's tools and of the console publishes
    ``scenario/progress`` with an advanced publisher; whoever reads the instructor's keys
    (debrief, the services) has it live and as a late joiner, from the publisher's cache; the
    crew (observer, dashboard) neither receives it nor gets it by asking: it tells what the
    drill does next; no one else may publish it."""
    key = keys.under(ROVER, "scenario/progress")
    battery, bridge = router.open("lunaris-battery"), router.open("lunaris-bridge")
    crew = {"observer": router.open("observer"), "dashboard": router.open("dashboard")}
    crew_got = {who: Collector() for who in crew}
    zext.declare_advanced_subscriber(crew["observer"], keys.under(ROVER), crew_got["observer"],
                                     history=zext.HistoryConfig(detect_late_publishers=True))
    crew["dashboard"].declare_subscriber("**", crew_got["dashboard"])
    for writer in ("instructor", "console"):
        session = router.open(writer)
        pub = zext.declare_advanced_publisher(session, key, cache=zext.CacheConfig(max_samples=1),
                                              publisher_detection=True)
        pub.put(f"{writer}: step 1".encode())
        # joined after the put: the sample comes from the writer's cache
        late = {who: Collector() for who in ("debrief", "lunaris-faults")}
        for who, got in late.items():
            zext.declare_advanced_subscriber(router.open(who), key, got,
                                             history=zext.HistoryConfig(detect_late_publishers=True))
        for who, got in late.items():
            wait_for(lambda g=got, w=writer: f"{w}: step 1".encode() in [p for _, p in _received(g)],
                     f"{who}, a late joiner, to have the {writer}'s progress")
        for intruder in ("observer", "dashboard", "debrief", "lunaris-battery"):
            forger = router.open(intruder)
            forger.put(key, b"forged")
            _barrier(forger)
        pub.put(f"{writer}: step 2".encode())
        for who, got in late.items():
            wait_for(lambda g=got, w=writer: f"{w}: step 2".encode() in [p for _, p in _received(g)],
                     f"{who} to have the {writer}'s progress live")
            assert b"forged" not in [p for _, p in _received(got)]
    # positive controls: each of the crew receives what it may, sent after the progress
    telemetry = battery.declare_publisher(keys.battery_state(ROVER))
    topic = bridge.declare_publisher("mapp_1/final_comms_radio_bool")
    _wait_subscribed(telemetry, "the battery to see the observer's subscriber")
    _wait_subscribed(topic, "the bridge to see the dashboard's subscriber")
    telemetry.put(b'{"soc": 0.5}')
    topic.put(b"\x00\x01\x00\x00\x01")
    wait_for(lambda: crew_got["observer"].items and crew_got["dashboard"].items, "the crew's own samples")
    assert [str(s.key_expr) for s in crew_got["observer"].items] == [keys.battery_state(ROVER)]
    assert [str(s.key_expr) for s in crew_got["dashboard"].items] == ["mapp_1/final_comms_radio_bool"]
    for who, session in crew.items():
        asked = [r.ok for sel in (key, f"{key}/@adv/**")
                 for r in session.get(sel, timeout=2.0) if r.ok is not None]
        assert asked == [], f"the {who} got the progress by asking"


@pytest.mark.timeout(60)
def test_the_dashboard_reads_the_bridges_topics(router: Router) -> None:
    bridge = router.open("lunaris-bridge")
    dashboard = router.open("dashboard")
    got = Collector()
    dashboard.declare_subscriber("ltv_1/final_comms_radio_bool", got)
    pub = bridge.declare_publisher("ltv_1/final_comms_radio_bool")
    wait_for(lambda: pub.matching_status.matching, "the bridge to see the dashboard")
    pub.put(b"\x00\x01\x00\x00\x01")
    wait_for(lambda: _received(got), "the dashboard's sample")


# -- authentication and TLS ------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", ["no-credentials", "wrong-password", "another-users-password",
                                  "unknown-user"])
def test_a_client_without_valid_credentials_cannot_open_a_session(router: Router, case: str) -> None:
    user, password = {"no-credentials": (None, None),
                      "wrong-password": ("observer", "not-the-password"),
                      "another-users-password": ("instructor", router.credentials["observer"]),
                      "unknown-user": ("intruder", "whatever")}[case]
    with pytest.raises(zenoh.ZError):
        zenoh.open(router.client_config(user, password, fail_fast=True)).close()


@pytest.mark.timeout(60)
def test_every_generated_client_configuration_opens_a_session_over_tls(router: Router) -> None:
    for user in IDENTITIES:
        conf = router.client_config(base=router.secrets / f"client-{user}.json5", fail_fast=True)
        zenoh.open(conf).close()


@pytest.mark.timeout(60)
def test_a_client_that_does_not_trust_the_deployments_ca_is_refused(router: Router, tmp_path) -> None:
    conf = json.loads((router.secrets / "client-instructor.json5").read_text())
    del conf["transport"]["link"]
    path = tmp_path / "no-ca.json5"
    path.write_text(json.dumps(conf))
    with pytest.raises(zenoh.ZError):
        zenoh.open(router.client_config(base=path, fail_fast=True)).close()


def test_the_router_configuration_denies_by_default_and_knows_every_identity() -> None:
    conf = zenoh.Config.from_file(str(DEPLOY / "zenohd.json5"))

    def get(path: str):
        return json.loads(conf.get_json(path))
    assert get("mode") == "router"
    assert get("listen/endpoints") == ["tls/0.0.0.0:7447"]
    assert get("scouting/multicast/enabled") is False
    acl = get("access_control")
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    users = {u for subject in acl["subjects"] for u in subject["usernames"]}
    assert users == set(IDENTITIES)


# -- the real services behind the router -----------------------------------------------------


@pytest.mark.timeout(90)
def test_services_run_with_their_own_identities(secrets) -> None:
    """clock, battery and faults as containers run them, each with its own client
    configuration; an instructor's fault reaches the battery, and the debrief sees it."""
    with running_router(secrets) as router:
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "lunaris.cli", "run", name,
                 "--rover", str(REPO / "config/rovers/mapp.yaml"), "--connect", router.endpoint],
                env=service_env(secrets, name), cwd=REPO,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for name in ("clock", "battery", "faults")
        ]
        try:
            debrief = router.open("debrief")
            observer = router.open("observer")
            instructor = router.open("instructor")
            state, active = Collector(), Collector()
            zext.declare_advanced_subscriber(
                observer, keys.battery_state(ROVER), state,
                history=zext.HistoryConfig(detect_late_publishers=True))
            zext.declare_advanced_subscriber(
                debrief, keys.faults_active(ROVER, "*"), active,
                history=zext.HistoryConfig(detect_late_publishers=True))

            def running() -> list[str]:
                replies = debrief.liveliness().get(keys.service(ROVER, "*"), timeout=5.0)
                return sorted(str(r.ok.key_expr).rsplit("/", 1)[1] for r in replies if r.ok is not None)

            wait_for(lambda: running() == ["battery", "clock", "faults"], "the services' tokens", 30)
            wait_for(lambda: len(state.items) >= 2, "battery telemetry on the clock", 30)
            fault = instructor.declare_publisher(keys.fault(ROVER, "battery", "heating"))
            _wait_subscribed(fault, "the battery service's fault subscriber")
            fault.put(b"40")

            def in_effect() -> list[str]:
                return [f["key"] for s in active.items
                        for f in json.loads(s.payload.to_bytes())["faults"]]

            wait_for(lambda: keys.fault(ROVER, "battery", "heating") in in_effect(),
                     "the battery service's faults in effect to list the instructor's fault")
            (listed,) = [json.loads(r.ok.payload.to_bytes())
                         for r in debrief.get(keys.faults(ROVER), timeout=5.0) if r.ok is not None]
            assert [f["key"] for f in listed] == [keys.fault(ROVER, "battery", "heating")]
        finally:
            router.close_sessions()
            for proc in procs:
                stop_process(proc)


# -- events are authenticated by their key (DECISIONS D1) -----------------------------------


@pytest.mark.timeout(60)
def test_a_service_publishes_events_only_on_its_own_key_and_the_journal_relays_them(
        router: Router) -> None:
    """``lunaris-<service>`` puts its events on ``event/<service>`` only; only
    ``lunaris-faults`` puts on the rover's ``event``. A forged event (the bridge's identity
    claiming to be the battery, or writing the journal's stream) is refused by the router;
    the crew's identities read neither stream."""
    own, journal = f"{keys.event(ROVER)}/battery", keys.event(ROVER)
    debrief = router.open("debrief")
    got = Collector()
    debrief.declare_subscriber(f"{journal}/**", got)  # `event` and every `event/<service>`
    crew = {who: Collector() for who in ("observer", "dashboard")}
    for who, seen in crew.items():
        router.open(who).declare_subscriber("lunaris/**" if who == "observer" else "**", seen)
    forgers = {who: router.open(who) for who in ("lunaris-bridge", "lunaris-battery", "instructor",
                                                  "dashboard")}
    for who, session in forgers.items():
        if who != "lunaris-battery":
            session.put(own, f"forged by {who}")
        session.put(journal, f"forged by {who}")
        session.put(f"{journal}/faults", f"forged by {who}")
        _barrier(session)
    battery = router.open("lunaris-battery").declare_publisher(own)
    faults = router.open("lunaris-faults")
    relay = faults.declare_publisher(journal)
    faults_own = faults.declare_publisher(f"{journal}/faults")
    for pub, payload in ((battery, b"battery's own"), (relay, b"relayed by the journal"),
                         (faults_own, b"the journal's own")):
        _wait_subscribed(pub, "the event's publisher to see the debrief's subscriber")
        pub.put(payload)
    wait_for(lambda: len(got.items) >= 3, "the three genuine events")
    assert sorted((str(s.key_expr), s.payload.to_bytes()) for s in got.items) == sorted([
        (own, b"battery's own"), (journal, b"relayed by the journal"),
        (f"{journal}/faults", b"the journal's own")])
    _barrier(debrief)
    assert [str(s.key_expr) for c in crew.values() for s in c.items] == []
