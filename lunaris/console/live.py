"""The console's live view of the twin: what every page is sent, as it changes.

One :class:`Hub` per console, around the client's mirror of every rover
(:class:`lunaris.client.Mirror`: the latest payload of every telemetry key, the recent events
of each rover taken once, the live services, each rover's link, a short history for the plots,
all of it bounded whatever is published) and its writer (:class:`lunaris.client.Writer`, which
answers the API's writes). The mirror tells the hub of each change on Zenoh's threads; the hub
hands them to the asyncio loop in bulk (the first change after a quiet spell schedules one
``call_soon_threadsafe``, the loop drains everything that came meanwhile) and folds them into
*batches*: the first change after a quiet spell goes out at once, then at most one batch per
``flush_s``, so a fault reaches the page within milliseconds while twenty pages at 10 Hz
telemetry cost the console one encoding per batch, not one per page per sample.

A page gets a *snapshot* (everything), then every batch after it. A page too slow to keep up
(it fell out of the last ``LOG`` batches), or a page whose rovers were forgotten (their
services long gone), gets a snapshot again. Twice a second the hub looks at the router and at
each rover's link (lost when its clock has not ticked for 2 s): a change goes out in a batch's
``links`` (and as a ``link`` message for the router), so a cut shows within 3 s.

The messages (``data:`` lines of the event stream, JSON):

- ``{"type": "snapshot", "v", "values": {key: payload}, "events": [event], "services":
  {rover: [service]}, "history": {rover: {t, soc, temperature_c, load_w, generation_w}},
  "connected": bool, "router": {"state", "endpoint", "message"}, "links": {rover: {"state":
  "up"|"lost"|"unknown", "since": wall time or null, "reason": words}}, "sessions": {rover:
  {"id", "trainee"}}}``
- ``{"type": "batch", "v", "values", "events", "services", "links", "sessions"}``: what
  changed (``links`` holds the rovers whose link changed, ``sessions`` those whose session's
  trainee became known: often none)
- ``{"type": "link", "v", "connected": bool, "router"}``: the router came or went.

``router`` says where the console is with the twin's router, in words for the page:
``state`` is ``waiting`` (the console has not reached it yet: it serves the page before the
twin is up), ``connected`` or ``lost``; ``message`` is "waiting for the twin at
tcp/127.0.0.1:7447 ...", "connected to the twin at ..." or "the twin at ... is gone ...".

``sessions`` says each rover's trainee session (SPEC §12c): ``id`` (as ``get sessions`` lists
it) and ``trainee`` (``""``: none named; null: not known yet). When a rover's session changes
(a new trainee), the mirror has dropped that rover's history and events, and every page is
sent a snapshot: its plots and event log start empty with the session.
"""

from __future__ import annotations

import asyncio
import bisect
import threading
from collections import deque
from collections.abc import AsyncIterator
from typing import Any

import msgspec
import zenoh

from common import keys
from lunaris.client import Change, Link, Mirror, Writer

__all__ = ["Hub"]

LOG = 200  # batches kept for pages that are a little behind
EVENTS = 300  # recent events kept per rover
HISTORY = 900  # points of the plots' history per rover (one a second: 15 minutes)
HISTORY_S = 1.0
KEEPALIVE_S = 15.0
LINKS_S = 0.5  # how often the router and the rovers' links are looked at
RESTART_S = 5.0  # rovers forgotten: the pages start again from a snapshot at most this often
PENDING_EVENTS = 2000  # events held for the next batch at most (a flood is cut, not kept)


class Hub:
    def __init__(self, loop: asyncio.AbstractEventLoop, flush_s: float = 0.05, endpoint: str = "",
                 **mirror: Any):
        self.loop = loop
        self.flush_s = flush_s
        self.endpoint = endpoint or "its router"
        self.started = False  # the Zenoh session is open and the mirror subscribed
        self.mirror = Mirror("*", keep_events=EVENTS, history={"battery/state": HISTORY,
                                                               "power/summary": HISTORY},
                             history_every_s=HISTORY_S, **mirror)
        self.writer: Writer | None = None
        self.connected = False
        self.links: dict[str, Link] = {}
        self.version = 0
        self._log: deque[tuple[int, bytes]] = deque(maxlen=LOG)
        self._lock = threading.Lock()
        self._incoming: list[Change] = []  # from Zenoh threads
        self._scheduled = False
        self._pending_values: dict[str, bytes] = {}
        self._pending_events: deque[bytes] = deque(maxlen=PENDING_EVENTS)
        self._pending_services: set[str] = set()
        self._pending_links: dict[str, Link] = {}
        self._pending_sessions: set[str] = set()
        self._session_ids: dict[str, str] = {}  # rover -> the session the pages were sent
        self._flush_handle: asyncio.TimerHandle | None = None
        self._last_flush = 0.0
        self._changed = asyncio.Event()
        self._watch: asyncio.Task | None = None
        self._restart_due = False
        self._last_restart = 0.0
        self.closed = False

    # -- Zenoh ------------------------------------------------------------------------------

    def start(self, session: zenoh.Session) -> None:
        """Mirror every rover (the publishers' caches replayed first: a console started
        mid-session shows the current values at once) and look at the links twice a second."""
        self.mirror.listen(self._hand)
        self.mirror.start(session)
        self.writer = Writer(session, self.mirror, "instructor")
        self.started = True
        self._watch = self.loop.create_task(self._watch_links())

    def router(self) -> dict[str, str]:
        """Where the console is with the twin's router, in words (the module's ``router``)."""
        if not self.started:
            return {"state": "waiting", "endpoint": self.endpoint, "message":
                    f"waiting for the twin at {self.endpoint}: nothing answers there yet (start "
                    "the twin with make run, or lunaris up)"}
        if self.connected:
            return {"state": "connected", "endpoint": self.endpoint,
                    "message": f"connected to the twin at {self.endpoint}"}
        return {"state": "lost", "endpoint": self.endpoint, "message":
                f"the twin's router at {self.endpoint} is gone: waiting for it to come back"}

    def not_connected(self) -> str | None:
        """Why a write or a query cannot go to the twin now (None: it can)."""
        if not self.started:
            return (f"not applied: the console is not connected to the twin yet (waiting for it at "
                    f"{self.endpoint})")
        return None

    def stop(self) -> None:
        self.closed = True
        if self._watch is not None:
            self._watch.cancel()
        if self.writer is not None:
            self.writer.close()
        self.mirror.close()
        self._notify()

    def _hand(self, change: Change) -> None:  # on a Zenoh thread
        with self._lock:
            self._incoming.append(change)
            if self._scheduled or self.closed:
                return
            self._scheduled = True
        self.loop.call_soon_threadsafe(self._drain)

    # -- on the loop ------------------------------------------------------------------------

    def _drain(self) -> None:
        with self._lock:
            items, self._incoming = self._incoming, []
            self._scheduled = False
        forgot = new_session = False
        for c in items:
            if c.kind == "value":
                self._pending_values[c.key] = c.raw
            elif c.kind == "event":
                self._pending_events.append(c.raw)
            elif c.kind == "services":
                self._pending_services.add(c.rover)
            elif c.kind == "session":  # a new trainee: the pages start again, empty of the last
                new_session |= self._session_ids.get(c.rover) != c.value.id
                self._session_ids[c.rover] = c.value.id
                self._pending_sessions.add(c.rover)
            else:  # forget: the pages start again from a snapshot without it
                forgot = True
        if forgot or new_session:
            self._restart_due = True
            self._restart(force=new_session)
        self._schedule()

    def _restart(self, force: bool = False) -> None:
        """Every page takes a new snapshot (a rover was forgotten), at most every RESTART_S
        (a flood of forged rovers, each making room for the next, costs the pages little);
        at once for a new session (``force``: the clock's ticks say it, which only the clock
        may publish)."""
        if not self._restart_due or (not force and self.loop.time() - self._last_restart < RESTART_S):
            return
        self._restart_due, self._last_restart = False, self.loop.time()
        self.version += 1
        self._log.clear()
        self._pending_values, self._pending_services = {}, set()
        self._pending_events.clear()
        self._pending_links = {}
        self._pending_sessions = set()
        self._notify()

    async def _watch_links(self) -> None:
        """The router and every rover's link, twice a second; forgetting what is long gone."""
        while not self.closed:
            try:
                connected = await asyncio.to_thread(self.mirror.refresh_connection)
            except zenoh.ZError:
                connected = False
            self.set_connected(connected)
            links = self.mirror.links()
            changed = {r: lk for r, lk in links.items()
                       if (old := self.links.get(r)) is None or old.state != lk.state}
            self.links = links
            if changed:
                self._pending_links.update(changed)
                self._schedule()
            self.mirror.sweep()  # a rover forgotten comes to _hand, as every change
            self._restart()  # one left waiting, if any
            await asyncio.sleep(LINKS_S)

    def _schedule(self) -> None:
        if self._flush_handle is not None:
            return
        delay = max(0.0, self._last_flush + self.flush_s - self.loop.time())
        self._flush_handle = self.loop.call_later(delay, self._flush)

    def _flush(self) -> None:
        self._flush_handle = None
        self._last_flush = self.loop.time()
        if not (self._pending_values or self._pending_events or self._pending_services
                or self._pending_links or self._pending_sessions):
            return
        self.version += 1
        values = b",".join(msgspec.json.encode(k) + b":" + v for k, v in self._pending_values.items())
        services = msgspec.json.encode({r: sorted(self.mirror.services(r)) for r in self._pending_services})
        links = msgspec.json.encode({r: lk.as_json() for r, lk in self._pending_links.items()})
        sessions = msgspec.json.encode({r: s for r, s in self.sessions().items()
                                        if r in self._pending_sessions})
        body = (b'{"type":"batch","v":%d,"values":{%s},"events":[%s],"services":%s,"links":%s,'
                b'"sessions":%s}' % (self.version, values, b",".join(self._pending_events), services,
                                     links, sessions))
        self._pending_values, self._pending_services, self._pending_links = {}, set(), {}
        self._pending_sessions = set()
        self._pending_events.clear()
        self._log.append((self.version, body))
        self._notify()

    def _notify(self) -> None:
        old, self._changed = self._changed, asyncio.Event()
        old.set()

    def set_connected(self, connected: bool) -> None:
        if connected != self.connected:
            self.connected = connected
            self.version += 1
            self._log.append((self.version, b'{"type":"link","v":%d,"connected":%s,"router":%s}'
                              % (self.version, b"true" if connected else b"false",
                                 msgspec.json.encode(self.router()))))
            self._notify()

    # -- what pages are sent ------------------------------------------------------------------

    def history(self) -> dict[str, dict[str, list]]:
        """The plots' history of each rover: a point a second of the battery's state, with the
        power summary of that moment."""
        out = {}
        for rover in self.mirror.rovers():
            points = self.mirror.history(keys.battery_state(rover))
            if not points:
                continue
            power = self.mirror.history(keys.power_summary(rover))
            at = [p.at for p in power]
            h: dict[str, list] = {n: [] for n in ("t", "soc", "temperature_c", "load_w", "generation_w")}
            for b in points:
                i = bisect.bisect_right(at, b.at) - 1
                p = power[i].value if i >= 0 else None
                h["t"].append(round(b.at, 3))
                h["soc"].append(round(b.value.soc * 100, 4))
                h["temperature_c"].append(round(b.value.temperature_c, 3))
                h["load_w"].append(round(p.load_power_w, 3) if p else None)
                h["generation_w"].append(round(p.generation_w, 3) if p else None)
            out[rover] = h
        return out

    def sessions(self) -> dict[str, dict[str, str | None]]:
        """Each rover's trainee session as the pages are sent it: ``{"id", "trainee"}``."""
        return {r: {"id": s.id, "trainee": s.trainee} for r, s in self.mirror.sessions().items()}

    def snapshot(self) -> bytes:
        latest = self.mirror.latest()
        values = b",".join(msgspec.json.encode(k) + b":" + v.raw for k, v in latest.items())
        events = b",".join(raw for _, _, raw in self.mirror.events())
        rest = msgspec.json.encode({
            "services": {r: sorted(s) for r, s in self.mirror.all_services().items()},
            "history": self.history(),
            "connected": self.connected,
            "router": self.router(),
            "links": {r: lk.as_json() for r, lk in self.mirror.links().items()},
            "sessions": self.sessions()})
        return (b'{"type":"snapshot","v":%d,"values":{%s},"events":[%s],%s'
                % (self.version, values, events, rest[1:]))

    async def stream(self, alive: Any = None) -> AsyncIterator[bytes]:
        """Server-sent events for one page: a snapshot, then every batch; a keep-alive comment
        when nothing happens (a page that went away is found out then). ``alive()``, asked
        at every turn, ends the stream when false (its user was removed, its sign-in ended)."""
        seen = self.version
        yield b"data: " + self.snapshot() + b"\n\n"
        while not self.closed and (alive is None or alive()):
            if self.version == seen:
                changed = self._changed
                try:
                    await asyncio.wait_for(changed.wait(), KEEPALIVE_S)
                except TimeoutError:
                    yield b": keep-alive\n\n"
                    continue
                if self.closed or (alive is not None and not alive()):
                    break
            if not self._log or self._log[0][0] > seen + 1:
                seen = self.version  # fell behind, or the rovers changed: start again
                yield b"data: " + self.snapshot() + b"\n\n"
                continue
            out = [b"data: " + body + b"\n\n" for v, body in self._log if v > seen]
            seen = self.version
            yield b"".join(out)

    def wake(self) -> None:
        """Wake every stream (to look at ``alive`` again: a user was removed)."""
        self._notify()
