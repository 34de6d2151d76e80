"""The lab's side of the HTTP contract: the dashboard's data, excluding a participant, the export and the status.

`GET /api/admin/participants`, `POST /api/admin/participants/ID/exclude`, `GET /api/admin/export`,
`GET /api/admin/status`; every one needs the header `Authorization: Bearer ADMIN_TOKEN` (401 without it, 403 with
another token), checked before anything else of the request is read.
"""

from __future__ import annotations

import hmac
from typing import Any

from fastapi import APIRouter, Depends, Request
from starlette.concurrency import run_in_threadpool

from langpref.study.protocol import db as sdb
from langpref.study.protocol import schema
from langpref.study.protocol.flow import AnswerError, clean_text, progress
from langpref.study.server.guard import HttpError, decode_json, read_body
from langpref.study.server.state import StudyApp

MAX_REASON = 300
"""Characters of the reason given for leaving a participant out."""


def check_admin(state: StudyApp, header: str | None) -> None:
    """Raise 401 without an `Authorization` header and 403 unless it is `Bearer` and the admin token."""
    if not header:
        raise HttpError(401, "missing Authorization: Bearer ADMIN_TOKEN header")
    scheme, _, value = header.partition(" ")
    if scheme.lower() != "bearer" or not hmac.compare_digest(value.strip().encode(), state.admin_token.encode()):
        raise HttpError(403, "wrong admin token")


def admin_router(state: StudyApp) -> APIRouter:
    """The admin endpoints over `state`, each behind `check_admin`."""

    async def admin_only(request: Request) -> None:
        check_admin(state, request.headers.get("authorization"))

    router = APIRouter(prefix="/api/admin", dependencies=[Depends(admin_only)])

    @router.get("/participants")
    def participants():
        return participants_overview(state)

    @router.post("/participants/{pid}/exclude")
    async def exclude(pid: str, request: Request):
        body = await read_body(request)
        return await run_in_threadpool(set_excluded, state, pid, body)

    @router.get("/export")
    def export():
        return export_all(state)

    @router.get("/status")
    def status():
        return server_status(state)

    return router


def participants_overview(state: StudyApp) -> dict[str, Any]:
    """Every participant with where they are and their last feedback, the videos' progress, the protocol and the
    hook's status (the dashboard)."""
    conn = state.connect()
    out = []
    for p in conn.execute("SELECT * FROM participants ORDER BY number").fetchall():
        step, _ = state.current_step(conn, p["id"])
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
                "progress": progress(state.cfg, step),
                "answers": n_answers,
                "recent_feedback": feedback,
            }
        )
    return {
        "participants": out,
        "videos": state.videos.progress(),
        "study": state.cfg.to_dict(),
        "hooks": state.hook.status() if state.hook else None,
    }


def set_excluded(state: StudyApp, pid: str, body: bytes) -> dict[str, Any]:
    """`{"excluded": true|false, "reason": "..."}`: leave a participant out of the analyses (or back in)."""
    data = decode_json(body)
    if not isinstance(data, dict) or not isinstance(data.get("excluded"), bool):
        raise HttpError(400, 'send {"excluded": true or false, "reason": "why (optional)"}')
    try:
        reason = clean_text(data.get("reason") or "")
    except AnswerError as exc:
        raise HttpError(400, str(exc)) from None
    if not isinstance(reason, str) or len(reason) > MAX_REASON:
        raise HttpError(400, f"'reason' must be a text of at most {MAX_REASON} characters")
    conn = state.connect()
    with sdb.transaction(conn):
        n = conn.execute(
            "UPDATE participants SET excluded=?, excluded_reason=? WHERE id=?",
            (int(data["excluded"]), reason.strip() or None if data["excluded"] else None, pid),
        ).rowcount
    if not n:
        raise HttpError(404, "unknown participant")
    return {"participant_id": pid, "excluded": data["excluded"]}


def export_all(state: StudyApp) -> dict[str, Any]:
    """The study's meta, every table, the analyses and the learned rewards, as `langpref study export` computes
    them (no files)."""
    from langpref.study.analysis.learned import learned_rewards
    from langpref.study.analysis.stats import analyse
    from langpref.study.analysis.tables import read_tables, resolve_exclusions

    conn = state.connect()
    tables = read_tables(conn)
    return {
        "meta": sdb.read_meta(conn),
        "tables": tables,
        "analysis": analyse(tables),
        "learned_rewards": learned_rewards(tables, resolve_exclusions(tables["participants"])),
    }


def server_status(state: StudyApp) -> dict[str, Any]:
    """Rows per table and the progress of the videos, the engine, the hook and the generated trajectories."""
    conn = state.connect()
    counts = {t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in schema.TABLES}
    return {
        "videos": {**state.videos.progress(), "waiting_requests": state.video_waiters},
        "rows": counts,
        "engine": state.engine.describe(),
        "hooks": state.hook.status() if state.hook else None,
        "generated": state.generated.progress() if state.generated else None,
    }
