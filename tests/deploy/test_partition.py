"""A write that cannot reach its owner is never applied late, and the writer is told
(DECISIONS D3, SPEC §12f): the rover's cable cut for 5 s and for 15 s, the same outcome both
times.

The shipped site on three machines (tests/deploy/machines.py). Before the cuts a fault is in
effect on the rover (battery heating). During each cut an instructor on the ground runs
``lunaris fault inject mapp-1 battery capacity_loss 0.3`` and ``lunaris fault list mapp-1``,
and a debrief ``lunaris watch --once --rover mapp-1`` 3 s into the cut. The documented outcome:

- the writer is told: ``fault inject`` says "not applied" and exits 2;
- the write is not applied after the link returns (the owner refuses a write stamped more
  than 2 s before it arrives: at most a ``rejected`` "arrived late" event in the journal);
  the rover's faults in effect never list it;
- ``fault list`` exits 2 naming the owners that did not answer (the battery's), and never
  says "no active faults" while the heating is in effect behind the cut;
- ``watch --once`` shows the rover's link lost 3 s into the cut, and not once it is back.

A 5 s cut is shorter than Zenoh's lease (10 s): the routers keep their link and deliver the
queued write when the cable is back, 5 s late. A 15 s cut outlasts it: the link closes and
opens again. Both must end the same way.

This needs the harden-input branch (owners refuse late writes, ``get faults`` names missing
owners) and the clients branch (the CLI's "not applied", exit 2): it fails on the deploy
branch alone, which only brings the machines, the routers and this contract.
"""

from __future__ import annotations

import json
import re
import subprocess
import time
from collections.abc import Iterator

import pytest

from common import keys
from tests import netns
from tests.deploy.deployment import Remote, wait_until
from tests.deploy.machines import SiteOnMachines

pytestmark = [pytest.mark.timeout(600),
              pytest.mark.skipif(netns.unavailable() is not None, reason=str(netns.unavailable()))]

ROVER = "mapp-1"
HEATING = keys.fault(ROVER, "battery", "heating")
LATE = keys.fault(ROVER, "battery", "capacity_loss")
SERVICES = ("clock", "battery", "loads", "power", "solar", "radio", "drive", "faults", "bridge")
LOST = re.compile(r"\blost\b", re.IGNORECASE)


class Partition:
    def __init__(self, machines: SiteOnMachines, debrief: Remote):
        self.m, self.debrief = machines, debrief

    def cli(self, identity: str, *args: str) -> subprocess.Popen:
        """A ``lunaris`` command on the ground, its output kept."""
        return self.m.lunaris_popen("ground", identity, *args)

    def in_effect(self) -> list[list[str]]:
        """Every ``faults/active/battery`` the debrief on the ground got: the keys in each."""
        return [[f["key"] for f in s["payload"]["faults"]]
                for s in self.debrief.samples("active", keys.faults_active(ROVER, "battery"))]


def _finish(proc: subprocess.Popen, timeout_s: float = 60.0) -> tuple[int, str]:
    out, _ = proc.communicate(timeout=timeout_s)
    return proc.returncode, out


def _listed_with_heating(partition: Partition, what: str) -> list[str]:
    """The faults ``lunaris fault list`` gives, once every owner answers (the heating in it)."""
    def listed() -> list[str] | None:
        code, out = _finish(partition.cli("instructor", "fault", "list", ROVER, "--json"))
        active = [f["key"] for f in json.loads(out)["active"]] if code == 0 else []
        return active if HEATING in active else None
    return wait_until(listed, 90, what)


@pytest.fixture(scope="module")
def partition(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Partition]:
    with SiteOnMachines(tmp_path_factory.mktemp("partition")) as m:
        try:
            debrief = m.remote("ground", "debrief")
            instructor = m.remote("ground", "instructor")
            debrief.subscribe("active", "lunaris/*/faults/active/*")
            every = {keys.service(ROVER, s) for s in SERVICES}
            wait_until(lambda: every <= set(debrief.call("alive", key=f"lunaris/{ROVER}/service/*")
                                            ["keys"]), 120, lambda: f"every service\n{m.tails()}")
            p = Partition(m, debrief)
            instructor.call("pub", key=HEATING)
            wait_until(lambda: instructor.call("matching", key=HEATING)["matching"], 30,
                       "the instructor to learn of the battery's subscriber")
            instructor.call("put", key=HEATING, payload="5")
            wait_until(lambda: [HEATING] in p.in_effect()[-1:], 30,
                       "the heating in effect on the rover (before the cuts)")
            yield p
        finally:
            print(m.tails())


@pytest.mark.parametrize("cut_s", [5.0, 15.0])
def test_a_write_during_a_cut_is_refused_said_and_never_applied_late(
        partition: Partition, cut_s: float) -> None:
    net = partition.m.net
    _listed_with_heating(partition, "linked, before the cut")  # every owner answers

    net.cut(ROVER)
    t_cut = time.monotonic()
    try:
        inject = partition.cli("instructor", "fault", "inject", ROVER, "battery", "capacity_loss", "0.3")
        listing = partition.cli("instructor", "fault", "list", ROVER)
        wait_until(lambda: time.monotonic() >= t_cut + 3.0, 10, "3 s into the cut")
        watch = partition.cli("debrief", "watch", "--once", "--rover", ROVER)
        watched = _finish(watch)[1]
        injected = _finish(inject)
        during = _finish(listing)
        wait_until(lambda: time.monotonic() >= t_cut + cut_s, cut_s + 60,
                   f"the end of the {cut_s:g} s cut")
    finally:
        net.restore(ROVER)

    # the writer was told, in words, and the status says so
    assert injected[0] == 2 and "not applied" in injected[1], injected
    # the list names what is missing, never "no active faults" with the heating behind the cut
    assert during[0] == 2, during
    assert "no active faults" not in during[1] and "battery" in during[1], during
    # the link shown lost 3 s into the cut
    assert LOST.search(watched), watched

    # back: every owner answers again, the heating is still listed, the late write is not
    active = _listed_with_heating(partition, f"the battery answering again after the {cut_s:g} s cut")
    assert LATE not in active, active
    assert all(LATE not in faults for faults in partition.in_effect()), partition.in_effect()
    assert not LOST.search(_finish(partition.cli("debrief", "watch", "--once", "--rover", ROVER))[1])
