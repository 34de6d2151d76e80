"""What a browser opens: the pages (`/` guidelines and consent, `/study`, `/admin`), their static files, `/healthz`
and `/api/info` (the task and the protocol the pages describe)."""

from __future__ import annotations

import html
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import HTMLResponse

from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.kinds import label, study_kind
from langpref.study.protocol.surveys import task_text
from langpref.study.server.state import StudyApp

HERE = Path(__file__).parents[1]
"""`langpref/study/`, where the pages (`templates/`) and their scripts (`static/`) are shipped."""
STATIC = HERE / "static"
PAGES = (("/", "index.html"), ("/study", "study.html"), ("/admin", "admin.html"))
"""Route -> template in `templates/`."""
HEAD = HERE / "templates" / "_head.html"
"""The start of every page up to its own title and scripts, which the templates' `{{HEAD}}` stands for: the same
doctype, viewport and style sheet, written once."""
NUMBERS = {1: "one method", 2: "two methods", 3: "three methods", 4: "four methods"}
"""How the guidelines say how many methods Study 2 has."""


def page_router(state: StudyApp) -> APIRouter:
    """The pages, `/healthz` and `/api/info` over `state` (the static files are mounted by `create_app`)."""
    router = APIRouter()

    def page_route(template: str):
        def _page() -> HTMLResponse:  # no parameters: nothing from the request chooses the file
            return HTMLResponse(render_page(state, template), headers={"Cache-Control": "no-store"})

        return _page

    for route, template in PAGES:
        router.add_api_route(route, page_route(template), methods=["GET"], include_in_schema=False)

    @router.get("/healthz")
    def healthz():
        return {"ok": True}

    @router.get("/api/info")
    def info():
        return {
            "env": state.engine.env,
            "task": task_text(state.engine.env),
            "study": state.cfg.to_dict(),
            "methods": {m: label(m) for m in state.cfg.kinds},
        }

    return router


def render_page(state: StudyApp, name: str) -> str:
    """The template `name` after the shared head, with the task's text and the protocol's numbers filled in
    (HTML-escaped)."""
    task = task_text(state.engine.env)
    c = state.cfg
    values = {
        "ROBOT": task["robot"],
        "TASK": task["task"],
        "EXAMPLES": ", ".join(f"\u201c{e}\u201d" for e in task["examples"]),
        "IMPROVE_MAX": str(c.improve_max_iterations),
        "PREF_QUERIES": str(c.pref_queries),
        "RATING_EVERY": str(c.rating_every),
        "METHOD_COUNT": NUMBERS.get(len(c.kinds), f"{len(c.kinds)} methods"),
        "DURATION": duration_text(c),
    }
    text = (HERE / "templates" / name).read_text().replace("{{HEAD}}", HEAD.read_text().rstrip("\n"), 1)
    for key, value in values.items():
        text = text.replace("{{" + key + "}}", html.escape(value))
    return text.replace("{{METHOD_LIST}}", method_list(c.kinds))


def method_list(kinds: tuple[str, ...]) -> str:
    """The guidelines' list of Study 2's methods: each kind's label and introduction (`StudyPage`), HTML-escaped."""
    items = []
    for name in kinds:
        page = study_kind(name).page
        assert page is not None  # study_kind checked it
        items.append(f"<li><strong>{html.escape(page.label)}:</strong> {html.escape(page.intro)}</li>")
    return "\n".join(items)


def duration_text(c: StudyConfig) -> str:
    """How long the study takes, from its protocol, for the guidelines ("30 to 45 minutes" for the paper's): surveys
    8-10 minutes in all, a Study-1 round 40-60 s (most people are satisfied within 3), a language query 30-40 s, a
    comparison 20-25 s, a rating 10-15 s."""
    ratings = 2 * len(c.rating_points())
    lo = 8 * 60 + 40 * min(c.improve_max_iterations, 3) + c.pref_queries * (30 + 20) + ratings * 10
    hi = 10 * 60 + 60 * c.improve_max_iterations + c.pref_queries * (40 + 25) + ratings * 15
    lo_min = max(5, 5 * round(lo / 300))
    return f"{lo_min} to {max(5 * round(hi / 300), lo_min + 5)} minutes"
