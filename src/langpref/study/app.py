"""The study web app: the HTTP contract of DESIGN.md ("Study web app") over the database, the flow and the engine.

    app = create_app(StudyApp(db_path, engine, videos, admin_token))

Participant API: `POST /api/participants`, `GET /api/participants/ID/step`, `POST /api/participants/ID/answer`
(header `X-Participant-Token`). Videos: `GET /videos/NAME`. Admin (header `Authorization: Bearer TOKEN`):
`GET /api/admin/participants`, `GET /api/admin/export`, `GET /api/admin/status`. Pages: `/` (guidelines and
consent), `/study`, `/admin`. Every error is a 4xx `{"error": "one line"}`; bad input never stores anything.
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import html
import json
import logging
import secrets
import threading
import time
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

from langpref.errors import LangprefError
from langpref.study import db as sdb
from langpref.study.config import METHODS, StudyConfig
from langpref.study.engine import StudyEngine, StudyRobot
from langpref.study.flow import (
    AnswerError,
    Confirmed,
    Participant,
    Step,
    advance,
    clean_text,
    first_step,
    parse_answer,
    progress,
    questions,
)
from langpref.study.generated import Generator, NotReady
from langpref.study.guard import HostCheck, HttpError, RateLimiter, client_key, cross_site, decode_json, read_body
from langpref.study.hook import ShowHook
from langpref.study.surveys import METHOD_LABELS, SURVEY_TITLES, task_text
from langpref.study.videos import VideoCache

log = logging.getLogger("langpref.study")
HERE = Path(__file__).parent
TIME_TOLERANCE_MS = 1000.0
"""A client time per query may exceed the server's (step shown -> answer received) by this much (clock grain)."""
NOT_FEEDBACK = (
    "That does not read as feedback on how the robot moves. Please say how it should move differently, "
    'for example "Move faster." or "Stay lower."'
)


VIDEO_WAIT_S = 2.0
"""A request for a video that is being made waits this long (asynchronously: no server thread is held) before it is
answered 503 with Retry-After; the page retries and shows its progress meanwhile."""
MAX_VIDEO_WAITERS = 32
"""Requests waiting for a video at once; beyond that they are answered 503 with Retry-After at once."""
VIDEO_RETRY_S = 2
LOCK_STRIPES = 64
MAX_RESUME_FAILURES = 20
"""Wrong resume codes taken per minute from one client (an address; IPv6 by its /64), then 429 for that client only:
about 2^50 codes cannot be tried, and no client can lock resume for the others."""
MAX_RESUMES_PER_CODE = 10
"""Sessions restored per minute with one resume code (each adds a token), then 429 for that code."""


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


class StudyApp:
    """Everything a request needs: the database path, the engine, the video cache, the admin token, the
    `--on-show` hook (told of every step handed out; it never blocks a request) and Study 1's generated candidates
    (`--improve-candidates generated`)."""

    def __init__(
        self,
        db_path: str | Path,
        engine: StudyEngine,
        videos: VideoCache,
        admin_token: str,
        cfg: StudyConfig | None = None,
        hook: ShowHook | None = None,
        allowed_origins: tuple[str, ...] = (),
        generated: Generator | None = None,
        allowed_hosts: tuple[str, ...] = (),
        bind_host: str | None = None,
    ):
        self.db_path = str(db_path)
        self.engine = engine
        self.cfg = cfg or engine.cfg
        self.videos = videos
        self.admin_token = admin_token
        self.hook = hook
        self.generated = generated
        self.robot = StudyRobot(
            engine, self._history, cfg=self.cfg, generated=generated, confirmations=self._confirmations
        )
        # answers of one participant run one at a time; a fixed set of locks (by hash of the id, taken only after
        # the token is checked) keeps memory bounded whatever ids unauthenticated requests send
        self._locks = [threading.Lock() for _ in range(LOCK_STRIPES)]
        self._resume_failures = RateLimiter(MAX_RESUME_FAILURES)
        self._resumes = RateLimiter(MAX_RESUMES_PER_CODE)
        self._local = threading.local()
        self.video_waiters = 0  # changed only on the event loop
        self.allowed_origins = {o.rstrip("/").lower() for o in allowed_origins}
        self.hosts = HostCheck(allowed_hosts, bind_host, self.allowed_origins)

    # ---- database helpers ----

    def connect(self):
        """This thread's connection, kept open: closing the last connection of a WAL database checkpoints it
        (an fsync per request)."""
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._local.conn = sdb.connect(self.db_path)
        return conn

    def _history(self, pid: str, method: str) -> list[Any]:
        """The participant's stored Study-2 answers of `method`, in order, as its feedback kind's answers."""
        return sdb.stored_answers(self.connect(), pid, method)

    def _confirmations(self, pid: str, method: str) -> dict[int, Confirmed]:
        """What the participant confirmed their Study-2 answers of `method` meant, by query number."""
        return {n: Confirmed(m) for n, m in sdb.confirmed_meanings(self.connect(), pid, method).items()}

    def _lock(self, pid: str) -> threading.Lock:
        return self._locks[int(_sha256(pid)[:8], 16) % LOCK_STRIPES]

    @staticmethod
    def _participant(row) -> Participant:
        return Participant(row["id"], int(row["number"]), tuple(row["method_order"].split(",")), int(row["seed"]))

    def _auth(self, conn, pid: str, token: str | None) -> tuple[Participant, Any]:
        """The participant `pid` if `token` is one of theirs (the first, or one issued on resume), and its row."""
        if not isinstance(pid, str) or len(pid) > 64:
            raise HttpError(404, "unknown participant")
        row = conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone()
        if row is None:
            raise HttpError(404, "unknown participant")
        if not token:
            raise HttpError(401, "missing X-Participant-Token header")
        digest = _sha256(token)
        if (
            not hmac.compare_digest(digest, row["token_sha256"])
            and conn.execute(
                "SELECT 1 FROM participant_tokens WHERE participant_id=? AND token_sha256=?", (pid, digest)
            ).fetchone()
            is None
        ):
            raise HttpError(403, "this token does not belong to this participant")
        return self._participant(row), row

    @staticmethod
    def _current(conn, pid: str) -> tuple[Step, dict]:
        row = conn.execute("SELECT * FROM steps WHERE participant_id=? ORDER BY seq DESC LIMIT 1", (pid,)).fetchone()
        if row is None:
            raise HttpError(409, "this participant has no step (the database was edited?)")
        return Step.from_row(dict(row)), dict(row)

    # ---- JSON of a step ----

    def step_json(self, step: Step, resume_code: str | None = None, p: Participant | None = None) -> dict[str, Any]:
        out = {
            "phase": step.phase,
            "kind": step.kind,
            "videos": [self.videos.url(i) for i in step.shown],
            "questions": questions(step),
            "progress": progress(self.cfg, step),
            "seq": step.seq,
            "number": step.number,
            "method": step.method,
            "survey": step.survey,
        }
        if step.survey:
            out["title"] = SURVEY_TITLES[step.survey]
        out.update(step.extra)
        if "previous" in step.extra:
            out["previous_video"] = self.videos.url(int(step.extra["previous"]))
        if resume_code:
            out["resume_code"] = resume_code
        if p is not None and step.method:
            out["method_position"] = p.method_order.index(step.method) + 1  # the page's introduction of a method
        if step.phase == "improve":
            out["last_round"] = step.number >= self.cfg.improve_max_iterations
        return out

    # ---- participant endpoints ----

    def create_participant(self, body: bytes) -> dict[str, Any]:
        """A new participant; nothing about the browser or the person is stored (no User-Agent, no address)."""
        data = decode_json(body, allow_empty=True)
        if not isinstance(data, dict):
            raise HttpError(400, "the body must be a JSON object ({})")
        pid, token = secrets.token_hex(16), secrets.token_urlsafe(32)
        now = time.time()
        conn = self.connect()
        with sdb.transaction(conn):
            number = conn.execute("SELECT coalesce(max(number), 0) + 1 FROM participants").fetchone()[0]
            # counterbalancing: odd arrivals start Study 2 with language, even ones with comparisons
            order = METHODS if number % 2 == 1 else tuple(reversed(METHODS))
            conn.execute(
                "INSERT INTO participants (id, token_sha256, number, method_order, seed, created_at, "
                "resume_code) VALUES (?, ?, ?, ?, ?, ?, ?)",
                (pid, _sha256(token), number, ",".join(order), number, now, sdb.new_resume_code(conn)),
            )
            step = first_step()
            conn.execute(
                "INSERT INTO steps (participant_id, seq, phase, kind, payload, created_at) VALUES (?, ?, ?, ?, ?, ?)",
                (pid, step.seq, step.phase, step.kind, step.payload(), now),
            )
        return {"participant_id": pid, "token": token}

    def resume(self, body: bytes, client: str | None = None) -> dict[str, Any]:
        """`{"code": "XXXXX-XXXXX"}` -> a new token of the participant with that resume code (their other tokens
        keep working). Wrong codes are limited per client (`client`: its address), so codes cannot be guessed by
        trying and one client's wrong codes never block another's right one."""
        data = decode_json(body)
        code = (
            sdb.normalise_resume_code(data.get("code", ""))
            if isinstance(data, dict) and isinstance(data.get("code"), str)
            else None
        )
        who = client_key(client)
        if self._resume_failures.blocked(who):
            raise HttpError(429, "too many wrong resume codes; wait a minute and try again", {"Retry-After": "60"})
        conn = self.connect()
        row = conn.execute("SELECT id FROM participants WHERE resume_code=?", (code,)).fetchone() if code else None
        if row is None:
            self._resume_failures.add(who)
            raise HttpError(404, "no participant has this resume code; check it (it looks like ABCDE-FGH23)")
        if self._resumes.blocked(code):
            raise HttpError(429, "this resume code was used many times just now; wait a minute", {"Retry-After": "60"})
        self._resumes.add(code)
        now = time.time()
        token = secrets.token_urlsafe(32)
        with sdb.transaction(conn):
            conn.execute(
                "INSERT INTO participant_tokens (participant_id, token_sha256, created_at) VALUES (?, ?, ?)",
                (row["id"], _sha256(token), now),
            )
        return {"participant_id": row["id"], "token": token}

    def get_step(self, pid: str, token: str | None) -> dict[str, Any]:
        conn = self.connect()
        p, prow = self._auth(conn, pid, token)
        step, row = self._current(conn, pid)
        if row["first_shown_at"] is None:
            conn.execute(
                "UPDATE steps SET first_shown_at=? WHERE participant_id=? AND seq=? AND first_shown_at IS NULL",
                (time.time(), pid, step.seq),
            )
        self._show(pid, step)
        return self.step_json(step, prow["resume_code"], p)

    def answer(self, pid: str, token: str | None, body: bytes) -> dict[str, Any]:
        conn = self.connect()
        p, prow = self._auth(conn, pid, token)  # before the lock: unknown ids never reach it
        with self._lock(pid):
            step, row = self._current(conn, pid)
            data = decode_json(body)
            try:
                ans = parse_answer(data, step)
            except AnswerError as exc:
                raise HttpError(exc.status, str(exc)) from None
            if ans.kind == "language" and not self.engine.gate.score(ans.value.text).ok:
                raise HttpError(400, NOT_FEEDBACK)
            if self.generated is not None and step.phase == "improve":
                try:
                    for index in step.shown:  # an answer about a trajectory still being made is not taken yet
                        self.generated.phi(index)
                except NotReady as exc:
                    raise HttpError(503, str(exc), {"Retry-After": str(VIDEO_RETRY_S)}) from None
            received = time.time()
            try:
                tr = advance(self.cfg, p, step, ans, self.robot)
            except NotReady as exc:
                self.robot.forget(pid)
                raise HttpError(503, str(exc), {"Retry-After": str(VIDEO_RETRY_S)}) from None
            except LangprefError as exc:
                self.robot.forget(pid)
                raise HttpError(400, str(exc)) from None
            except BaseException:
                self.robot.forget(pid)
                raise
            try:
                self._store(conn, p, step, row, ans, data, tr, received)
            except BaseException:
                self.robot.forget(pid)
                raise
            if self.generated is not None:
                self.generated.after_answer(p, step.seq, tr.records)
            self._show(pid, tr.next)
            return self.step_json(tr.next, prow["resume_code"], p)

    def _show(self, pid: str, step: Step) -> None:
        """Tell the `--on-show` hook of a step handed out (it runs for a generated trajectory once it is made)."""
        if self.hook is not None:
            self.hook.show(pid, step.seq, step.kind, step.shown)

    def _store(self, conn, p: Participant, step: Step, row: dict, ans, data: dict, tr, received: float) -> None:
        shown_at = row["first_shown_at"] or row["created_at"]
        server_ms = max(0.0, (received - shown_at) * 1000.0)
        consistent = None if ans.client_ms is None else int(ans.client_ms <= server_ms + TIME_TOLERANCE_MS)
        now = time.time()
        with sdb.transaction(conn):
            cur = conn.execute("SELECT max(seq) FROM steps WHERE participant_id=?", (p.id,)).fetchone()[0]
            if cur != step.seq:
                raise HttpError(409, "this step was answered meanwhile; GET the current step")
            conn.execute(
                "INSERT INTO answers (participant_id, seq, phase, kind, body, client_ms, server_ms, "
                "time_consistent, answered_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    p.id,
                    step.seq,
                    step.phase,
                    step.kind,
                    json.dumps(ans.body),
                    ans.client_ms,
                    server_ms,
                    consistent,
                    now,
                ),
            )
            for table, record in tr.records:
                record = {"participant_id": p.id, "seq": step.seq, **record, "answered_at": now}
                if table in ("feedback", "comparisons"):
                    record["server_ms"] = server_ms
                if table == "survey_responses":
                    record.pop("seq")
                cols = ", ".join(record)
                conn.execute(
                    f"INSERT INTO {table} ({cols}) VALUES ({', '.join('?' * len(record))})", tuple(record.values())
                )
            conn.execute("UPDATE steps SET answered_at=? WHERE participant_id=? AND seq=?", (now, p.id, step.seq))
            nxt = tr.next
            conn.execute(
                "INSERT INTO steps (participant_id, seq, phase, kind, payload, created_at, first_shown_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                (p.id, nxt.seq, nxt.phase, nxt.kind, nxt.payload(), now, now),
            )
            if nxt.selection is not None:
                sdb.add_query(conn, p.id, nxt, now)
            if nxt.phase == "done":
                conn.execute("UPDATE participants SET finished_at=? WHERE id=?", (now, p.id))

    # ---- admin ----

    def check_admin(self, header: str | None) -> None:
        if not header:
            raise HttpError(401, "missing Authorization: Bearer ADMIN_TOKEN header")
        scheme, _, value = header.partition(" ")
        if scheme.lower() != "bearer" or not hmac.compare_digest(value.strip().encode(), self.admin_token.encode()):
            raise HttpError(403, "wrong admin token")

    def admin_participants(self) -> dict[str, Any]:
        conn = self.connect()
        out = []
        for p in conn.execute("SELECT * FROM participants ORDER BY number").fetchall():
            step, _ = self._current(conn, p["id"])
            n_answers = conn.execute("SELECT count(*) FROM answers WHERE participant_id=?", (p["id"],)).fetchone()[0]
            feedback = [
                dict(r)
                for r in conn.execute(
                    "SELECT phase, number, text, understood_feature, understood_direction FROM feedback "
                    "WHERE participant_id=? ORDER BY seq DESC LIMIT 5",
                    (p["id"],),
                )
            ]
            out.append(
                {
                    "participant_id": p["id"],
                    "number": p["number"],
                    "resume_code": p["resume_code"],
                    "excluded": bool(p["excluded"]),
                    "excluded_reason": p["excluded_reason"],
                    "method_order": p["method_order"],
                    "created_at": p["created_at"],
                    "finished_at": p["finished_at"],
                    "phase": step.phase,
                    "kind": step.kind,
                    "progress": progress(self.cfg, step),
                    "answers": n_answers,
                    "recent_feedback": feedback,
                }
            )
        return {
            "participants": out,
            "videos": self.videos.progress(),
            "study": self.cfg.to_dict(),
            "hooks": self.hook.status() if self.hook else None,
        }

    def set_excluded(self, pid: str, body: bytes) -> dict[str, Any]:
        """`{"excluded": true|false, "reason": "..."}`: leave a participant out of the analyses (or back in)."""
        data = decode_json(body)
        if not isinstance(data, dict) or not isinstance(data.get("excluded"), bool):
            raise HttpError(400, 'send {"excluded": true or false, "reason": "why (optional)"}')
        try:
            reason = clean_text(data.get("reason") or "")
        except AnswerError as exc:
            raise HttpError(400, str(exc)) from None
        if not isinstance(reason, str) or len(reason) > 300:
            raise HttpError(400, "'reason' must be a text of at most 300 characters")
        conn = self.connect()
        with sdb.transaction(conn):
            n = conn.execute(
                "UPDATE participants SET excluded=?, excluded_reason=? WHERE id=?",
                (int(data["excluded"]), reason.strip() or None if data["excluded"] else None, pid),
            ).rowcount
        if not n:
            raise HttpError(404, "unknown participant")
        return {"participant_id": pid, "excluded": data["excluded"]}

    def admin_export(self) -> dict[str, Any]:
        from langpref.study.export import analyse, read_tables, resolve_exclusions
        from langpref.study.learned import learned_rewards

        conn = self.connect()
        tables = read_tables(conn)
        return {
            "meta": sdb.read_meta(conn),
            "tables": tables,
            "analysis": analyse(tables),
            "learned_rewards": learned_rewards(tables, resolve_exclusions(tables["participants"])),
        }

    # ---- pages ----

    def page(self, name: str) -> str:
        task = task_text(self.engine.env)
        c = self.cfg
        values = {
            "ROBOT": task["robot"],
            "TASK": task["task"],
            "EXAMPLES": ", ".join(f"\u201c{e}\u201d" for e in task["examples"]),
            "IMPROVE_MAX": str(c.improve_max_iterations),
            "PREF_QUERIES": str(c.pref_queries),
            "RATING_EVERY": str(c.rating_every),
            "LANGUAGE": METHOD_LABELS["language"],
            "COMPARISON": METHOD_LABELS["comparison"],
            "DURATION": duration_text(c),
        }
        text = (HERE / "templates" / name).read_text()
        for key, value in values.items():
            text = text.replace("{{" + key + "}}", html.escape(value))
        return text


def duration_text(c: StudyConfig) -> str:
    """How long the study takes, from its protocol, for the guidelines ("30 to 45 minutes" for the paper's): surveys
    8-10 minutes in all, a Study-1 round 40-60 s (most people are satisfied within 3), a language query 30-40 s, a
    comparison 20-25 s, a rating 10-15 s."""
    ratings = 2 * len(c.rating_points())
    lo = 8 * 60 + 40 * min(c.improve_max_iterations, 3) + c.pref_queries * (30 + 20) + ratings * 10
    hi = 10 * 60 + 60 * c.improve_max_iterations + c.pref_queries * (40 + 25) + ratings * 15
    lo_min = max(5, 5 * round(lo / 300))
    return f"{lo_min} to {max(5 * round(hi / 300), lo_min + 5)} minutes"


SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; media-src 'self'; style-src 'self'; "
    "script-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
}


def create_app(state: StudyApp) -> FastAPI:
    """The FastAPI application over `state`."""
    app = FastAPI(title="langpref study", docs_url=None, redoc_url=None, openapi_url=None)
    app.state.study = state

    def error(status: int, message: str) -> JSONResponse:
        return JSONResponse({"error": message}, status_code=status)

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
        return error(500, "internal error; nothing was stored, please retry")

    @app.middleware("http")
    async def _headers(request: Request, call_next):
        refused = state.hosts.refused(request.headers.get("host"))
        if refused:
            return error(400, refused)
        if request.method not in ("GET", "HEAD", "OPTIONS"):
            refused = cross_site(request.headers, state.allowed_origins)
            if refused:
                return error(403, refused)
        try:
            response = await call_next(request)
        except Exception:  # answered here, so that the keep-alive connection stays up
            log.exception("unexpected error on %s %s", request.method, request.scope["path"][:200])
            response = error(500, "internal error; nothing was stored, please retry")
        for key, value in SECURITY_HEADERS.items():
            response.headers.setdefault(key, value)
        if request.scope["path"].startswith("/api/"):  # not request.url: it caches every URL parsed
            response.headers.setdefault("Cache-Control", "no-store")
        return response

    # pages
    def page_route(template: str):
        def _page() -> HTMLResponse:  # no parameters: nothing from the request chooses the file
            return HTMLResponse(state.page(template), headers={"Cache-Control": "no-store"})

        return _page

    for route, template in (("/", "index.html"), ("/study", "study.html"), ("/admin", "admin.html")):
        app.add_api_route(route, page_route(template), methods=["GET"], include_in_schema=False)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")

    @app.get("/healthz")
    def healthz():
        return {"ok": True}

    @app.get("/api/info")
    def info():
        task = task_text(state.engine.env)
        return {
            "env": state.engine.env,
            "task": task,
            "study": state.cfg.to_dict(),
            "methods": {m: METHOD_LABELS[m] for m in METHODS},
        }

    # participants
    @app.post("/api/participants")
    async def new_participant(request: Request):
        body = await read_body(request)
        return await run_in_threadpool(state.create_participant, body)

    @app.post("/api/participants/resume")
    async def resume(request: Request):
        body = await read_body(request)
        return await run_in_threadpool(state.resume, body, request.client.host if request.client else None)

    @app.get("/api/participants/{pid}/step")
    def get_step(pid: str, request: Request):
        return state.get_step(pid, request.headers.get("x-participant-token"))

    @app.post("/api/participants/{pid}/answer")
    async def post_answer(pid: str, request: Request):
        body = await read_body(request)
        return await run_in_threadpool(state.answer, pid, request.headers.get("x-participant-token"), body)

    # videos
    @app.get("/videos/{name:path}")
    async def video(request: Request):
        # async and never blocking: a video that is not made yet holds no worker thread (issue: 80 such requests
        # froze every other endpoint); it waits here a little, then the client is told to come back. The name is
        # read from the path itself: the route's pattern ends in `$`, which lets a trailing newline through
        index = state.videos.index_of(request.scope["path"].removeprefix("/videos/"))
        if index is None:
            raise HttpError(404, "no such video")
        status, info = state.videos.request(index)
        if status in ("pending", "generating") and state.video_waiters < MAX_VIDEO_WAITERS:
            state.video_waiters += 1
            try:
                loop = asyncio.get_running_loop()
                deadline = loop.time() + VIDEO_WAIT_S
                while status in ("pending", "generating") and loop.time() < deadline:
                    await asyncio.sleep(0.05)
                    status, info = state.videos.request(index)
            finally:
                state.video_waiters -= 1
        if status == "ready":
            return FileResponse(
                info, media_type=state.videos.media_type, headers={"Cache-Control": "public, max-age=86400, immutable"}
            )
        retry = {"Retry-After": str(VIDEO_RETRY_S), "Cache-Control": "no-store"}
        if status == "failed":
            raise HttpError(503, f"the video could not be made ({info}); it is being tried again", retry)
        if status == "generating":
            raise HttpError(
                503,
                f"the robot is making a new trajectory in the simulator ({info} ahead of it); "
                f"retry in {VIDEO_RETRY_S} s",
                retry,
            )
        raise HttpError(503, f"the video is being made ({info} ahead of it); retry in {VIDEO_RETRY_S} s", retry)

    # admin
    @app.get("/api/admin/participants")
    def admin_participants(request: Request):
        state.check_admin(request.headers.get("authorization"))
        return state.admin_participants()

    @app.post("/api/admin/participants/{pid}/exclude")
    async def admin_exclude(pid: str, request: Request):
        state.check_admin(request.headers.get("authorization"))
        body = await read_body(request)
        return await run_in_threadpool(state.set_excluded, pid, body)

    @app.get("/api/admin/export")
    def admin_export(request: Request):
        state.check_admin(request.headers.get("authorization"))
        return state.admin_export()

    @app.get("/api/admin/status")
    def admin_status(request: Request):
        state.check_admin(request.headers.get("authorization"))
        conn = state.connect()
        counts = {t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in sdb.TABLES}
        return {
            "videos": state.videos.progress(),
            "rows": counts,
            "engine": state.engine.describe(),
            "hooks": state.hook.status() if state.hook else None,
            "generated": state.generated.progress() if state.generated else None,
        }

    return app
