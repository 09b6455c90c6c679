"""tests/netns.py: machines made of network namespaces, their cables, their cleanup."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests import netns

pytestmark = [pytest.mark.timeout(60),
              pytest.mark.skipif(netns.unavailable() is not None, reason=str(netns.unavailable()))]

ECHO = """
import socket, sys
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], 9000)); s.listen()
print("listening", flush=True)
while True:
    c, _ = s.accept(); c.sendall(c.recv(100)); c.close()
"""
CALL = """
import socket, sys
s = socket.create_connection((sys.argv[1], 9000), timeout=float(sys.argv[2]))
s.sendall(b"hello"); print(s.recv(100).decode())
"""


def _call(net: netns.Network, machine: str, address: str, timeout_s: float = 2.0) -> str:
    out = net.run(machine, [sys.executable, "-c", CALL, address, str(timeout_s)], timeout_s=30)
    return out.stdout.strip() if out.returncode == 0 else f"failed: {out.stderr.strip()[-200:]}"


def test_machines_talk_through_the_switch_and_a_cut_cable_stops_them() -> None:
    with netns.Network() as net:
        a, b = net.add("a"), net.add("b")
        server = net.popen("a", [sys.executable, "-c", ECHO, a.address], stdout=subprocess.PIPE)
        assert server.stdout is not None and server.stdout.readline().strip() == b"listening"
        assert _call(net, "b", a.address) == "hello"
        net.cut("a")
        assert net.is_cut("a")
        assert _call(net, "b", a.address, 1.0).startswith("failed")
        net.restore("a")
        assert not net.is_cut("a")
        assert _call(net, "b", a.address, 5.0) == "hello"
        # the addresses exist only inside the namespaces, not in the test's own
        assert a.address not in subprocess.run(["ip", "addr"], capture_output=True, text=True).stdout
        assert b.address in net.run("b", ["ip", "addr"]).stdout


def test_everything_is_deleted_even_when_the_test_fails() -> None:
    with pytest.raises(RuntimeError, match="the test failed"):
        with netns.Network() as net:
            net.add("a")
            proc = net.popen("a", ["sleep", "300"])
            names = [m.namespace for m in net.machines.values()] + [net.switch]
            raise RuntimeError("the test failed")
    assert proc.poll() is not None
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert not [n for n in names if n in listed]


def test_namespaces_left_by_a_crashed_run_are_deleted_by_the_next() -> None:
    gone = subprocess.Popen(["true"])
    gone.wait()  # a pid that is no longer alive: the maker of the namespace crashed
    stale = f"{netns.PREFIX}{gone.pid}-1-sw"
    subprocess.run(["ip", "netns", "add", stale], check=True)
    inside = subprocess.Popen(["ip", "netns", "exec", stale, "sleep", "300"])
    try:
        with netns.Network():
            listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
            assert stale not in listed
        assert inside.wait(10) is not None
    finally:
        if inside.poll() is None:
            inside.kill()
        subprocess.run(["ip", "netns", "del", stale], capture_output=True)
