"""The crew's accepted commands folded in the journal beyond a rate (issue 32), without
processes: a dashboard's thousand calls a second, the instructor's commands never folded."""

from __future__ import annotations

import msgspec

from common.messages import Event
from services.faults.journal import Journal
from services.faults.model import CREW_BURST


def command(seq: int, actor: str = "crew", rail: str = "5V_CH2") -> Event:
    return Event(t_s=seq / 1000, severity="info", source="power", kind="command",
                 key=f"lunaris/r/cmd/rail/{rail}", message=f"rail {rail}: on=true; the rail is now on",
                 params={"on": True, "reset": False, "state": "on"}, source_id="p", seq=seq,
                 actor=actor, session="20260101-000000")


def test_a_thousand_crew_commands_in_a_second_are_one_summary_beyond_the_burst():
    j = Journal(rover="r")
    written = [w for seq in range(1, 1001) for w in j.record(command(seq), seq / 1000)]
    assert len(written) == CREW_BURST  # the rest held for the summary
    summary = j.tick(2.0)
    assert len(summary) == 1
    s = summary[0]
    assert s.kind == "command" and s.actor == "crew" and s.params is not None
    assert s.params["summarised"] == 1000 - CREW_BURST
    assert s.params["keys"] == {"lunaris/r/cmd/rail/5V_CH2": 1000 - CREW_BURST}
    assert s.params["state"] == "on" and s.params["seq"] == {"p": [CREW_BURST + 1, 1000]}
    assert s.message.startswith(f"{1000 - CREW_BURST} more crew commands summarised")
    assert j.summarised == 1000 - CREW_BURST and j.ledger.known("p", 1000)
    # read back, the summary counts them again
    again = Journal(rover="r")
    for line in j.lines():
        again._write([msgspec.json.decode(line, type=Event)], 3.0)
    assert again.summarised == 1000 - CREW_BURST


def test_the_instructors_commands_are_never_folded():
    j = Journal(rover="r")
    written = [w for seq in range(1, 201) for w in j.record(command(seq, "instructor"), 0.0)]
    assert len(written) == 200 and j.tick(5.0) == []
