"""A tick that begins an epoch or a session is handled ahead of what waits (as a fault is), so
that a write sent once the new session was seen is never applied in the old one and undone
by its reset. Found: tests/integration/test_trainee_sessions.py saw the loads service take
a fault injected in Ben's session into Ana's (the write, urgent, overtook the tick that began
Ben's session in the loads service's queue) and clear it with her session's reset."""

from __future__ import annotations

import msgspec

from common import keys
from common.connection import make_config
from common.messages import Clock
from common.runtime import Runtime, Sample
from common.worker import Worker

R = "mapp-1"


def _tick(epoch: int, t_s: float, session: str = "s1") -> Sample:
    payload = msgspec.json.encode(Clock(t_s=t_s, dt_s=0.1, seq=round(t_s * 10), time_scale=1.0,
                                        paused=False, epoch=epoch, session=session))
    return Sample(keys.clock(R), R, ["clock"], payload, False)


def test_only_the_first_tick_of_a_new_epoch_or_session_is_urgent() -> None:
    rt = Runtime("loads", [R], make_config(connect=["tcp/127.0.0.1:9"]), None)  # never opened
    said = [rt._begins_epoch(t) for t in (
        _tick(0, 0.1), _tick(0, 0.2),   # the running epoch
        _tick(1, 0.0), _tick(1, 0.1),   # a reset: its first tick only
        _tick(2, 0.0, "s2"),            # a new trainee's session
        _tick(2, 0.1, "s2"))]
    assert said == [False, False, True, False, True, False]


def test_an_urgent_tick_goes_ahead_of_what_waits_and_a_write_after_it_follows_it() -> None:
    handled: list[str] = []
    worker = Worker(lambda fn, *args: fn(*args))
    worker.put(handled.append, "load sample of the old epoch")
    worker.put(handled.append, "tick of the new session", urgent=True)
    worker.put(handled.append, "fault written in the new session", urgent=True)
    worker.every(0.01, worker.stop)
    worker.run()
    assert handled == ["tick of the new session", "fault written in the new session",
                       "load sample of the old epoch"]
