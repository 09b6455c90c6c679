"""The console's web server: Starlette on uvicorn, one Zenoh session, the sign-in gate.

Every request goes through :class:`Gate` (pure ASGI, so the live stream is not buffered):
without an accounts file every request is the local instructor's (the server listens on
loopback only, :mod:`lunaris.console`); with one, a request without a valid sign-in is sent
to ``/login`` (a page) or refused with 401 (the API), and a write whose ``Origin`` is another
site is refused with 403. The Zenoh session is opened before the server starts; the hub
subscribes in the lifespan, on the server's loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import mimetypes
import urllib.parse
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import zenoh
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from lunaris.console import api, extras
from lunaris.console.auth import COOKIE, LOCAL, SESSION_S, Accounts, SignIns
from lunaris.console.live import Hub

__all__ = ["STATIC", "make_app"]

STATIC = Path(__file__).resolve().parent / "static"
mimetypes.add_type("text/javascript", ".js")  # the page's ES modules (RFC 9239), whatever the OS's table says
# The page runs only its own scripts: a name that reached the document as markup could not run.
PAGE_POLICY = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
               "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
               "form-action 'self'; frame-ancestors 'none'")
PUBLIC = ("/login", "/static/app.css", "/favicon.ico")
WRITES = {"PUT", "POST", "DELETE", "PATCH"}


class Gate:
    """Who is asking: the local user, a signed-in user, or nobody (sign in first)."""

    def __init__(self, app: Any, accounts: Accounts | None, sign_ins: SignIns | None):
        self.app, self.accounts, self.sign_ins = app, accounts, sign_ins

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        scope.setdefault("state", {})
        path = scope["path"]
        headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope["headers"]}
        if scope["method"] in WRITES and "origin" in headers:
            host = urllib.parse.urlsplit(headers["origin"]).netloc
            if host != headers.get("host"):
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
    return nxt if nxt.startswith("/") and not nxt.startswith("//") else "/"


async def _login(request: Request) -> Response:
    accounts: Accounts | None = request.app.state.accounts
    if accounts is None:
        return RedirectResponse("/", status_code=303)
    if request.method == "GET":
        nxt = html.escape(_safe_next(request.query_params.get("next", "/")))
        return HTMLResponse(_LOGIN.format(error="", next=nxt))
    form = urllib.parse.parse_qs((await request.body()).decode("utf-8", "replace"))
    name, password = form.get("user", [""])[0], form.get("password", [""])[0]
    nxt = _safe_next(form.get("next", ["/"])[0])
    user = await asyncio.to_thread(accounts.check, name, password)
    if user is None:
        await asyncio.sleep(1.0)  # a guesser pays a second a try
        error = '<p class="error" role="alert">Wrong user or password.</p>'
        return HTMLResponse(_LOGIN.format(error=error, next=html.escape(nxt)), status_code=401)
    token = request.app.state.sign_ins.open(user)
    response = RedirectResponse(nxt, status_code=303)
    response.set_cookie(COOKIE, token, max_age=int(SESSION_S), httponly=True, samesite="strict",
                        secure=request.app.state.tls)
    return response


async def _logout(request: Request) -> Response:
    sign_ins: SignIns | None = request.app.state.sign_ins
    if sign_ins is not None:
        sign_ins.close(request.scope["state"].get("token"))
    response = RedirectResponse("/login" if sign_ins else "/", status_code=303)
    response.delete_cookie(COOKIE)
    return response


async def _favicon(request: Request) -> Response:
    return Response(status_code=204)


async def _index(request: Request) -> Response:
    return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store",
                                                        "Content-Security-Policy": PAGE_POLICY})


def make_app(session: zenoh.Session, accounts: Accounts | None, *, tls: bool = False,
             scenarios_dir: Path | None = None, recordings_dir: Path | None = None,
             connection: list[str] | None = None, flush_s: float = 0.05) -> Any:
    """The console as an ASGI application around an open Zenoh session."""

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        hub = Hub(asyncio.get_running_loop(), flush_s)
        hub.start(session)
        app.state.hub = hub
        watch = asyncio.create_task(_watch_link(hub, session))
        try:
            yield
        finally:
            watch.cancel()
            app.state.extras.close()
            hub.stop()

    app = Starlette(routes=[
        Route("/", _index),
        Route("/favicon.ico", _favicon),
        Route("/login", _login, methods=["GET", "POST"]),
        Route("/logout", _logout, methods=["GET", "POST"]),
        *api.routes(),
        *extras.routes(),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ], lifespan=lifespan)
    app.state.session = session
    app.state.accounts = accounts
    app.state.sign_ins = SignIns(accounts) if accounts is not None else None
    app.state.tls = tls
    app.state.catalogue = api.catalogue()
    app.state.extras = extras.Extras(session, scenarios_dir, recordings_dir, connection or [])
    return Gate(app, accounts, app.state.sign_ins)


async def _watch_link(hub: Hub, session: zenoh.Session) -> None:
    """Tell the pages whether the router is there (Zenoh reconnects by itself)."""
    while True:
        try:
            connected = bool(await asyncio.to_thread(lambda: list(session.info.routers_zid())))
        except zenoh.ZError:
            connected = False
        hub.set_connected(connected)
        await asyncio.sleep(1.0 if connected else 0.5)
