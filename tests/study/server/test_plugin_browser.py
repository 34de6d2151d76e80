"""The participant page draws a plugin kind's query from the step's `widget` with no edit in the study's JS: a choice
among three trajectories (buttons and keys) and a typed verdict, in Debian's Chromium
(as tests/study/server/test_browser.py)."""

from __future__ import annotations

import json
import sqlite3

from test_browser import browser, wait_kind  # noqa: F401 (the fixture, shared)
from test_plugin_kinds import answer, installed  # noqa: F401 (the fixture, shared)


def test_the_page_asks_plugin_kinds_by_their_widgets(installed, browser, engine, h, tmp_path):  # noqa: F811
    import httpx

    from langpref.study.server.serve import BackgroundServer, build_state

    cfg = h.serve_config(
        tmp_path / "widgets.sqlite", kinds=("best_of_three", "verdict"), pref_queries=2, improve_max_iterations=1
    )
    cfg.video.width, cfg.video.height, cfg.video.stride = 160, 120, 3
    state = build_state(cfg, engine=engine, progress=False)
    state.videos.start(prerender=False)
    errors: list[str] = []
    try:
        with BackgroundServer(state) as url:
            with httpx.Client(base_url=url, timeout=60) as c:  # to the first plugin query over HTTP
                pid, headers = h.join(c)
                step = c.get(f"/api/participants/{pid}/step", headers=headers).json()
                while step["kind"] != "best_of_three":
                    step = c.post(f"/api/participants/{pid}/answer", json=answer(step, h), headers=headers).json()
            session = json.dumps({"participant_id": pid, "token": headers["X-Participant-Token"]})
            page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(url + "/")
            page.evaluate(f"localStorage.setItem('langpref-participant', {json.dumps(session)})")
            page.goto(url + "/study")

            wait_kind(page, "intro", "pref_best_of_three")
            assert "first method: best of three" in page.inner_text("h1")
            assert "Each query shows three trajectories." in page.inner_text("main")
            page.click("#begin")
            wait_kind(page, "best_of_three", "pref_best_of_three")
            assert page.inner_text("h1") == "Which of the three is best?"
            assert page.inner_text("#phase-title") == "Experiment 2: Best of three"
            assert page.locator(".choices button").all_inner_texts() == ["Trajectory 1", "Trajectory 2", "Trajectory 3"]
            assert page.locator("video").count() == 3
            before = page.evaluate("current.seq")
            page.keyboard.press("3")  # keys 1..3 choose
            page.wait_for_function(f"() => current.seq > {before}")
            wait_kind(page, "best_of_three", "pref_best_of_three")
            page.click(".choices button >> nth=1")  # the second trajectory's button
            wait_kind(page, "rating", "pref_best_of_three")
            page.click("button[aria-label='Rate 3 of 5']")

            wait_kind(page, "intro", "pref_verdict")
            assert "second method: verdict" in page.inner_text("h1")
            page.click("#begin")
            wait_kind(page, "verdict", "pref_verdict")
            assert page.inner_text("h1") == "Is this trajectory good or bad?"
            page.click("form.feedback button[type=submit]")  # empty: said on the page, nothing sent
            assert "type your answer" in page.inner_text("#answer-error")
            page.fill("#feedback", "maybe")  # the kind's own check, as one line
            page.click("form.feedback button[type=submit]")
            page.wait_for_function("() => document.getElementById('answer-error').textContent.includes('good or bad')")
            before = page.evaluate("current.seq")
            page.fill("#feedback", "Bad")
            page.click("form.feedback button[type=submit]")
            page.wait_for_function(f"() => current.seq > {before}")  # the next query, not the one still shown
            wait_kind(page, "verdict", "pref_verdict")
            page.fill("#feedback", "good")
            page.click("form.feedback button[type=submit]")
            wait_kind(page, "rating", "pref_verdict")
    finally:
        state.videos.close()
    assert not errors, errors
    conn = sqlite3.connect(state.db_path)
    assert [json.loads(r[0])["best"] for r in conn.execute("SELECT answer FROM triples ORDER BY seq")] == [2, 1]
    assert [json.loads(r[0])["text"] for r in conn.execute("SELECT answer FROM verdicts ORDER BY seq")] == [
        "bad",
        "good",
    ]
