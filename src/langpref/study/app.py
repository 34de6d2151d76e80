"""The study web app: the HTTP contract of DESIGN.md ("Study web app") over the database, the flow and the engine.

    app = create_app(StudyApp(db_path, engine, videos, admin_token))

Participant API: `POST /api/participants`, `GET /api/participants/ID/step`, `POST /api/participants/ID/answer`
(header `X-Participant-Token`). Videos: `GET /videos/NAME`. Admin (header `Authorization: Bearer TOKEN`):
`GET /api/admin/participants`, `GET /api/admin/export`, `GET /api/admin/status`. Pages: `/` (guidelines and
consent), `/study`, `/admin`. Every error is a 4xx `{"error": "one line"}`; bad input never stores anything.
"""

from __future__ import annotations

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
from langpref.study.flow import AnswerError, Participant, Step, advance, first_step, parse_answer, progress, questions
from langpref.study.hook import ShowHook
from langpref.study.surveys import METHOD_LABELS, SURVEY_TITLES, task_text
from langpref.study.videos import VideoCache

log = logging.getLogger("langpref.study")
HERE = Path(__file__).parent
MAX_BODY = 64 * 1024
TIME_TOLERANCE_MS = 1000.0
"""A client time per query may exceed the server's (step shown -> answer received) by this much (clock grain)."""
NOT_FEEDBACK = ("That does not read as feedback on how the robot moves. Please say how it should move differently, "
                "for example \"Move faster.\" or \"Stay lower.\"")


class HttpError(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def _decode(body: bytes, allow_empty: bool = False) -> Any:
    if len(body) > MAX_BODY:
        raise HttpError(413, f"the body is over {MAX_BODY // 1024} KiB")
    if allow_empty and not body.strip():
        return {}
    try:
        return json.loads(body)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise HttpError(400, f"the body is not valid JSON ({exc.__class__.__name__}: {str(exc)[:80]})") from None


class StudyApp:
    """Everything a request needs: the database path, the engine, the video cache, the admin token and the
    `--on-show` hook (told of every step handed out; it never blocks a request)."""

    def __init__(self, db_path: str | Path, engine: StudyEngine, videos: VideoCache, admin_token: str,
                 cfg: StudyConfig | None = None, hook: ShowHook | None = None):
        self.db_path = str(db_path)
        self.engine = engine
        self.cfg = cfg or engine.cfg
        self.videos = videos
        self.admin_token = admin_token
        self.hook = hook
        self.robot = StudyRobot(engine, self._history)
        self._locks: dict[str, threading.Lock] = {}
        self._locks_guard = threading.Lock()
        self._local = threading.local()

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

    def _lock(self, pid: str) -> threading.Lock:
        with self._locks_guard:
            return self._locks.setdefault(pid, threading.Lock())

    @staticmethod
    def _participant(row) -> Participant:
        return Participant(row["id"], int(row["number"]), tuple(row["method_order"].split(",")), int(row["seed"]))

    def _auth(self, conn, pid: str, token: str | None) -> Participant:
        if not isinstance(pid, str) or len(pid) > 64:
            raise HttpError(404, "unknown participant")
        row = conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone()
        if row is None:
            raise HttpError(404, "unknown participant")
        if not token:
            raise HttpError(401, "missing X-Participant-Token header")
        if not hmac.compare_digest(_sha256(token), row["token_sha256"]):
            raise HttpError(403, "this token does not belong to this participant")
        return self._participant(row)

    @staticmethod
    def _current(conn, pid: str) -> tuple[Step, dict]:
        row = conn.execute("SELECT * FROM steps WHERE participant_id=? ORDER BY seq DESC LIMIT 1", (pid,)).fetchone()
        if row is None:
            raise HttpError(409, "this participant has no step (the database was edited?)")
        return Step.from_row(dict(row)), dict(row)

    # ---- JSON of a step ----

    def step_json(self, step: Step) -> dict[str, Any]:
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
        return out

    # ---- participant endpoints ----

    def create_participant(self, body: bytes, user_agent: str | None) -> dict[str, Any]:
        data = _decode(body, allow_empty=True)
        if not isinstance(data, dict):
            raise HttpError(400, "the body must be a JSON object ({})")
        pid, token = secrets.token_hex(16), secrets.token_urlsafe(32)
        now = time.time()
        conn = self.connect()
        with sdb.transaction(conn):
            number = conn.execute("SELECT coalesce(max(number), 0) + 1 FROM participants").fetchone()[0]
            # counterbalancing: odd arrivals start Study 2 with language, even ones with comparisons
            order = METHODS if number % 2 == 1 else tuple(reversed(METHODS))
            conn.execute("INSERT INTO participants (id, token_sha256, number, method_order, seed, created_at, "
                         "user_agent) VALUES (?, ?, ?, ?, ?, ?, ?)",
                         (pid, _sha256(token), number, ",".join(order), number, now, (user_agent or "")[:300]))
            step = first_step()
            conn.execute("INSERT INTO steps (participant_id, seq, phase, kind, payload, created_at) "
                         "VALUES (?, ?, ?, ?, ?, ?)", (pid, step.seq, step.phase, step.kind, step.payload(), now))
        return {"participant_id": pid, "token": token}

    def get_step(self, pid: str, token: str | None) -> dict[str, Any]:
        conn = self.connect()
        self._auth(conn, pid, token)
        step, row = self._current(conn, pid)
        if row["first_shown_at"] is None:
            conn.execute("UPDATE steps SET first_shown_at=? WHERE participant_id=? AND seq=? AND "
                         "first_shown_at IS NULL", (time.time(), pid, step.seq))
        if self.hook is not None:
            self.hook.show(pid, step.seq, step.kind, step.shown)
        return self.step_json(step)

    def answer(self, pid: str, token: str | None, body: bytes) -> dict[str, Any]:
        with self._lock(pid):
            conn = self.connect()
            p = self._auth(conn, pid, token)
            step, row = self._current(conn, pid)
            data = _decode(body)
            try:
                ans = parse_answer(data, step)
            except AnswerError as exc:
                raise HttpError(exc.status, str(exc)) from None
            if ans.kind == "language" and not self.engine.gate.score(ans.value.text).ok:
                raise HttpError(400, NOT_FEEDBACK)
            received = time.time()
            try:
                tr = advance(self.cfg, p, step, ans, self.robot)
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
            if self.hook is not None:
                self.hook.show(pid, tr.next.seq, tr.next.kind, tr.next.shown)
            return self.step_json(tr.next)

    def _store(self, conn, p: Participant, step: Step, row: dict, ans, data: dict, tr, received: float) -> None:
        shown_at = row["first_shown_at"] or row["created_at"]
        server_ms = max(0.0, (received - shown_at) * 1000.0)
        consistent = None if ans.client_ms is None else int(ans.client_ms <= server_ms + TIME_TOLERANCE_MS)
        now = time.time()
        with sdb.transaction(conn):
            cur = conn.execute("SELECT max(seq) FROM steps WHERE participant_id=?", (p.id,)).fetchone()[0]
            if cur != step.seq:
                raise HttpError(409, "this step was answered meanwhile; GET the current step")
            conn.execute("INSERT INTO answers (participant_id, seq, phase, kind, body, client_ms, server_ms, "
                         "time_consistent, answered_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                         (p.id, step.seq, step.phase, step.kind, json.dumps(data), ans.client_ms, server_ms,
                          consistent, now))
            for table, record in tr.records:
                record = {"participant_id": p.id, "seq": step.seq, **record, "answered_at": now}
                if table in ("feedback", "comparisons"):
                    record["server_ms"] = server_ms
                if table == "survey_responses":
                    record.pop("seq")
                cols = ", ".join(record)
                conn.execute(f"INSERT INTO {table} ({cols}) VALUES ({', '.join('?' * len(record))})",
                             tuple(record.values()))
            conn.execute("UPDATE steps SET answered_at=? WHERE participant_id=? AND seq=?", (now, p.id, step.seq))
            nxt = tr.next
            conn.execute("INSERT INTO steps (participant_id, seq, phase, kind, payload, created_at, first_shown_at) "
                         "VALUES (?, ?, ?, ?, ?, ?, ?)", (p.id, nxt.seq, nxt.phase, nxt.kind, nxt.payload(), now, now))
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
            feedback = [dict(r) for r in conn.execute(
                "SELECT phase, number, text, understood_feature, understood_direction FROM feedback "
                "WHERE participant_id=? ORDER BY seq DESC LIMIT 5", (p["id"],))]
            out.append({"participant_id": p["id"], "number": p["number"], "method_order": p["method_order"],
                        "created_at": p["created_at"], "finished_at": p["finished_at"], "phase": step.phase,
                        "kind": step.kind, "progress": progress(self.cfg, step), "answers": n_answers,
                        "recent_feedback": feedback})
        return {"participants": out, "videos": self.videos.progress(), "study": self.cfg.to_dict(),
                "hooks": self.hook.status() if self.hook else None}

    def admin_export(self) -> dict[str, Any]:
        from langpref.study.export import analyse, read_tables

        conn = self.connect()
        tables = read_tables(conn)
        return {"meta": sdb.read_meta(conn), "tables": tables, "analysis": analyse(tables)}

    # ---- pages ----

    def page(self, name: str) -> str:
        task = task_text(self.engine.env)
        c = self.cfg
        values = {
            "ROBOT": task["robot"], "TASK": task["task"],
            "EXAMPLES": ", ".join(f"\u201c{e}\u201d" for e in task["examples"]),
            "IMPROVE_MAX": str(c.improve_max_iterations), "PREF_QUERIES": str(c.pref_queries),
            "RATING_EVERY": str(c.rating_every), "LANGUAGE": METHOD_LABELS["language"],
            "COMPARISON": METHOD_LABELS["comparison"],
        }
        text = (HERE / "templates" / name).read_text()
        for key, value in values.items():
            text = text.replace("{{" + key + "}}", html.escape(value))
        return text


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
        return error(exc.status, exc.message)

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
        response = await call_next(request)
        for key, value in SECURITY_HEADERS.items():
            response.headers.setdefault(key, value)
        if request.url.path.startswith("/api/"):
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
        return {"env": state.engine.env, "task": task, "study": state.cfg.to_dict(),
                "methods": {m: METHOD_LABELS[m] for m in METHODS}}

    # participants
    @app.post("/api/participants")
    async def new_participant(request: Request):
        body = await request.body()
        return await run_in_threadpool(state.create_participant, body, request.headers.get("user-agent"))

    @app.get("/api/participants/{pid}/step")
    def get_step(pid: str, request: Request):
        return state.get_step(pid, request.headers.get("x-participant-token"))

    @app.post("/api/participants/{pid}/answer")
    async def post_answer(pid: str, request: Request):
        body = await request.body()
        return await run_in_threadpool(state.answer, pid, request.headers.get("x-participant-token"), body)

    # videos
    @app.get("/videos/{name:path}")
    def video(name: str):
        index = state.videos.index_of(name)
        if index is None:
            raise HttpError(404, "no such video")
        try:
            path = state.videos.ensure(index)
        except LangprefError as exc:
            raise HttpError(503, str(exc)) from None
        return FileResponse(path, media_type=state.videos.media_type,
                            headers={"Cache-Control": "public, max-age=86400, immutable"})

    # admin
    @app.get("/api/admin/participants")
    def admin_participants(request: Request):
        state.check_admin(request.headers.get("authorization"))
        return state.admin_participants()

    @app.get("/api/admin/export")
    def admin_export(request: Request):
        state.check_admin(request.headers.get("authorization"))
        return state.admin_export()

    @app.get("/api/admin/status")
    def admin_status(request: Request):
        state.check_admin(request.headers.get("authorization"))
        conn = state.connect()
        counts = {t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in sdb.TABLES}
        return {"videos": state.videos.progress(), "rows": counts, "engine": state.engine.describe(),
                "hooks": state.hook.status() if state.hook else None}

    return app
