"""A real browser (Playwright driving Debian's Chromium, headless) clicks through a whole participant session of a
tiny study on a server started here: videos really play, the keyboard works, the answers are all in the database,
and the dashboard shows typed `<script>` as text. Screenshots of every page kind go to the test's output folder
(and to $LANGPREF_STUDY_SCREENSHOTS as study_<kind>.png when that is set)."""

from __future__ import annotations

import os
import shutil
import sqlite3
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run", "--autoplay-policy=no-user-gesture-required"]
EVIL = "<script>window.pwned=1</script> move faster"


@pytest.fixture
def browser():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (make install)")
    if not Path(CHROMIUM).exists():
        pytest.skip("Debian's chromium is not installed (make install installs it with apt)")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


@pytest.fixture
def server(engine, h, tmp_path):
    from langpref.study.serve import BackgroundServer, build_state

    state = build_state(h.serve_config(tmp_path / "browser.sqlite", pref_queries=2, rating_every=2,
                                       improve_max_iterations=2), engine=engine, progress=False)
    state.videos.start(prerender=True)
    assert state.videos.wait(timeout=240), "videos were not rendered in time"
    assert state.videos.progress()["done"] == len(engine.study), state.videos.progress()
    with BackgroundServer(state) as url:
        yield state, url
    state.videos.close()


class Shots:
    def __init__(self, folder: Path):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.copy_to = os.environ.get("LANGPREF_STUDY_SCREENSHOTS")
        self.taken: dict[str, Path] = {}

    def __call__(self, page, name: str) -> None:
        if name in self.taken:
            return
        path = self.folder / f"study_{name}.png"
        page.screenshot(path=str(path), full_page=True)
        self.taken[name] = path
        if self.copy_to:
            Path(self.copy_to).mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, Path(self.copy_to) / path.name)


def wait_kind(page, kind: str, phase: str | None = None) -> None:
    sel = f'main[data-kind="{kind}"]' + (f'[data-phase="{phase}"]' if phase else "")
    page.wait_for_selector(sel, timeout=30000)


def seq(page) -> int:
    return page.evaluate("current.seq")


def assert_videos_play(page, count: int) -> None:
    page.wait_for_function(
        f"""() => {{ const vs = [...document.querySelectorAll('video')];
              return vs.length === {count} && vs.every(v => v.readyState >= 2 && v.duration > 0 && v.currentTime > 0
                                                           && !v.paused && !v.error); }}""", timeout=30000)
    t1 = page.evaluate("[...document.querySelectorAll('video')].map(v => v.currentTime)")
    page.wait_for_timeout(250)
    t2 = page.evaluate("[...document.querySelectorAll('video')].map(v => v.currentTime)")
    assert all(a != b for a, b in zip(t1, t2)), (t1, t2)
    assert page.evaluate("document.querySelector('video').duration") > 0


def fill_survey(page) -> None:
    for fs in page.query_selector_all("fieldset"):
        kind = fs.get_attribute("data-type")
        if kind == "text":
            fs.query_selector("textarea").fill("I have seen robots in videos.")
        else:
            fs.query_selector("input").check()
    before = seq(page)
    page.click("form.survey button[type=submit]")
    page.wait_for_function(f"() => current.seq > {before}")


def give_feedback(page, text: str, by_enter: bool = True) -> None:
    before = seq(page)
    page.fill("#feedback", text)
    if by_enter:
        page.press("#feedback", "Enter")
    else:
        page.click("form.feedback button[type=submit]")
    page.wait_for_function(f"() => current.seq > {before}")


def click_and_wait(page, selector: str) -> None:
    before = seq(page)
    page.click(selector)
    page.wait_for_function(f"() => current.seq > {before}")


def test_a_participant_clicks_through_the_whole_study(browser, server, tmp_path):
    state, url = server
    shots = Shots(tmp_path / "screenshots")
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))

    page.goto(url + "/")
    shots(page, "guidelines")
    page.click("#start")  # without consent: refused with a message
    assert page.is_visible("#error")
    page.check("#consent")
    page.click("#start")
    wait_kind(page, "survey", "pre_survey")
    shots(page, "survey")
    page.reload()  # a reload continues at the same step
    wait_kind(page, "survey", "pre_survey")
    fill_survey(page)

    # Study 1: feedback, improved trajectory, not satisfied, feedback again, then the round limit
    wait_kind(page, "language", "improve")
    assert_videos_play(page, 1)
    shots(page, "language")
    page.click("form.feedback button[type=submit]")  # empty feedback: a message, nothing sent
    assert "type your feedback" in page.inner_text("#answer-error")
    assert seq(page) == 1
    page.fill("#feedback", "qwertyuiop")  # nonsense: the server's one-line message, the same step
    page.press("#feedback", "Enter")
    page.wait_for_function("() => document.getElementById('answer-error').textContent.includes('does not read')")
    assert seq(page) == 1
    give_feedback(page, EVIL)
    wait_kind(page, "satisfaction", "improve")
    assert "understood your feedback as" in page.inner_text(".understood")
    assert_videos_play(page, 1)
    shots(page, "satisfaction")
    click_and_wait(page, "text=No, keep improving")
    wait_kind(page, "language", "improve")
    give_feedback(page, "Stay a bit lower.", by_enter=False)
    wait_kind(page, "satisfaction", "improve")
    click_and_wait(page, "text=No, keep improving")  # round 2 of 2: on to the survey
    wait_kind(page, "survey", "improve_survey")
    fill_survey(page)

    # Study 2, participant 1: language first (2 queries and a rating), then comparisons
    wait_kind(page, "language", "pref_language")
    assert "Query 1 of 2" in page.inner_text("#progress-text")
    give_feedback(page, "Move faster.")
    wait_kind(page, "language", "pref_language")
    give_feedback(page, "Get closer to the button.")
    wait_kind(page, "rating", "pref_language")
    assert_videos_play(page, 1)
    shots(page, "rating")
    click_and_wait(page, "button[aria-label='Rate 4 of 5']")
    wait_kind(page, "comparison", "pref_comparison")
    assert_videos_play(page, 2)
    shots(page, "comparison")
    page.click("button.replay >> nth=0")  # replay works and the video plays on
    assert_videos_play(page, 2)
    before = seq(page)
    page.keyboard.press("2")  # keyboard choice
    page.wait_for_function(f"() => current.seq > {before}")
    wait_kind(page, "comparison", "pref_comparison")
    click_and_wait(page, "text=I prefer trajectory 1")
    wait_kind(page, "rating", "pref_comparison")
    click_and_wait(page, "button[aria-label='Rate 2 of 5']")
    wait_kind(page, "survey", "pref_survey")
    fill_survey(page)
    wait_kind(page, "done")
    shots(page, "done")

    # a phone-sized screen
    phone = browser.new_page(viewport={"width": 390, "height": 844}, is_mobile=True)
    phone.goto(url + "/")
    shots(phone, "phone_guidelines")
    phone.close()

    # every answer is in the database, with client times consistent with the server's clock
    conn = sqlite3.connect(state.db_path)
    n_steps = conn.execute("SELECT count(*) FROM steps").fetchone()[0]
    assert conn.execute("SELECT count(*) FROM answers").fetchone()[0] == n_steps - 1 == 1 + 4 + 1 + 3 + 3 + 1
    assert conn.execute("SELECT count(*) FROM answers WHERE time_consistent = 0").fetchone()[0] == 0
    assert conn.execute("SELECT text FROM feedback ORDER BY seq").fetchone()[0] == EVIL
    assert conn.execute("SELECT count(*) FROM comparisons").fetchone()[0] == 2
    assert [r[0] for r in conn.execute("SELECT choice FROM comparisons ORDER BY seq")] == [1, 0]

    # the dashboard shows the typed script as text and runs nothing
    admin = browser.new_page(viewport={"width": 1280, "height": 800})
    admin.on("pageerror", lambda e: errors.append(str(e)))
    admin.goto(url + "/admin")
    admin.fill("#token", "wrong-token-of-some-length")
    admin.click("#login button")
    admin.wait_for_selector("#error:not([hidden])")
    admin.fill("#token", state.admin_token)
    admin.click("#login button")
    admin.wait_for_selector("#participants tbody tr")
    texts = admin.eval_on_selector_all("li.feedback-text", "els => els.map(e => e.textContent)")
    assert any(EVIL in t for t in texts)
    assert admin.evaluate("window.pwned === undefined && document.querySelectorAll('#participants script').length "
                          "=== 0")
    shots(admin, "admin")
    assert not errors, errors
    print(f"screenshots in {shots.folder}")
    assert set(shots.taken) >= {"guidelines", "survey", "language", "satisfaction", "comparison", "rating", "done",
                                "admin"}
