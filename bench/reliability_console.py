"""The console's door and its names (issue 23.4, 23.5, 23.10), measured on ``lunaris console``
run as a process with an accounts file, against a router and a twin of MAPP's clock and battery:
real HTTP requests on 127.0.0.1 (the brute force from 127.0.0.2-4, so each has an address of its
own), timed. ``console_cases(tmp)`` gives (case, measured, target, ok) rows.

    cd bench && python reliability_console.py
"""

from __future__ import annotations

import http.client
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import urlencode

from benchlib import ROOT

from common import keys
from lunaris.console.auth import Accounts, Attempts
from lunaris.console.server import ACCOUNTS_S, REQUEST_S
from testbed.console import Console, start_console
from testbed.twin import (
    Probe,
    Twin,
    free_endpoint,
    lunaris_cmd,
    open_router,
    static_rover,
    stop_process,
    wait_for,
)

R = "mapp-1"
EVIL = "<img src=x onerror=alert(1)>"
PASSWORDS = {"ana": "crater-rim-instructor", "obi": "lander-side-observer", "cyd": "regolith-dust-watcher"}
WEAK = ["password", "12345678", "password123", "zzzzzzzzzzzz", "cyd-is-watching", "0987654321"]
SCENARIO = (f"scenario: {{name: '{EVIL}', description: '{EVIL}'}}\nrover: {R}\nstart: reset\n"
            "steps:\n  - {name: dust, at_s: 2, inject: {component: solar/left, kind: dust, value: 0.25}}\n")
Case = tuple[str, str, str, bool]
Answer = tuple[int, dict[str, str], bytes]


def ask(port: int, method: str, path: str, body: bytes = b"", headers: dict[str, str] | None = None,
        source: str = "127.0.0.1", host: str | None = None, timeout: float = 20) -> Answer:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout, source_address=(source, 0))
    try:
        c.request(method, path, body=body, headers={"Host": host or f"127.0.0.1:{port}", **(headers or {})})
        r = c.getresponse()
        return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
    finally:
        c.close()


def sign_in(port: int, user: str, password: str, source: str = "127.0.0.1", timeout: float = 20) -> Answer:
    form = urlencode({"user": user, "password": password, "next": "/"}).encode()
    return ask(port, "POST", "/login", form, {"Content-Type": "application/x-www-form-urlencoded"}, source,
               timeout=timeout)


def cookie(port: int, user: str) -> str:
    status, h, _ = sign_in(port, user, PASSWORDS[user])
    assert status == 303, f"{user} could not sign in: {status}"
    return h["set-cookie"].split(";", 1)[0]


class Stream(threading.Thread):
    """``/api/live`` followed: the time of each message, and when the server ended it."""

    def __init__(self, port: int, cookie: str):
        super().__init__(daemon=True)
        self.port, self.cookie, self.ctype, self.started, self.ended = port, cookie, "", time.time(), 0.0
        self.times: list[float] = []  # wall clock, to compare with a file's mtime
        self.messages: list[dict] = []
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)

    def run(self) -> None:
        try:
            self.conn.request("GET", "/api/live", headers={"Cookie": self.cookie})
            r = self.conn.getresponse()
            self.ctype = r.getheader("content-type", "")
            for line in r:
                if line.startswith(b"data: "):
                    self.times.append(time.time())
                    if len(self.messages) < 5:
                        self.messages.append(json.loads(line[6:]))
        except (OSError, http.client.HTTPException, ValueError, AttributeError):
            pass  # AttributeError: closed from the measuring's side
        self.ended = time.time()


def held_open(port: int, first: bytes, drip: bytes = b"") -> float:
    """Seconds until the server closes a connection that sent ``first`` then ``drip`` a byte a
    second (a slow client), at most 3 x REQUEST_S."""
    t0 = time.monotonic()
    with socket.create_connection(("127.0.0.1", port)) as s:
        s.sendall(first)
        s.settimeout(1.0)
        try:
            for i in range(int(3 * REQUEST_S)):
                try:
                    if not s.recv(4096):
                        break  # closed (after a 408, or without a word)
                except TimeoutError:
                    s.sendall(drip[i:i + 1])
        except OSError:
            pass  # reset
    return time.monotonic() - t0


def rebinding(port: int, ana: str, p: Probe) -> Case:
    evil = {"Cookie": ana, "Origin": f"http://evil.example:{port}"}
    fault = f"/api/rovers/{R}/keys/fault/battery/heating"
    codes = [ask(port, "GET", path, headers=evil, host=f"evil.example:{port}")[0]
             for path in ("/api/me", "/")]
    codes.append(ask(port, "PUT", fault, b"55", evil, host=f"evil.example:{port}")[0])
    time.sleep(1.0)
    leaked = len(p.samples(keys.fault(R, "battery", "heating")))
    own = ask(port, "PUT", fault, b"5", {"Cookie": ana, "Origin": f"http://127.0.0.1:{port}"})[0]
    ask(port, "DELETE", fault, headers={"Cookie": ana})
    ok = codes == [421] * 3 and leaked == 0 and own == 200
    return ("console: DNS rebinding (Host evil.example, instructor's cookie)",
            f"GET /api/me, GET /, PUT heating 55 -> {', '.join(map(str, codes))}; {leaked} fault samples "
            f"on the twin; the same PUT with Host 127.0.0.1 -> {own}",
            "421 for every foreign Host, nothing written", ok)


def stored_xss(port: int, ana: str, p: Probe, recordings: Path) -> Case:
    h = {"Cookie": ana, "Content-Type": "application/json"}
    trainee = ask(port, "PUT", f"/api/rovers/{R}/keys/control/session",
                  json.dumps({"trainee": EVIL}).encode(), h)
    record = ask(port, "POST", "/api/recordings", json.dumps({"name": EVIL}).encode(), h)
    time.sleep(0.5)
    sent = len(p.samples(keys.under(R, "control/session")))
    made = sorted(x.name for x in recordings.iterdir()) if recordings.exists() else []
    scen = ask(port, "GET", "/api/scenarios", headers=h)
    served = any(s.get("name") == EVIL for s in json.loads(scen[2]).get("scenarios", []))
    forged, live = False, Stream(port, ana)
    for _ in range(5):  # a forged load name, put by any client of the twin, while the console listens
        p.put(keys.load_power(R, EVIL), {"t_s": 1.0, "power_w": 1.5, "rail": "12V", "on": True, "faults": []})
        time.sleep(0.5)
        live = Stream(port, ana)
        live.start()
        wait_for(lambda: live.messages or live.ended, 10, "the live stream's snapshot")  # noqa: B023
        live.conn.close()
        if forged := bool(live.messages) and EVIL in json.dumps(live.messages[0], ensure_ascii=False):
            break
    page = ask(port, "GET", "/", headers={"Cookie": ana})
    login = ask(port, "GET", "/login?" + urlencode({"next": "/" + EVIL}))
    htmls = [a for a in (trainee, record, scen, page, login) if "html" in a[1].get("content-type", "")]
    markup = sum(EVIL.encode() in a[2] for a in htmls)
    csp = "script-src 'self'" in page[1].get("content-security-policy", "")
    jsons = all(a[1].get("content-type", "").startswith("application/json") for a in (trainee, record, scen))
    named = b"bad name" in record[2]
    ok = (trainee[0] == 422 and 400 <= record[0] < 500 and named and sent == 0 and not made and served
          and forged and "event-stream" in live.ctype and markup == 0 and csp and jsons)
    nosniff = "yes" if "x-content-type-options" in page[1] else "no"
    return ("console: stored XSS (trainee, recording, scenario, load names)",
            f"trainee {trainee[0]}, recording name {record[0]} ({'bad name' if named else '?'}), "
            f"{sent} sent, {len(made)} files; scenario name {'served' if served else 'NOT seen'} as JSON, "
            f"forged load name {'in' if forged else 'NOT in'} the live snapshot ({live.ctype}); "
            f"{markup} of {len(htmls)} HTML answers hold the markup; CSP script-src 'self' "
            f"{'yes' if csp else 'NO'}; nosniff {nosniff}; the page draws names with lit-html (text)",
            "refused (4xx) or JSON data only, never markup in HTML", ok)


def brute_force(port: int) -> list[Case]:
    rows: list[Case] = []
    free = range(Attempts.FREE)
    for who, tries, right, source, said in (
            ("one user (ana), each guess from another address", [("ana", f"127.0.1.{i + 1}") for i in free],
             "ana", "127.0.1.99", b"for the user"),
            ("one address (127.0.0.3), each guess another name", [(f"guess{i}", "127.0.0.3") for i in free],
             "obi", "127.0.0.3", b"from this computer")):
        t0 = time.monotonic()
        codes = [sign_in(port, n, "a wrong guess", address)[0] for n, address in tries]
        took = (time.monotonic() - t0) / len(tries)
        status, h, body = sign_in(port, right, PASSWORDS[right], source)
        ok = codes == [401] * len(tries) and status == 429 and "retry-after" in h and said in body
        rows.append((f"console: sign-in brute force, {who}",
                     f"{len(tries)} wrong -> {sorted(set(codes))} ({took:.2f} s each); then {right}'s right "
                     f"password -> {status}, Retry-After {h.get('retry-after', '-')} s, "
                     f"said {said.decode()!r}: {'yes' if said in body else 'no'}",
                     f"refused (429) after {Attempts.FREE} wrong", ok))
    n = 20
    t0 = time.monotonic()
    with ThreadPoolExecutor(n) as pool:
        codes = list(pool.map(lambda i: _guess(port, f"guess {i}"), range(n)))
    checked = codes.count(401)
    rows.append((f"console: sign-in burst, {n} parallel guesses from one address",
                 f"{checked} passwords checked (401), {codes.count(429)} refused (429), {codes.count(0)} "
                 f"unanswered in 60 s; {time.monotonic() - t0:.1f} s in all",
                 f"at most {Attempts.FREE} checked", checked <= Attempts.FREE))
    return rows


def _guess(port: int, password: str) -> int:
    try:
        return sign_in(port, "zed", password, "127.0.0.4", 60)[0]
    except (OSError, http.client.HTTPException):
        return 0


def weak_passwords(tmp: Path) -> Case:
    def add(i: int, password: str) -> int:
        return subprocess.run(lunaris_cmd("console", "users", "add", "cyd", "--role", "observer",
                                          "--accounts", str(tmp / f"weak-{i}.json"), "--password-stdin"),
                              input=password + "\n", capture_output=True, text=True, timeout=60,
                              cwd=ROOT).returncode
    with ThreadPoolExecutor(4) as pool:
        codes = list(pool.map(add, range(len(WEAK) + 1), [*WEAK, PASSWORDS["cyd"]]))
    refused = sum(c != 0 and not (tmp / f"weak-{i}.json").exists() for i, c in enumerate(codes[:-1]))
    return ("console: weak passwords (lunaris console users add)",
            f"{refused} of {len(WEAK)} refused ({', '.join(WEAK)}); a strong one -> exit {codes[-1]}",
            "every weak one refused, a strong one added", refused == len(WEAK) and codes[-1] == 0)


def console_cases(tmp: Path) -> list[Case]:
    tmp.mkdir(parents=True, exist_ok=True)
    accounts, scenarios, recordings = tmp / "users.json", tmp / "scenarios", tmp / "recordings"
    for user, password in PASSWORDS.items():
        Accounts.add(accounts, user, "instructor" if user == "ana" else "observer", password, replace=True)
    scenarios.mkdir(exist_ok=True)
    (scenarios / "evil.yaml").write_text(SCENARIO)
    endpoint = free_endpoint()
    router = open_router(endpoint)
    console: Console | None = None
    try:
        with Twin(endpoint, [static_rover("mapp.yaml")], tmp / "state", services=("clock", "battery")), \
                Probe(endpoint) as p:
            p.watch(keys.under(R, "**"))
            p.wait_services(R, ("clock", "battery"))
            console = start_console(endpoint, tmp, "--accounts", str(accounts), "--scenarios",
                                    str(scenarios))
            port = console.port
            ana = cookie(port, "ana")
            wait_for(lambda: b"mapp-1" in ask(port, "GET", "/api/about", headers={"Cookie": ana})[2],
                     20, "the console to see the twin", poll_s=0.3)
            stream = Stream(port, cookie(port, "cyd"))
            stream.start()
            with ThreadPoolExecutor(3) as pool:  # three slow clients while the rest goes on
                slow = [pool.submit(held_open, port, b"POST /login HTTP/1.1\r\nHost: 127.0.0.1\r\n"),
                        pool.submit(held_open, port, b"POST /login HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                    b"Content-Length: 40\r\n\r\nuser=ana", b"&password=crater-rim"),
                        pool.submit(held_open, port, b"GET /api/me HTTP/1.1\r\n", b"X-Slow: " + b"a" * 60)]
                rows = [rebinding(port, ana, p), stored_xss(port, ana, p, recordings), weak_passwords(tmp)]
                closed = [f.result() for f in slow]
            rows.append(("console: slow requests (headers unfinished; headers, body a byte/s)",
                         "closed after " + ", ".join(f"{s:.1f}" for s in closed) + " s",
                         f"closed within REQUEST_S {REQUEST_S:g} s (+1 s)", max(closed) <= REQUEST_S + 1))
            rows.append(_removed(accounts, stream))
            rows.extend(brute_force(port))
            return rows
    finally:
        if console is not None:
            stop_process(console.proc, 10)
        router.close()


def _removed(accounts: Path, stream: Stream) -> Case:
    time.sleep(max(0.0, stream.started + REQUEST_S + 1 - time.time()))  # open past the request deadline
    open_s = time.time() - stream.started
    before, alive = len(stream.times), stream.is_alive() and bool(stream.times) and open_s > REQUEST_S
    done = subprocess.run(lunaris_cmd("console", "users", "remove", "cyd", "--accounts", str(accounts)),
                          capture_output=True, timeout=60, cwd=ROOT)
    removed = accounts.stat().st_mtime  # when the file said it
    stream.join(10)
    took = float("inf") if stream.is_alive() else stream.ended - removed
    after = sum(t > removed + 0.05 for t in stream.times)
    stream.conn.close()
    limit = ACCOUNTS_S + 1
    return ("console: a removed user's open live stream",
            f"open {open_s:.1f} s with {before} messages; users remove (exit {done.returncode}) -> closed "
            f"{took:.2f} s after the file changed, {after} messages after",
            f"open past REQUEST_S; closed within {limit:g} s",
            alive and done.returncode == 0 and took <= limit)


if __name__ == "__main__":
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="lunaris-console-rel-") as folder:
        got = console_cases(Path(folder))
    for case, measured, target, ok in got:
        print(f"{'ok' if ok else 'NO'} | {case} | {measured} | {target}")
    print(f"({time.monotonic() - t0:.1f} s)")
    sys.exit(0 if all(r[3] for r in got) else 1)
