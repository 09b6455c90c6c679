"""The router's roles (SPEC §9), exercised on deploy/zenohd.json5 itself.

Every "not received" check has a positive control: after the denied operation an
allowed one goes the same way, and the test waits for the allowed one before it
asserts that the denied one never arrived. A round trip of the denied client to the
router (a query) sits in between, so the router has dealt with the denied message
before the allowed one is even sent.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import zenoh
import zenoh.ext as zext

from tests.deploy.conftest import (
    DEPLOY,
    REPO,
    Collector,
    Router,
    read_credentials,
    running_router,
    service_env,
    stop_process,
    wait_for,
)

ROVER = "mapp-1"
INSTRUCTOR_KEYS = [
    f"lunaris/{ROVER}/fault/battery/heating",
    f"lunaris/{ROVER}/cmd/rail/12V",
    f"lunaris/{ROVER}/input/sun_angle",
    f"lunaris/{ROVER}/clock/control",
]


def _barrier(session: zenoh.Session) -> None:
    """Return once the router has handled everything ``session`` sent before."""
    list(session.get(f"lunaris/{ROVER}/faults", timeout=5.0))


def _received(collector: Collector) -> list[tuple[str, bytes]]:
    return [(str(s.kind), s.payload.to_bytes()) for s in collector.items]


def _get(conf: zenoh.Config, path: str):
    return json.loads(conf.get_json(path))


def _wait_subscribed(publisher: zenoh.Publisher, what: str) -> None:
    wait_for(lambda: publisher.matching_status.matching, what)


# -- writing ---------------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("intruder", ["observer", "dashboard"])
@pytest.mark.parametrize("key", INSTRUCTOR_KEYS)
def test_only_an_instructor_writes_faults_commands_inputs_and_time(
        router: Router, key: str, intruder: str) -> None:
    service = router.open("lunaris-service")
    denied = router.open(intruder)
    instructor = router.open("instructor")
    got = Collector()
    service.declare_subscriber(key, got)
    pub = instructor.declare_publisher(key)
    _wait_subscribed(pub, "the instructor's publisher to see the service's subscriber")

    denied.put(key, b"intruder")
    denied.delete(key)
    denied.declare_publisher(key).put(b"intruder-publisher")
    _barrier(denied)
    pub.put(b"instructor")
    wait_for(lambda: ("SampleKind.PUT", b"instructor") in _received(got),
             "the instructor's put")
    pub.delete()
    wait_for(lambda: any(kind == "SampleKind.DELETE" for kind, _ in _received(got)),
             "the instructor's delete")

    assert _received(got) == [("SampleKind.PUT", b"instructor"), ("SampleKind.DELETE", b"")]


@pytest.mark.timeout(60)
def test_the_dashboard_sends_the_rover_position_and_nothing_else(router: Router) -> None:
    service = router.open("lunaris-service")
    dashboard = router.open("dashboard")
    observer = router.open("observer")
    inbound = Collector()
    service.declare_subscriber("curr_to_receiving_radio_m", inbound)
    pub = dashboard.declare_publisher("curr_to_receiving_radio_m")
    _wait_subscribed(pub, "the dashboard's publisher to see the bridge's subscriber")

    observer.put("curr_to_receiving_radio_m", b"observer")
    _barrier(observer)
    pub.put(b"dashboard")
    wait_for(lambda: _received(inbound), "the dashboard's rover position")
    assert _received(inbound) == [("SampleKind.PUT", b"dashboard")]


# -- reading ---------------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize("reader", ["observer", "instructor", "dashboard"])
def test_readers_receive_telemetry_live_and_as_late_joiners(router: Router, reader: str) -> None:
    key = f"lunaris/{ROVER}/battery/state"
    service = router.open("lunaris-service")
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
def test_readers_receive_the_dashboard_topics(router: Router) -> None:
    service = router.open("lunaris-service")
    readers = {name: router.open(name) for name in ("observer", "dashboard")}
    got = {name: Collector() for name in readers}
    for name, session in readers.items():
        session.declare_subscriber("final_comms_radio_bool", got[name])
    pub = service.declare_publisher("final_comms_radio_bool")
    wait_for(lambda: pub.matching_status.matching, "the bridge to see the dashboard readers")
    # Both subscribers are known once each reader's declaration went through the router.
    for session in readers.values():
        _barrier(session)
    pub.put(b"\x00\x01\x00\x00\x01")
    for name in readers:
        wait_for(lambda name=name: _received(got[name]), f"the {name}'s dashboard sample")


@pytest.mark.timeout(60)
@pytest.mark.parametrize("impostor", ["observer", "instructor", "dashboard"])
def test_only_services_answer_queries_and_announce_themselves(
        router: Router, impostor: str) -> None:
    faults_key = f"lunaris/{ROVER}/faults"
    service = router.open("lunaris-service")
    fake = router.open(impostor)
    asker = router.open("observer" if impostor != "observer" else "instructor")

    fake.declare_queryable(faults_key, lambda q: q.reply(q.key_expr, b'["fake"]'))
    fake_token = fake.liveliness().declare_token(f"lunaris/{ROVER}/service/battery")
    _barrier(fake)
    service.declare_queryable(faults_key, lambda q: q.reply(q.key_expr, b'["real"]'))
    token = service.liveliness().declare_token(f"lunaris/{ROVER}/service/faults")

    def answers() -> list[bytes]:
        # Every reply of every queryable: the same key would otherwise be consolidated.
        replies = asker.get(faults_key, target=zenoh.QueryTarget.ALL,
                            consolidation=zenoh.ConsolidationMode.NONE, timeout=5.0)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

    def tokens() -> list[str]:
        replies = asker.liveliness().get(f"lunaris/{ROVER}/service/*", timeout=5.0)
        return [str(r.ok.key_expr) for r in replies if r.ok is not None]

    assert wait_for(answers, "the faults service's reply") == [b'["real"]']
    assert wait_for(tokens, "the faults service's token") == [f"lunaris/{ROVER}/service/faults"]
    del fake_token, token


# -- authentication --------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("user", "password"), [
    (None, None),
    ("observer", "not-the-password"),
    ("instructor", read_credentials()["observer"]),
    ("intruder", "whatever"),
], ids=["no-credentials", "wrong-password", "another-users-password", "unknown-user"])
def test_a_client_without_valid_credentials_cannot_open_a_session(
        router: Router, user: str | None, password: str | None) -> None:
    with pytest.raises(zenoh.ZError):
        zenoh.open(router.client_config(user, password, fail_fast=True)).close()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("user", sorted(read_credentials()))
def test_every_user_of_the_dictionary_opens_a_session(router: Router, user: str) -> None:
    conf = router.client_config(user, read_credentials()[user], fail_fast=True)
    zenoh.open(conf).close()  # the same fail-fast settings as the refused clients


@pytest.mark.timeout(60)
@pytest.mark.parametrize("config", [
    "client-instructor.json5", "client-observer.json5", "client-service.json5",
    "zenoh-bridge-ros2dds.json5",
])
def test_the_shipped_client_configurations_authenticate(router: Router, config: str) -> None:
    shipped = zenoh.Config.from_file(str(DEPLOY / config))
    assert _get(shipped, "mode") == "client"
    assert _get(shipped, "scouting/multicast/enabled") is False
    assert _get(shipped, "transport/auth/usrpwd/user") in read_credentials()
    zenoh.open(router.client_config(base=DEPLOY / config, fail_fast=True)).close()


def test_the_router_configuration_denies_by_default() -> None:
    conf = zenoh.Config.from_file(str(DEPLOY / "zenohd.json5"))
    assert _get(conf, "mode") == "router"
    assert _get(conf, "listen/endpoints") == ["tcp/0.0.0.0:7447"]
    assert _get(conf, "scouting/multicast/enabled") is False
    assert _get(conf, "transport/auth/usrpwd/dictionary_file") == "/etc/zenoh/credentials.txt"
    acl = _get(conf, "access_control")
    assert acl["enabled"] is True
    assert acl["default_permission"] == "deny"
    users = {u for subject in acl["subjects"] for u in subject["usernames"]}
    assert users == set(read_credentials())


# -- the real services behind the router -----------------------------------------------------


@pytest.mark.timeout(60)
def test_services_run_with_the_service_identity() -> None:
    """clock and battery as containers run them: LUNARIS_ZENOH_CONFIG=client-service.json5."""
    with running_router() as router:
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "lunaris.cli", "run", name,
                 "--rover", str(REPO / "config/rovers/mapp.yaml"),
                 "--connect", router.endpoint],
                env=service_env(), cwd=REPO,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for name in ("clock", "battery")
        ]
        try:
            observer = router.open("observer")
            instructor = router.open("instructor")
            state = Collector()
            events = Collector()
            zext.declare_advanced_subscriber(
                observer, f"lunaris/{ROVER}/battery/state", state,
                history=zext.HistoryConfig(detect_late_publishers=True))
            zext.declare_advanced_subscriber(
                observer, f"lunaris/{ROVER}/event", events,
                history=zext.HistoryConfig(detect_late_publishers=True))

            def running() -> list[str]:
                replies = observer.liveliness().get(f"lunaris/{ROVER}/service/*", timeout=5.0)
                return sorted(str(r.ok.key_expr).rsplit("/", 1)[1]
                              for r in replies if r.ok is not None)

            wait_for(lambda: running() == ["battery", "clock"], "both services' tokens", 30)
            wait_for(lambda: len(state.items) >= 2, "battery telemetry on the clock", 30)

            fault = instructor.declare_publisher(f"lunaris/{ROVER}/fault/battery/heating")
            _wait_subscribed(fault, "the battery service's fault subscriber")
            observer.put(f"lunaris/{ROVER}/fault/battery/disconnect", b"")
            _barrier(observer)
            fault.put(b"40")

            def event_keys() -> list[str]:
                return [json.loads(s.payload.to_bytes())["key"] for s in events.items]

            wait_for(lambda: f"lunaris/{ROVER}/fault/battery/heating" in event_keys(),
                     "the battery service's event for the instructor's fault")
            assert f"lunaris/{ROVER}/fault/battery/disconnect" not in event_keys()
        finally:
            router.close_sessions()
            for proc in procs:
                stop_process(proc)
