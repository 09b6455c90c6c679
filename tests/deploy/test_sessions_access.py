"""Who may read the trainee sessions (SPEC §12c) under the deployment's access control: the
faults service alone answers ``get lunaris/<rover>/sessions`` (the trainees' names), which
instructors, the console and the debrief read and the crew's identities never do. (Who may
put ``control/session`` and ``control/mark``: test_access_control.py, with the other
instructor writes.)"""

from __future__ import annotations

import pytest

from common import keys
from tests.deploy.conftest import Router

ROVER = "mapp-1"


@pytest.mark.timeout(60)
def test_the_sessions_are_the_faults_services_to_answer_and_hidden_from_the_crew(router: Router) -> None:
    faults = router.open("lunaris-faults")
    forger = router.open("lunaris-battery")
    faults.declare_queryable(keys.sessions(ROVER), lambda q: q.reply(q.key_expr, b'[{"trainee": "Ana"}]'))
    forger.declare_queryable(keys.sessions(ROVER), lambda q: q.reply(q.key_expr, b'"forged"'))
    answers = {}
    for who in ("instructor", "console", "debrief", "observer", "dashboard"):
        session = router.open(who)
        answers[who] = [r.ok.payload.to_bytes() for r in session.get(keys.sessions(ROVER), timeout=3.0)
                        if r.ok is not None]
    for who in ("instructor", "console", "debrief"):
        assert answers[who] == [b'[{"trainee": "Ana"}]'], (who, answers[who])
    assert answers["observer"] == [] and answers["dashboard"] == [], answers
