"""The console's web server: Starlette on uvicorn, one Zenoh session, the gate in front.

Every request goes through :class:`Gate` (pure ASGI, so the live stream is not buffered):

- its ``Host`` must be one of the console's own names (the address it listens on, this
  computer's loopback names, and the names given with ``--allow-host`` or
  ``$LUNARIS_ALLOW_HOST``): a page of another site whose name was made to resolve to this
  computer (DNS rebinding) is refused with 421, in words;
- a write whose ``Origin`` is another site is refused with 403;
- every answer says what it is and nothing else (``X-Content-Type-Options: nosniff``: a
  downloaded recording or a JSON answer is never run as a page or a script) and may be
  framed only by the console's own pages (``X-Frame-Options: SAMEORIGIN``: no other site
  shows the console under its own buttons);
- without an accounts file every request is the local instructor's (the server listens on
  loopback only, :mod:`lunaris.console`); with one, a request without a valid sign-in is sent
  to ``/login`` (a page) or refused with 401 (the API).

Sign-ins are limited per user name and per address (:class:`~lunaris.console.auth.Attempts`:
a lockout that doubles, said on the page). A request must be complete (headers and body)
within :data:`REQUEST_S` of its connection or of the answer before it (:class:`Protocol`, the
HTTP/1.1 protocol uvicorn runs), or its connection is closed: a half-sent request holds
nothing for long. A user removed from the accounts file is signed out at once, their live
streams closed within a second.

The page is up before the twin is: given an opener rather than a session, the server answers
at once and opens its Zenoh session behind it (the live stream says "waiting for the twin at
<endpoint>" until then, a write or a query is 503 in words); the hub subscribes on the
server's loop once the session is open. ``GET /api/about`` says, to anyone, that this is a
Lunaris console (``lunaris up`` asks it, to say what holds an address), and to its users the
twin it serves.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import mimetypes
import socket
import sys
import threading
import time
import urllib.parse
from collections.abc import AsyncIterator, Callable, Iterable
from pathlib import Path
from typing import Any

import h11
import zenoh
from starlette.applications import Starlette
from starlette.requests import ClientDisconnect, Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles
from uvicorn.protocols.http.h11_impl import H11Protocol

from lunaris.address import ABOUT_APP, ABOUT_PATH
from lunaris.client import ToolError, close_session
from lunaris.console import api, drive, extras, response, rovers, session_notes
from lunaris.console.auth import COOKIE, LOCAL, SESSION_S, Accounts, AccountsError, Attempts, SignIns
from lunaris.console.live import Hub

__all__ = ["LOCAL_NAMES", "REQUEST_S", "STATIC", "Opener", "Protocol", "host_names", "make_app"]

# Opens the console's Zenoh session, waiting for the router as long as it takes; returns early
# (raising) when the event is set: the console is stopping.
Opener = Callable[[threading.Event], zenoh.Session]

STATIC = Path(__file__).resolve().parent / "static"
mimetypes.add_type("text/javascript", ".js")  # the page's ES modules (RFC 9239), whatever the OS's table says
# The page runs only its own scripts: a name that reached the document as markup could not run.
PAGE_POLICY = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
               "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
               "form-action 'self'; frame-ancestors 'none'")
LOGIN_POLICY = ("default-src 'none'; style-src 'self'; base-uri 'none'; "
                "form-action 'self'; frame-ancestors 'none'")
LIVE_PATH = "/api/live"
PUBLIC = ("/login", "/static/app.css", "/favicon.ico", ABOUT_PATH)
WRITES = {"PUT", "POST", "DELETE", "PATCH"}
LOCAL_NAMES = ("localhost", "127.0.0.1", "::1", "localhost.localdomain")
REQUEST_S = 10.0  # a request's headers and body must be in within this long
LOGIN_BYTES = 4096  # a sign-in form is a name and a password
VERIFYING = 2  # password checks at once (Argon2id takes a core for ~50 ms each)
ACCOUNTS_S = 1.0  # how often the accounts file is looked at for removed users
WRONG_S = 1.0  # what a wrong password costs its sender, besides the lockouts


def host_names(listen_host: str, extra: Iterable[str] = ()) -> set[str]:
    """The names a request's ``Host`` may carry (ports aside): the loopback names, the address
    the console listens on (every address of this computer, and its names, for ``0.0.0.0``
    or ``::``) and ``extra`` (``--allow-host``)."""
    names = {n.lower() for n in (*LOCAL_NAMES, listen_host, *extra) if n}
    if listen_host in ("0.0.0.0", "::", ""):
        for name in {socket.gethostname(), socket.getfqdn()}:
            names.add(name.lower())
            try:
                names.update(str(info[4][0]).lower() for info in socket.getaddrinfo(name, None))
            except OSError:
                pass
    return names


def _host_of(header: str) -> str:
    """``name:port`` or ``[v6]:port`` -> the name, lower case."""
    header = header.strip().lower()
    if header.startswith("["):
        return header[1:].split("]", 1)[0]
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


HARDENING = ((b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"SAMEORIGIN"))


def _hardened(send: Any) -> Any:
    """``send`` with :data:`HARDENING` added to every answer's headers (unless it set them)."""
    async def hardened(message: dict) -> None:
        if message["type"] == "http.response.start":
            headers = list(message.get("headers", []))
            have = {name.lower() for name, _ in headers}
            headers += [h for h in HARDENING if h[0] not in have]
            message = {**message, "headers": headers}
        await send(message)
    return hardened


class Gate:
    """Which site is asking (``Host``, ``Origin``) and who: the local user, a signed-in user,
    or nobody (sign in first)."""

    def __init__(self, app: Any, accounts: Accounts | None, sign_ins: SignIns | None,
                 hosts: set[str]):
        self.app, self.accounts, self.sign_ins, self.hosts = app, accounts, sign_ins, hosts

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        send = _hardened(send)
        scope.setdefault("state", {})
        path = scope["path"]
        headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope["headers"]}
        host = _host_of(headers.get("host", ""))
        if host not in self.hosts:
            shown = ", ".join(sorted(self.hosts))
            await JSONResponse({"message": f"refused: this console is not {host or 'a nameless host'!r}: "
                                           f"it answers to {shown} (give lunaris console "
                                           "--allow-host NAME, or LUNARIS_ALLOW_HOST=NAME,..., for "
                                           "another name of this computer)"},
                               status_code=421)(scope, receive, send)
            return
        if scope["method"] in WRITES and "origin" in headers:
            origin = urllib.parse.urlsplit(headers["origin"]).netloc
            if origin != headers.get("host"):
                await JSONResponse({"message": "refused: a request from another site"},
                                   status_code=403)(scope, receive, send)
                return
        if self.sign_ins is None:
            scope["state"]["user"] = LOCAL
            await self.app(scope, receive, send)
            return
        token = _cookie(headers.get("cookie", ""))
        user = self.sign_ins.user(token)
        if user is not None:
            scope["state"]["user"], scope["state"]["token"] = user, token
            await self.app(scope, receive, send)
        elif path in PUBLIC:
            await self.app(scope, receive, send)
        elif path.startswith("/api/"):
            await JSONResponse({"message": "sign in first"}, status_code=401)(scope, receive, send)
        else:
            nxt = urllib.parse.quote(path)
            await RedirectResponse(f"/login?next={nxt}", status_code=303)(scope, receive, send)


class Protocol(H11Protocol):
    """uvicorn's HTTP/1.1 protocol, with a deadline for each request to be in whole.

    uvicorn closes an idle kept-alive connection, but it waits for ever for a request whose
    headers or body come slowly or never (75 s and counting, issue 23.10): here a request must
    be complete within :data:`REQUEST_S` of its connection, or of the answer before it; past
    that the connection is closed (with a 408 if nothing was answered yet)."""

    _deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()

    def _arm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
        self._deadline = self.loop.call_later(REQUEST_S, self._too_slow)

    def handle_events(self) -> None:
        super().handle_events()
        if self._deadline is not None and self.conn.their_state in (h11.DONE, h11.MUST_CLOSE,
                                                                     h11.CLOSED, h11.ERROR):
            self._deadline.cancel()
            self._deadline = None

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()  # the next request on this connection, if one comes

    def shutdown(self) -> None:
        """The server stops: a live stream, which never ends by itself, is closed at once
        (its page reconnects to the next console) rather than waited for and cancelled."""
        cycle = self.cycle
        if cycle is not None and not cycle.response_complete and cycle.scope.get("path") == LIVE_PATH:
            self.transport.close()
            return
        super().shutdown()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None
        super().connection_lost(exc)

    def _too_slow(self) -> None:
        self._deadline = None
        if self.transport.is_closing() or self.conn.their_state in (h11.DONE, h11.MUST_CLOSE):
            return
        if self.cycle is None and self.conn.their_state is h11.IDLE and self.conn.our_state is h11.IDLE:
            message = (f"the request did not come whole within {REQUEST_S:g} s: closed\n").encode()
            self.transport.write(b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain; "
                                 b"charset=utf-8\r\nconnection: close\r\ncontent-length: %d\r\n\r\n%s"
                                 % (len(message), message))
        self.transport.close()


def _cookie(header: str) -> str | None:
    for part in header.split(";"):
        name, _, value = part.strip().partition("=")
        if name == COOKIE:
            return value
    return None


_LOGIN = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>Sign in - Lunaris console</title><link rel="stylesheet" href="/static/app.css"></head>
<body class="login"><form method="post" action="/login" class="card login-card">
<h1>Lunaris console</h1><p>Sign in with the account your training lead gave you.</p>
{error}<label>User <input name="user" autocomplete="username" autofocus required></label>
<label>Password <input name="password" type="password" autocomplete="current-password" required></label>
<input type="hidden" name="next" value="{next}"><button type="submit" class="primary">Sign in</button>
</form></body></html>"""


def _safe_next(nxt: str) -> str:
    """A path of this console to go back to after signing in, never ``//host`` nor ``/\\host``."""
    return nxt if nxt.startswith("/") and not nxt.startswith(("//", "/\\")) else "/"


def _login_page(error: str, nxt: str, status: int, headers: dict[str, str] | None = None) -> Response:
    shown = f'<p class="error" role="alert">{html.escape(error)}</p>' if error else ""
    return HTMLResponse(_LOGIN.format(error=shown, next=html.escape(nxt)), status_code=status,
                        headers={"Content-Security-Policy": LOGIN_POLICY, **(headers or {})})


def _wait_words(seconds: float) -> str:
    s = int(seconds + 0.999)
    return f"{s // 60} min {s % 60} s" if s >= 60 else f"{s} s"


async def _login(request: Request) -> Response:
    accounts: Accounts | None = request.app.state.accounts
    if accounts is None:
        return RedirectResponse("/", status_code=303)
    if request.method == "GET":
        return _login_page("", _safe_next(request.query_params.get("next", "/")), 200)
    try:
        body = await api.read_body(request, LOGIN_BYTES)
    except api.TooLarge:
        return _login_page("That is not a sign-in.", "/", 413)
    except ClientDisconnect:
        return Response(status_code=400)
    form = urllib.parse.parse_qs(body.decode("utf-8", "replace"))
    name, password = form.get("user", [""])[0], form.get("password", [""])[0]
    nxt = _safe_next(form.get("next", ["/"])[0])
    attempts: Attempts = request.app.state.attempts
    address = request.client.host if request.client else "unknown"
    now = time.monotonic()
    waits = [(attempts.wait_s(f"user:{name}", now), f"for the user {name!r}"),
             (attempts.wait_s(f"address:{address}", now), f"from this computer ({address})")]
    wait, whose = max(waits)
    if wait > 0:
        return _login_page(f"Too many wrong passwords {whose}: sign-in is locked for "
                           f"{_wait_words(wait)} more. Try again then.", nxt, 429,
                           {"Retry-After": str(int(wait + 0.999))})
    # The try counts as a wrong one before its password is checked (a success clears it): a
    # burst of guesses sent at once had every password checked before the first failure was
    # counted (20 of 20, bench/reliability_console.py); now the sixth waits
    attempts.failed(f"user:{name}", now)
    attempts.failed(f"address:{address}", now)
    async with request.app.state.verifying:
        user = await asyncio.to_thread(accounts.check, name, password)
    if user is None:
        await asyncio.sleep(WRONG_S)  # a guesser pays a second a try
        return _login_page("Wrong user or password.", nxt, 401)
    attempts.succeeded(f"user:{name}")
    attempts.succeeded(f"address:{address}")
    token = request.app.state.sign_ins.open(user)
    response = RedirectResponse(nxt, status_code=303)
    response.set_cookie(COOKIE, token, max_age=int(SESSION_S), httponly=True, samesite="strict",
                        secure=request.app.state.tls)
    return response


async def _logout(request: Request) -> Response:
    sign_ins: SignIns | None = request.app.state.sign_ins
    if sign_ins is not None:
        sign_ins.close(request.scope["state"].get("token"))
        request.app.state.hub.wake()  # its live streams end
    response = RedirectResponse("/login" if sign_ins else "/", status_code=303)
    response.delete_cookie(COOKIE)
    return response


async def _favicon(request: Request) -> Response:
    return Response(status_code=204)


async def _index(request: Request) -> Response:
    return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store",
                                                        "Content-Security-Policy": PAGE_POLICY})


async def _about(request: Request) -> Response:
    """Who answers here: a Lunaris console; to its users, the twin it serves and its rovers."""
    about: dict[str, Any] = {"app": ABOUT_APP}
    if "user" in request.scope["state"]:
        hub: Hub = request.app.state.hub
        about.update(twin=hub.endpoint, connected=hub.connected,
                     rovers=[r for r in hub.mirror.rovers() if hub.mirror.services(r)])
    return JSONResponse(about)


def make_app(twin: zenoh.Session | Opener, accounts: Accounts | None, *, tls: bool = False,
             scenarios_dir: Path | None = None, recordings_dir: Path | None = None,
             traverse_dirs: Iterable[Path] = (), rover_files: rovers.RoverFiles | None = None,
             connection: list[str] | None = None, flush_s: float = 0.05,
             hosts: Iterable[str] | None = None, endpoint: str = "",
             give_up: Callable[[str], None] | None = None, **mirror: Any) -> Any:
    """The console as an ASGI application around the twin: an open Zenoh session, or an
    :data:`Opener` run behind the server (the page is up first; ``give_up(why)`` is called if
    the opener fails, e.g. no router within ``--wait``). ``endpoint``: the twin's address in
    words. ``traverse_dirs``: folders of traverse files offered besides the shipped ones;
    ``rover_files``: the rover files the console knows (which radios follow the drive).
    ``hosts``: the names a request's ``Host`` may carry (:func:`host_names`; default the
    loopback names)."""

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        hub = Hub(asyncio.get_running_loop(), flush_s, endpoint=endpoint, **mirror)
        app.state.hub = hub
        app.state.responses = response.Responses(hub.mirror)  # the crew's response, live (SPEC 12d)
        hub.mirror.listen(app.state.responses.on_change)
        app.state.verifying = asyncio.Semaphore(VERIFYING)
        stop = threading.Event()
        connecting = None
        if isinstance(twin, zenoh.Session):
            _connected(app, twin)
        else:
            connecting = asyncio.create_task(_connect(app, twin, stop, give_up))
        watch = asyncio.create_task(_watch_accounts(app)) if accounts is not None else None
        try:
            yield
        finally:
            stop.set()
            for task in (watch, connecting):
                if task is not None:
                    task.cancel()
            app.state.extras.close()
            hub.stop()
            if connecting is not None and app.state.session is not None:
                await asyncio.to_thread(close_session, app.state.session)

    app = Starlette(routes=[
        Route("/", _index),
        Route("/favicon.ico", _favicon),
        Route("/login", _login, methods=["GET", "POST"]),
        Route("/logout", _logout, methods=["POST"]),  # a link or an image cannot sign anyone out
        Route(ABOUT_PATH, _about),
        *drive.routes(),
        *rovers.routes(),
        *response.routes(),  # before api's /api/rovers/{rover}/{what}
        *session_notes.routes(),
        *api.routes(),
        *extras.routes(),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ], lifespan=lifespan)
    app.state.session = None  # until the twin is reached
    app.state.accounts = accounts
    app.state.sign_ins = SignIns(accounts) if accounts is not None else None
    app.state.attempts = Attempts()
    app.state.tls = tls
    app.state.catalogue = api.catalogue()
    app.state.traverses = drive.Traverses([drive.SHIPPED, *traverse_dirs])
    app.state.rover_files = rover_files or rovers.RoverFiles()
    app.state.session_notes = session_notes.SessionNotes(recordings_dir)
    app.state.extras = extras.Extras(
        None, scenarios_dir, recordings_dir, connection or [],
        live_rovers=lambda: [r for r in app.state.hub.mirror.rovers() if app.state.hub.mirror.services(r)])
    return Gate(app, accounts, app.state.sign_ins, set(hosts) if hosts is not None else set(LOCAL_NAMES))


def _connected(app: Starlette, session: zenoh.Session) -> None:
    """The twin reached: the hub mirrors it, the API and the scenarios write on it."""
    app.state.session = session
    app.state.extras.session = session
    app.state.hub.start(session)


async def _connect(app: Starlette, opener: Opener, stop: threading.Event,
                   give_up: Callable[[str], None] | None) -> None:
    """Open the session behind the running server, then start the hub on it."""
    try:
        session = await asyncio.to_thread(opener, stop)
    except ToolError as exc:
        if stop.is_set():
            return
        if give_up is not None:
            give_up(str(exc))
        else:
            print(f"lunaris console: {exc}", file=sys.stderr, flush=True)
        return
    if stop.is_set():
        await asyncio.to_thread(close_session, session)
        return
    _connected(app, session)
    print(f"Lunaris console: connected to the twin at {app.state.hub.endpoint}", flush=True)


async def _watch_accounts(app: Starlette) -> None:
    """A user removed (or made an observer) counts at once: their live streams are woken, look
    at their sign-in again, and end."""
    accounts: Accounts = app.state.accounts
    users = accounts.users()
    while True:
        await asyncio.sleep(ACCOUNTS_S)
        try:
            now = await asyncio.to_thread(accounts.users)
        except AccountsError:
            continue  # a file being written: the next look
        if now != users:
            users = now
            app.state.hub.wake()
