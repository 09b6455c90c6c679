"""The faults service journals its own events (a mark, a session control, a rejection) before it
publishes them. It used to journal them as it heard them back from Zenoh, a moment after the
publication: a kill -9 in that moment lost one, with no ``journal_gap`` to show for it (its
publisher's cache died with it). Found as a failure of
tests/integration/test_trainee_sessions.py.

The real node on a real runtime, Zenoh's declarations replaced by stand-ins: each publication
records what the journal held when it was made."""

from __future__ import annotations

from collections.abc import Iterator
from unittest import mock

import msgspec
import pytest
import zenoh.ext as zext

from common import keys
from common.config import load_rover
from common.connection import make_config
from common.messages import Event, TimelineMark
from common.runtime import Runtime, Sample
from services.faults.service import FaultsNode
from testbed.twin import static_rover

R = "mapp-1"


class _Publishers:
    """Stand-ins for Zenoh's advanced publishers: what the journal held at each put."""

    def __init__(self, node: FaultsNode) -> None:
        self.node = node
        self.puts: list[tuple[str, bytes, list[bytes]]] = []

    def declare(self, _session: object, key: str, **_: object) -> mock.Mock:
        pub = mock.Mock()
        pub.put.side_effect = lambda payload, attachment=None: self.puts.append(
            (key, payload, list(self.node.rovers[R].journal.lines(None))))
        return pub


@pytest.fixture
def faults() -> Iterator[tuple[FaultsNode, Runtime, _Publishers]]:
    node = FaultsNode([load_rover(static_rover("mapp.yaml"))])
    pubs = _Publishers(node)
    with mock.patch.object(zext, "declare_advanced_subscriber"), \
            mock.patch.object(zext, "declare_advanced_publisher", side_effect=pubs.declare):
        rt = Runtime("faults", [R], make_config(connect=["tcp/127.0.0.1:9"]), None)  # never opened
        rt.session = mock.MagicMock()
        rt._zid = "f00d"
        node.attach(rt)
        rt.t_s[R], rt.session_id[R] = 12.5, "s1"
        yield node, rt, pubs


def _mark(text: str) -> Sample:
    return Sample(keys.control_mark(R), R, ["control", "mark"],
                  msgspec.json.encode(TimelineMark(text=text)), False)


def test_an_own_event_is_in_the_journal_before_it_is_published(faults) -> None:
    node, _, pubs = faults
    node.on_control(_mark("crew called the lander"))
    own = [(payload, held) for key, payload, held in pubs.puts if key == keys.event_of(R, "faults")]
    assert len(own) == 1
    payload, held = own[0]
    assert [msgspec.json.decode(line, type=Event).message for line in held] == \
        ["mark: crew called the lander"]
    assert msgspec.json.decode(payload, type=Event).seq == msgspec.json.decode(held[0], type=Event).seq


def test_an_own_event_heard_back_is_not_journalled_twice(faults) -> None:
    node, _, pubs = faults
    node.on_control(_mark("first"))
    payload = next(p for key, p, _ in pubs.puts if key == keys.event_of(R, "faults"))
    relayed = len([key for key, _, _ in pubs.puts if key == keys.event(R)])
    node.on_event(Sample(keys.event_of(R, "faults"), R, ["event", "faults"], payload, False))
    assert node.rovers[R].journal.count == 1
    assert len([key for key, _, _ in pubs.puts if key == keys.event(R)]) == relayed == 1
