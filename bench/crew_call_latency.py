"""A crew call's latency: a dashboard calls /pdm/rail_5V_CH2/set_enabled, the twin answers.

The whole way of SPEC §12a, as a dashboard sees it: the call (a Zenoh query, as each flavour's
client makes it) reaches the bridge, which writes ``cmd/rail/5V_CH2`` with ``actor=crew``; the
power service switches the rail and answers with its event; the bridge hears it and answers
the call with ``success`` and the twin's words. Timed from the query sent to its reply
received, in this process, for:

- ``ros2dds``: a CDR ``SetBool`` request on ``pdm/rail_5V_CH2/set_enabled``, what
  zenoh-bridge-ros2dds sends for a (Cyclone DDS) client;
- ``rmw_zenoh``: the same on the service key with the type hash, target ``ALL_COMPLETE`` and
  rmw_zenoh's 33-byte attachment, what an rmw_zenoh client sends;
- ``json``: ``{"data": ...}`` on ``json/pdm/rail_5V_CH2/set_enabled``.

The calls alternate off and on (each one changes the rail), one at a time, the flavours in
turn; every answer must be ``success`` with the rail's new state in its words, or the run
stops. The bridge runs the shipped mapping with the json flavour on; the clock runs (10 Hz).

SPEC §12 target: a crew call answered, p99 under 20 ms on a 2-core machine.
Run: ``.venv/bin/python bench/crew_call_latency.py [N calls per flavour]``.
"""

from __future__ import annotations

import struct
import sys
import tempfile
import time
from pathlib import Path

import zenoh
from benchlib import ROOT, machine, percentiles, running_twin

from common import keys
from testbed.twin import ALL_SERVICES, json_bridge_extra, wait_for

R, RAIL = "mapp-1", "5V_CH2"
SERVICE = f"pdm/rail_{RAIL}/set_enabled"
# Published (share/std_srvs/srv/SetBool.json of ros-std-srvs): the service type's hash.
SET_BOOL_HASH = "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a"
CDR_HEADER = b"\x00\x01\x00\x00"  # little-endian plain CDR


def _request(flavour: str, on: bool, seq: int) -> tuple[str, bytes, bytes | None]:
    """(key, payload, attachment) of a SetBool call as that flavour's client sends it."""
    if flavour == "json":
        return f"json/{SERVICE}", b'{"data": true}' if on else b'{"data": false}', None
    payload = CDR_HEADER + bytes([on])
    if flavour == "ros2dds":
        return SERVICE, payload, None
    gid = bytes(range(16))
    att = struct.pack("<qqB", seq, time.time_ns(), 16) + gid
    return f"0/{SERVICE}/std_srvs::srv::dds_::SetBool_/{SET_BOOL_HASH}", payload, att


def _response(flavour: str, raw: bytes) -> tuple[bool, str]:
    """(success, message) of a SetBool response: JSON, or CDR read by hand (a bool, padding to
    4, a string's length with its NUL, its bytes)."""
    if flavour == "json":
        import json
        got = json.loads(raw)
        return got["success"], got["message"]
    body = raw[4:]
    n = int.from_bytes(body[4:8], "little")
    return body[0] != 0, body[8:8 + n - 1].decode()


def run(n: int = 200) -> dict[str, list[float]]:
    latencies: dict[str, list[float]] = {"ros2dds": [], "rmw_zenoh": [], "json": []}
    with tempfile.TemporaryDirectory(prefix="lunaris-bench-crew-") as tmp, running_twin(
            [ROOT / "config/rovers/mapp.yaml"], services=(*ALL_SERVICES, "bridge"),
            extra=json_bridge_extra(Path(tmp))) as (probe, _twin, _endpoint):
        probe.watch(keys.rail_state(R, RAIL))
        probe.wait_services(R, (*ALL_SERVICES, "bridge"))
        probe.wait_value(keys.rail_state(R, RAIL), lambda v: v["state"] == "on")
        # the bridge's queryables are declared once it has started: wait for a first answer
        wait_for(lambda: list(probe.session.get(f"json/{SERVICE}", payload=b'{"data": true}',
                                                timeout=5.0)), 20, "the bridge's services")
        on, seq = True, 0
        for _ in range(n):
            for flavour, times in latencies.items():
                on, seq = not on, seq + 1
                key, payload, att = _request(flavour, on, seq)
                target = (zenoh.QueryTarget.ALL_COMPLETE if flavour == "rmw_zenoh"
                          else zenoh.QueryTarget.BEST_MATCHING)
                t0 = time.perf_counter()
                replies = list(probe.session.get(key, payload=payload, attachment=att,
                                                 target=target, timeout=5.0))
                dt = time.perf_counter() - t0
                ok = replies[0].ok if len(replies) == 1 else None
                if ok is None:
                    raise SystemExit(f"{flavour}: no answer to call {seq}: {replies!r}")
                success, message = _response(flavour, ok.payload.to_bytes())
                want = "on" if on else "off"
                if not success or f"the rail is now {want}" not in message:
                    raise SystemExit(f"{flavour}: call {seq} answered {success} {message!r}")
                times.append(dt * 1e3)
    return latencies


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(f"crew call -> the twin's answer, /{SERVICE} on {R}, {n} calls per flavour ({machine()})")
    every: list[float] = []
    for flavour, times in run(n).items():
        every += times
        print(f"  {flavour:<10} {percentiles(times)}")
    print(f"  {'all':<10} {percentiles(every)}")


if __name__ == "__main__":
    main()
