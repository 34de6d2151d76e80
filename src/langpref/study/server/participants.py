"""The participants' side of the HTTP contract (docs/design.md): joining, resuming, the current step,
answers, and the videos the steps show.

`POST /api/participants`, `POST /api/participants/resume`, `GET /api/participants/ID/step`,
`POST /api/participants/ID/answer` (header `X-Participant-Token`), `GET /videos/NAME`. Every error is an `HttpError`
(a 4xx or 503 `{"error": "one line"}`); bad input never stores anything.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import secrets
import time
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind
from langpref.study.protocol import db as sdb
from langpref.study.protocol.flow import (
    AnswerError,
    Participant,
    Step,
    advance,
    first_step,
    parse_answer,
    progress,
    questions,
)
from langpref.study.protocol.kinds import asks_feedback, label, method_order, said, widget
from langpref.study.protocol.surveys import SURVEY_TITLES
from langpref.study.server.guard import HttpError, client_key, decode_json, read_body
from langpref.study.server.state import StudyApp, sha256
from langpref.study.session.generated import NotReady

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


def participant_router(state: StudyApp) -> APIRouter:
    """The participants' endpoints over `state`. Those that write run in the thread pool after their body is read."""
    router = APIRouter()

    @router.post("/api/participants")
    async def new_participant(request: Request):
        body = await read_body(request)
        return await run_in_threadpool(create_participant, state, body, _client(state, request))

    @router.post("/api/participants/resume")
    async def resume_session(request: Request):
        body = await read_body(request)
        return await run_in_threadpool(resume, state, body, _client(state, request))

    @router.get("/api/participants/{pid}/step")
    def current(pid: str, request: Request):
        return get_step(state, pid, request.headers.get("x-participant-token"))

    @router.post("/api/participants/{pid}/answer")
    async def post_answer(pid: str, request: Request):
        body = await read_body(request)
        return await run_in_threadpool(answer, state, pid, request.headers.get("x-participant-token"), body)

    @router.get("/videos/{name:path}")
    async def video_file(request: Request):
        return await video(state, request)

    return router


def _client(state: StudyApp, request: Request) -> str | None:
    """The address a request comes from: the connection's, or where a named proxy says it comes from."""
    peer = request.client.host if request.client else None
    return state.proxies.client(peer, request.headers.getlist("x-forwarded-for"))


def authenticate(state: StudyApp, conn, pid: str, token: str | None) -> tuple[Participant, Any]:
    """The participant `pid` if `token` is one of theirs (the first, or one issued on resume), and its row."""
    if not isinstance(pid, str) or len(pid) > 64:
        raise HttpError(404, "unknown participant")
    row = conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone()
    if row is None:
        raise HttpError(404, "unknown participant")
    if not token:
        raise HttpError(401, "missing X-Participant-Token header")
    digest = sha256(token)
    if (
        not hmac.compare_digest(digest, row["token_sha256"])
        and conn.execute(
            "SELECT 1 FROM participant_tokens WHERE participant_id=? AND token_sha256=?", (pid, digest)
        ).fetchone()
        is None
    ):
        raise HttpError(403, "this token does not belong to this participant")
    return state.participant(row), row


def step_json(state: StudyApp, step: Step, resume_code: str | None = None, p: Participant | None = None) -> dict:
    """A step as the page receives it: what to show and ask, progress, and the resume code."""
    out = {
        "phase": step.phase,
        "kind": step.kind,
        "videos": [state.videos.url(i) for i in step.shown],
        "questions": questions(step, state.cfg.kinds),
        "progress": progress(state.cfg, step),
        "seq": step.seq,
        "number": step.number,
        "method": step.method,
        "survey": step.survey,
    }
    if step.survey:
        out["title"] = SURVEY_TITLES[step.survey]
    out.update(step.extra)
    if "previous" in step.extra:
        out["previous_video"] = state.videos.url(int(step.extra["previous"]))
    if resume_code:
        out["resume_code"] = resume_code
    if p is not None and step.method:
        out["method_position"] = p.method_order.index(step.method) + 1  # the page's introduction of a method
        out["methods"] = len(p.method_order)
    if step.method:
        out["method_label"] = label(step.method)
    if step.method and step.kind == step.method:
        out["widget"] = widget(step.kind)  # how the page asks this kind's query
    if step.phase == "improve":
        out["last_round"] = step.number >= state.cfg.improve_max_iterations
    return out


def create_participant(state: StudyApp, body: bytes, client: str | None = None) -> dict[str, Any]:
    """A new participant; nothing about the browser or the person is stored (no User-Agent, no address). Sign-ups
    are limited per client (`client`, as for `resume`; held in memory only): made-up participants cannot outnumber
    real ones in the turns of the robot and the simulator."""
    data = decode_json(body, allow_empty=True)
    if not isinstance(data, dict):
        raise HttpError(400, "the body must be a JSON object ({})")
    if state.signups is not None:
        wait = state.signups.take(client_key(client))
        if wait:
            minutes = max(1, round(wait / 60))
            raise HttpError(
                429,
                f"too many people started the study from this address just now; try again in {minutes} min",
                {"Retry-After": str(wait)},
            )
    pid, token = secrets.token_hex(16), secrets.token_urlsafe(32)
    now = time.time()
    conn = state.connect()
    with sdb.transaction(conn):
        number = conn.execute("SELECT coalesce(max(number), 0) + 1 FROM participants").fetchone()[0]
        # counterbalancing: each arrival starts Study 2 one kind later (the paper's: odd ones language first)
        order = method_order(state.cfg.kinds, number)
        conn.execute(
            "INSERT INTO participants (id, token_sha256, number, method_order, seed, created_at, "
            "resume_code) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (pid, sha256(token), number, ",".join(order), number, now, sdb.new_resume_code(conn)),
        )
        step = first_step()
        conn.execute(
            "INSERT INTO steps (participant_id, seq, phase, kind, payload, created_at) VALUES (?, ?, ?, ?, ?, ?)",
            (pid, step.seq, step.phase, step.kind, step.payload(), now),
        )
    return {"participant_id": pid, "token": token}


def resume(state: StudyApp, body: bytes, client: str | None = None) -> dict[str, Any]:
    """`{"code": "XXXXX-XXXXX"}` -> a new token of the participant with that resume code (their other tokens
    keep working). Wrong codes are limited per client (`client`: its address, as the connection or a trusted proxy
    says: `TrustedProxies`), so codes cannot be guessed by trying and one client's wrong codes never block another's
    right one."""
    data = decode_json(body)
    code = (
        sdb.normalise_resume_code(data.get("code", ""))
        if isinstance(data, dict) and isinstance(data.get("code"), str)
        else None
    )
    who = client_key(client)
    if state.resume_failures.blocked(who):
        raise HttpError(429, "too many wrong resume codes; wait a minute and try again", {"Retry-After": "60"})
    conn = state.connect()
    row = conn.execute("SELECT id FROM participants WHERE resume_code=?", (code,)).fetchone() if code else None
    if row is None:
        state.resume_failures.add(who)
        raise HttpError(404, "no participant has this resume code; check it (it looks like ABCDE-FGH23)")
    if state.resumes.blocked(code):
        raise HttpError(429, "this resume code was used many times just now; wait a minute", {"Retry-After": "60"})
    state.resumes.add(code)
    token = secrets.token_urlsafe(32)
    with sdb.transaction(conn):
        conn.execute(
            "INSERT INTO participant_tokens (participant_id, token_sha256, created_at) VALUES (?, ?, ?)",
            (row["id"], sha256(token), time.time()),
        )
    return {"participant_id": row["id"], "token": token}


def get_step(state: StudyApp, pid: str, token: str | None) -> dict[str, Any]:
    """The participant's current step (the first time it is shown is recorded, for the time per query)."""
    conn = state.connect()
    p, prow = authenticate(state, conn, pid, token)
    step, row = state.current_step(conn, pid)
    if row["first_shown_at"] is None:
        conn.execute(
            "UPDATE steps SET first_shown_at=? WHERE participant_id=? AND seq=? AND first_shown_at IS NULL",
            (time.time(), pid, step.seq),
        )
    _show(state, conn, pid, step)
    return step_json(state, step, prow["resume_code"], p)


def _check_feedback(gate, text: str) -> None:
    """Typed feedback that is not about the robot's motion, or is about something the task does not measure, is
    asked again (400) before anything is stored."""
    if not gate.score(text).ok:
        raise HttpError(400, NOT_FEEDBACK)
    scope = gate.scope(text)
    if scope is not None and scope.outside:
        raise HttpError(400, gate.out_of_task_message(text, scope))


def answer(state: StudyApp, pid: str, token: str | None, body: bytes) -> dict[str, Any]:
    """Take an answer to the current step: check it, advance the flow (the robot learns), store it all in one
    transaction, and return the next step. A failure leaves the robot as the stored answers say."""
    data = decode_json(body)  # before the lock: its size, depth and number of values bound the work under it
    if not isinstance(data, dict):
        raise HttpError(400, "the body must be a JSON object")
    conn = state.connect()
    p, prow = authenticate(state, conn, pid, token)  # before the lock: unknown ids never reach it
    with state.lock(pid):
        step, row = state.current_step(conn, pid)
        try:
            ans = parse_answer(data, step, state.cfg.kinds)
        except AnswerError as exc:
            raise HttpError(exc.status, str(exc)) from None
        # typed feedback passes the gate; "no change" is a button, not a text to read
        typed = said(get_kind(step.kind), ans.value) if asks_feedback(step.kind) else None
        if typed is not None:
            _check_feedback(state.engine.gate, typed)
        if state.generated is not None and step.phase == "improve":
            try:
                for index in step.shown:  # an answer about a trajectory still being made is not taken yet
                    state.generated.phi(index)
            except NotReady as exc:
                raise HttpError(503, str(exc), {"Retry-After": str(VIDEO_RETRY_S)}) from None
        received = time.time()
        try:
            tr = advance(state.cfg, p, step, ans, state.robot)
        except NotReady as exc:
            state.robot.forget(pid)
            raise HttpError(503, str(exc), {"Retry-After": str(VIDEO_RETRY_S)}) from None
        except LangprefError as exc:
            state.robot.forget(pid)
            raise HttpError(400, str(exc)) from None
        except BaseException:
            state.robot.forget(pid)
            raise
        try:
            _store(conn, p, step, row, ans, tr, received)
        except BaseException:
            state.robot.forget(pid)
            raise
        if state.generated is not None:
            state.generated.after_answer(p, step.seq, tr.records)
        _show(state, conn, pid, tr.next)
        return step_json(state, tr.next, prow["resume_code"], p)


def _show(state: StudyApp, conn, pid: str, step: Step) -> None:
    """Tell the `--on-show` hook of a step handed out (it runs for a generated trajectory once it is made), with the
    steps that showed videos the participant has answered: the turns of the robot they have earned."""
    if state.hook is not None and step.shown and not state.hook.handed_out(pid, step.seq):
        earned = conn.execute(
            "SELECT count(*) FROM answers WHERE participant_id=? AND kind != 'survey'", (pid,)
        ).fetchone()[0]
        state.hook.show(pid, step.seq, step.kind, step.shown, earned)


def _store(conn, p: Participant, step: Step, row: dict, ans, tr, received: float) -> None:
    """The answer, the flow's records and the next step, in one transaction (409 if the step was answered
    meanwhile). Times: the server's from the step first shown to `received`, and whether the page's agrees."""
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
            (p.id, step.seq, step.phase, step.kind, json.dumps(ans.body), ans.client_ms, server_ms, consistent, now),
        )
        for table, record in tr.records:
            record = {"participant_id": p.id, "seq": step.seq, **record, "answered_at": now}
            if "client_ms" in record:  # a feedback kind's answer: the server's time beside the page's
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


async def video(state: StudyApp, request: Request):
    """`GET /videos/NAME`: the file once it is made; until then 503 with Retry-After, after a short wait.

    Async and never blocking: a video that is not made yet holds no worker thread (80 such requests once froze every
    other endpoint); it waits here a little (not once the server is stopping), then the client is told to come back.
    The name is read from the path itself: the route's pattern ends in `$`, which lets a trailing newline through.
    """
    index = state.videos.index_of(request.scope["path"].removeprefix("/videos/"))
    if index is None:
        raise HttpError(404, "no such video")
    status, info = state.videos.request(index)
    waiting = status in ("pending", "generating") and not state.stopping.is_set()
    if waiting and state.video_waiters < MAX_VIDEO_WAITERS:
        state.video_waiters += 1
        try:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + VIDEO_WAIT_S
            # a stop does not wait for the video: the answer comes at once, and the page asks again later
            while status in ("pending", "generating") and loop.time() < deadline and not state.stopping.is_set():
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
            f"the robot is making a new trajectory in the simulator ({info} ahead of it); retry in {VIDEO_RETRY_S} s",
            retry,
        )
    raise HttpError(503, f"the video is being made ({info} ahead of it); retry in {VIDEO_RETRY_S} s", retry)
