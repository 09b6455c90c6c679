"""A scenario says what it waits for (the player's words, offline), and how it starts."""

from __future__ import annotations

import pytest

from common.scenario import ScenarioError, describe_start, parse_scenario
from common.scenario_player import Player

TEXT = """\
scenario: {name: w}
rover: mapp-1
start: {snapshot: before-storm}
duration_s: 100
steps:
  - {name: dust, at_s: 10, inject: {component: solar/left, kind: dust, value: 0.3}}
  - {name: low, after_s: 0, when: battery.soc < 0.5, timeout_s: 30, note: low}
  - {name: sun, after_s: 0, sun_angle: {from: 60, to: 80, over_s: 20}}
"""


def test_the_player_says_what_it_waits_for_until_the_end():
    sc = parse_scenario(TEXT)
    assert describe_start(sc.start) == "from the snapshot 'before-storm'"
    player = Player(sc)
    soc = {"soc": 0.9}
    def look(parts):
        return soc if parts == ("battery", "state") else None
    player.tick(0.0, look)
    assert player.waiting(look) == "waiting for step 1 'dust': its time, in 10 s"
    player.tick(12.0, look)
    assert player.waiting(look).startswith("waiting for step 2 'low': battery.soc < 0.5 (now battery.soc")
    assert player.waiting(look).endswith("for 30 s more")
    soc["soc"] = 0.4
    player.tick(13.0, look)
    player.tick(14.0, look)
    assert player.waiting(look) == "step 3 'sun' ramping, 19 s to go"
    player.tick(40.0, look)
    assert player.waiting(look) == ("every step has played; the scenario ends at its duration of 100 s, "
                                    "in 60 s")
    player.tick(100.0, look)
    assert player.waiting(look) == "ended: duration of 100 s reached"


def test_a_start_that_cannot_be():
    with pytest.raises(ScenarioError, match="start"):
        parse_scenario(TEXT.replace("{snapshot: before-storm}", "{snapshot: 'two words'}"))
    assert describe_start(None) == "from the twin as it is"
    assert describe_start("reset").startswith("from a reset")
