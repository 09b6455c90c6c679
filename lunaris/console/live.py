"""The console's live view of the twin: what every page is sent, as it changes.

One :class:`Hub` per console. Zenoh calls back on its own threads; each sample is checked
against its key family's Struct there (a payload that is not what its key carries is
ignored, and said once), then handed to the asyncio loop in bulk: the first sample after a
quiet spell schedules one ``call_soon_threadsafe``, and the loop drains everything that came
meanwhile. The loop keeps the latest payload of every telemetry key, the recent events of
each rover, the live services, and a short history for the plots, and folds the changes into
*batches*: the first change after a quiet spell goes out at once, then at most one batch per
``flush_s``, so a fault reaches the page within milliseconds while twenty pages at 10 Hz
telemetry cost the console one encoding per batch, not one per page per sample.

A page gets a *snapshot* (everything), then every batch after it. A page too slow to keep up
(it fell out of the last ``LOG`` batches) gets a snapshot again. The hub also answers the
API's writes: :meth:`Hub.answer` waits for the event that accepts or rejects a write.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections import deque
from collections.abc import AsyncIterator
from typing import Any

import msgspec
import zenoh
import zenoh.ext as zext

from common import keys
from common.messages import BatteryState, Event, PowerSummary
from lunaris.client import ignored

__all__ = ["Hub"]

LOG = 200  # batches kept for pages that are a little behind
EVENTS = 300  # recent events kept per rover
HISTORY = 900  # points of the plots' history per rover (one a second: 15 minutes)
HISTORY_S = 1.0
KEEPALIVE_S = 15.0


class _Waiter:
    __slots__ = ("future", "key", "kinds")

    def __init__(self, future: asyncio.Future, key: str, kinds: set[str]):
        self.future, self.key, self.kinds = future, key, kinds


class Hub:
    def __init__(self, loop: asyncio.AbstractEventLoop, flush_s: float = 0.05):
        self.loop = loop
        self.flush_s = flush_s
        self.latest: dict[str, bytes] = {}
        self.events: dict[str, deque[bytes]] = {}
        self.services: dict[str, set[str]] = {}
        self.history: dict[str, dict[str, deque]] = {}
        self.connected = False
        self.version = 0
        self._log: deque[tuple[int, bytes]] = deque(maxlen=LOG)
        self._lock = threading.Lock()
        self._incoming: list[tuple[str, str, Any]] = []  # (what, key, payload) from Zenoh threads
        self._scheduled = False
        self._pending_values: dict[str, bytes] = {}
        self._pending_events: list[bytes] = []
        self._pending_services: set[str] = set()
        self._flush_handle: asyncio.TimerHandle | None = None
        self._last_flush = 0.0
        self._changed = asyncio.Event()
        self._waiters: list[_Waiter] = []
        self._seen_events: deque[tuple] = deque(maxlen=4096)
        self._seen_set: set[tuple] = set()
        self._decoders: dict[type, msgspec.json.Decoder] = {}
        self._keep: list[Any] = []
        self._last_point: dict[str, float] = {}
        self.closed = False

    # -- Zenoh ------------------------------------------------------------------------------

    def start(self, session: zenoh.Session) -> None:
        """Subscribe to every telemetry family of every rover, with the publishers' caches
        replayed first (a console started mid-session shows the current values at once)."""
        history = zext.HistoryConfig(detect_late_publishers=True)
        for family in keys.families("out"):
            self._keep.append(zext.declare_advanced_subscriber(
                session, family.pattern("*"), self._on_sample, history=history))
        self._keep.append(session.liveliness().declare_subscriber(
            keys.service("*", "*"), self._on_token, history=True))
        self.session = session

    def stop(self) -> None:
        self.closed = True
        self._keep.clear()
        self._notify()

    def _on_sample(self, s: zenoh.Sample) -> None:  # on a Zenoh thread
        key = str(s.key_expr)
        try:
            _, parts = keys.split(key)
        except ValueError:
            return
        family = keys.telemetry_family(parts)
        if family is None or s.kind != zenoh.SampleKind.PUT:
            return
        payload = s.payload.to_bytes()
        dec = self._decoders.get(family.payload)
        if dec is None:
            dec = self._decoders[family.payload] = msgspec.json.Decoder(family.payload)
        try:
            value = dec.decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            ignored(key, f"not a valid {family.payload.__name__} ({exc})")
            return
        self._hand("event" if family.name == "event" else "value", key, (payload, value))

    def _on_token(self, s: zenoh.Sample) -> None:  # on a Zenoh thread
        self._hand("token", str(s.key_expr), s.kind == zenoh.SampleKind.PUT)

    def _hand(self, what: str, key: str, payload: Any) -> None:
        with self._lock:
            self._incoming.append((what, key, payload))
            if self._scheduled or self.closed:
                return
            self._scheduled = True
        self.loop.call_soon_threadsafe(self._drain)

    # -- on the loop ------------------------------------------------------------------------

    def _drain(self) -> None:
        with self._lock:
            items, self._incoming = self._incoming, []
            self._scheduled = False
        now = time.time()
        for what, key, payload in items:
            rover, parts = keys.split(key)
            if what == "token":
                live = self.services.setdefault(rover, set())
                (live.add if payload else live.discard)(parts[-1])
                self._pending_services.add(rover)
                continue
            raw, value = payload
            if what == "event":
                self._on_event(rover, raw, value)
                continue
            self.latest[key] = raw
            self._pending_values[key] = raw
            if parts == ["battery", "state"]:
                self._point(rover, now)
        self._schedule()

    def _on_event(self, rover: str, raw: bytes, ev: Event) -> None:
        ident = (rover, ev.source_id, ev.seq) if ev.source_id else (rover, ev.t_s, ev.source, ev.kind,
                                                                     ev.key, ev.message)
        if ident in self._seen_set:  # a cache replayed after a reconnection
            return
        if len(self._seen_events) == self._seen_events.maxlen:
            self._seen_set.discard(self._seen_events[0])
        self._seen_events.append(ident)
        self._seen_set.add(ident)
        self.events.setdefault(rover, deque(maxlen=EVENTS)).append(raw)
        self._pending_events.append(raw)
        for w in list(self._waiters):
            if w.key == ev.key and ev.kind in w.kinds and not w.future.done():
                w.future.set_result(msgspec.structs.asdict(ev))
                self._waiters.remove(w)

    def _point(self, rover: str, now: float) -> None:
        """A point of the plots' history, at most one a second of wall time."""
        if now - self._last_point.get(rover, 0.0) < HISTORY_S:
            return
        self._last_point[rover] = now
        b = self.value(keys.battery_state(rover), BatteryState)
        p = self.value(keys.power_summary(rover), PowerSummary)
        if b is None:
            return
        h = self.history.setdefault(rover, {n: deque(maxlen=HISTORY) for n in
                                            ("t", "soc", "temperature_c", "load_w", "generation_w")})
        h["t"].append(round(now, 3))
        h["soc"].append(round(b.soc * 100, 4))
        h["temperature_c"].append(round(b.temperature_c, 3))
        h["load_w"].append(round(p.load_power_w, 3) if p else None)
        h["generation_w"].append(round(p.generation_w, 3) if p else None)

    def value(self, key: str, typ: type) -> Any:
        raw = self.latest.get(key)
        return None if raw is None else msgspec.json.decode(raw, type=typ)

    def _schedule(self) -> None:
        if self._flush_handle is not None:
            return
        delay = max(0.0, self._last_flush + self.flush_s - self.loop.time())
        self._flush_handle = self.loop.call_later(delay, self._flush)

    def _flush(self) -> None:
        self._flush_handle = None
        self._last_flush = self.loop.time()
        if not (self._pending_values or self._pending_events or self._pending_services):
            return
        self.version += 1
        values = b",".join(msgspec.json.encode(k) + b":" + v for k, v in self._pending_values.items())
        services = msgspec.json.encode({r: sorted(self.services.get(r, ())) for r in self._pending_services})
        body = (b'{"type":"batch","v":%d,"values":{%s},"events":[%s],"services":%s}'
                % (self.version, values, b",".join(self._pending_events), services))
        self._pending_values, self._pending_events, self._pending_services = {}, [], set()
        self._log.append((self.version, body))
        self._notify()

    def _notify(self) -> None:
        old, self._changed = self._changed, asyncio.Event()
        old.set()

    def set_connected(self, connected: bool) -> None:
        if connected != self.connected:
            self.connected = connected
            self.version += 1
            self._log.append((self.version, b'{"type":"link","v":%d,"connected":%s}'
                              % (self.version, b"true" if connected else b"false")))
            self._notify()

    # -- what pages are sent ------------------------------------------------------------------

    def snapshot(self) -> bytes:
        values = b",".join(msgspec.json.encode(k) + b":" + v for k, v in self.latest.items())
        events = b",".join(e for q in self.events.values() for e in q)
        rest = msgspec.json.encode({
            "services": {r: sorted(s) for r, s in self.services.items()},
            "history": {r: {n: list(q) for n, q in h.items()} for r, h in self.history.items()},
            "connected": self.connected})
        return (b'{"type":"snapshot","v":%d,"values":{%s},"events":[%s],%s'
                % (self.version, values, events, rest[1:]))

    async def stream(self) -> AsyncIterator[bytes]:
        """Server-sent events for one page: a snapshot, then every batch; a keep-alive comment
        when nothing happens (a page that went away is found out then)."""
        seen = self.version
        yield b"data: " + self.snapshot() + b"\n\n"
        while not self.closed:
            if self.version == seen:
                changed = self._changed
                try:
                    await asyncio.wait_for(changed.wait(), KEEPALIVE_S)
                except TimeoutError:
                    yield b": keep-alive\n\n"
                    continue
            if not self._log or self._log[0][0] > seen + 1:
                seen = self.version  # fell behind: start again from everything
                yield b"data: " + self.snapshot() + b"\n\n"
                continue
            out = [b"data: " + body + b"\n\n" for v, body in self._log if v > seen]
            seen = self.version
            yield b"".join(out)

    # -- the answers to the API's writes -------------------------------------------------------

    def expect(self, key: str, kinds: set[str]) -> asyncio.Future:
        """A future for the next event on ``key`` of one of ``kinds`` (register before writing)."""
        w = _Waiter(self.loop.create_future(), key, kinds)
        self._waiters.append(w)
        return w.future

    def forget(self, future: asyncio.Future) -> None:
        self._waiters = [w for w in self._waiters if w.future is not future]
