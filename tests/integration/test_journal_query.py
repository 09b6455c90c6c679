"""The journal query's integers are bounded and refused in words (issue 32).

Found: ``get lunaris/<rover>/faults/journal?last=<5,000 digits>`` raised an internal error
in the faults service (a ``critical`` event; Python refuses to turn more than 4,300 digits
into an int) and answered ``[]``. Now ``last`` is a whole number from 0 to ``LAST_MAX``,
and anything else is an error reply that says so; nothing is raised.
"""

from __future__ import annotations

import pytest

from common import keys
from services.faults.service import LAST_MAX
from tests.harness import Probe

R = "mapp-1"
TWIN = ("clock", "faults")


def ask(p: Probe, parameters: str) -> tuple[list, list[str]]:
    """The journal's answers to ``?<parameters>``: (the lists, the error replies' words)."""
    ok, errors = [], []
    for reply in p.session.get(f"{keys.faults_journal(R)}?{parameters}", timeout=10):
        if reply.ok is not None:
            ok.append(reply.ok.payload.to_string())
        else:
            errors.append(reply.err.payload.to_string())
    return ok, errors


@pytest.fixture
def twin(twin_factory, probe_solo, mapp_file):
    probe_solo.watch(keys.under(R, "event/**"))
    twin_factory([mapp_file], services=TWIN)
    probe_solo.wait_services(R, TWIN)
    probe_solo.wait_event(R, lambda e: e["kind"] == "session" and e["source"] == "faults")
    return probe_solo


@pytest.mark.parametrize("last", ["9" * 5000, str(LAST_MAX + 1), "99999999999", "-1", "٣", "2.5"])
def test_a_last_out_of_bounds_is_refused_in_words(twin, last):
    ok, errors = ask(twin, f"last={last}")
    assert ok == [] and len(errors) == 1
    assert errors[0].startswith("last=") and f"give a whole number of events, 0 to {LAST_MAX:,}" in errors[0]
    assert len(errors[0]) < 200  # the 5,000 digits are not said back
    ok, errors = ask(twin, "last=1")  # and the service answers on, without an internal error
    assert errors == [] and len(ok) == 1
    assert not [e for e in twin.events(R) if e["kind"] == "internal_error"]
