"""The study web app: the HTTP contract of docs/design.md over the database, the flow and the engine.

    app = create_app(StudyApp(db_path, engine, videos, admin_token))

`create_app` assembles three routers over one `StudyApp` (`state.py`): the pages (`pages.py`: `/`, `/study`,
`/admin`, `/static`, `/healthz`, `/api/info`), the participants (`participants.py`: `/api/participants...` with the
header `X-Participant-Token`, `/videos/NAME`) and the lab (`admin.py`: `/api/admin/...` with `Authorization: Bearer
TOKEN`). This module adds what every request goes through: the Host and cross-site checks, the security headers,
and errors as a 4xx `{"error": "one line"}` (bad input never stores anything).
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.datastructures import Headers, MutableHeaders
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from langpref.study.server.admin import admin_router
from langpref.study.server.guard import HttpError, cross_site
from langpref.study.server.pages import STATIC, page_router
from langpref.study.server.participants import participant_router
from langpref.study.server.state import StudyApp

__all__ = ["SECURITY_HEADERS", "RequestGuard", "StudyApp", "create_app"]

log = logging.getLogger("langpref.study")

SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; media-src 'self'; style-src 'self'; "
    "script-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
}
INTERNAL_ERROR = "internal error; nothing was stored, please retry"


def create_app(state: StudyApp) -> FastAPI:
    """The FastAPI application over `state`."""
    app = FastAPI(title="langpref study", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.study = state
    add_error_handlers(app)
    add_request_guard(app, state)
    app.include_router(page_router(state))
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    app.include_router(participant_router(state))
    app.include_router(admin_router(state))
    return app


def error(status: int, message: str) -> JSONResponse:
    """The one shape of every error answer."""
    return JSONResponse({"error": message}, status_code=status)


def add_error_handlers(app: FastAPI) -> None:
    """Every error as `{"error": "one line"}`: ours with their status and headers, the framework's 404/405 and
    validation errors in a word, anything unexpected as a logged 500."""

    @app.exception_handler(HttpError)
    async def _http_error(request: Request, exc: HttpError):
        response = error(exc.status, exc.message)
        response.headers.update(exc.headers or {})
        return response

    @app.exception_handler(StarletteHTTPException)
    async def _starlette_error(request: Request, exc: StarletteHTTPException):
        message = {404: "not found", 405: "method not allowed"}.get(exc.status_code, str(exc.detail))
        return error(exc.status_code, message)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError):
        return error(400, "bad request")

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return error(500, INTERNAL_ERROR)


def add_request_guard(app: FastAPI, state: StudyApp) -> None:
    """Before a request: refuse a Host the server does not answer to, and a cross-site write. After it: the security
    headers, `Cache-Control: no-store` on the API, and `Connection: close` once the server is stopping (a client
    that asks again at once would otherwise keep its connection, and the stop, going)."""
    app.add_middleware(RequestGuard, state=state)


class RequestGuard:
    """The checks and headers of `add_request_guard`, as a plain ASGI middleware: starlette's `BaseHTTPMiddleware`
    (`@app.middleware("http")`) spends a task group and two memory streams on every request, event-loop time that
    every answer waited for when 20 participants answered at once."""

    def __init__(self, app: ASGIApp, state: StudyApp):
        self.app = app
        self.state = state

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        api = scope["path"].startswith("/api/")  # not request.url: it caches every URL parsed
        started = False

        async def send_with_headers(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
                headers = MutableHeaders(scope=message)
                for key, value in SECURITY_HEADERS.items():
                    headers.setdefault(key, value)
                if api:
                    headers.setdefault("Cache-Control", "no-store")
                if self.state.stopping.is_set():  # the server is stopping: no next request on this connection
                    headers["Connection"] = "close"
            await send(message)

        refused = self._refused(scope)
        if refused:
            await refused(scope, receive, send_with_headers)
            return
        try:
            await self.app(scope, receive, send_with_headers)
        except Exception:  # answered here, so that the keep-alive connection stays up
            log.exception("unexpected error on %s %s", scope["method"], scope["path"][:200])
            if started:
                raise
            await error(500, INTERNAL_ERROR)(scope, receive, send_with_headers)

    def _refused(self, scope: Scope) -> JSONResponse | None:
        """The error answer to a Host the server does not answer to (400) or a cross-site write (403), else None."""
        headers = Headers(scope=scope)
        refused = self.state.hosts.refused(headers.get("host"))
        if refused:
            return error(400, refused)
        if scope["method"] not in ("GET", "HEAD", "OPTIONS"):
            refused = cross_site(headers, self.state.allowed_origins)
            if refused:
                return error(403, refused)
        return None
