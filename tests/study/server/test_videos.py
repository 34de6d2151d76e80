"""Videos that are not made yet never hold the server: 80 concurrent requests for them leave `/healthz` and
`POST /api/participants` answering within a second; each such request is answered (the video, or a 503 with
Retry-After) within a few seconds, and the number of waiting requests is bounded."""

from __future__ import annotations

import asyncio
import time

import httpx


def test_unrendered_videos_do_not_freeze_the_server(engine, h, tmp_path):
    from langpref.study.server import participants as sapp
    from langpref.study.server.serve import BackgroundServer, build_state

    cfg = h.serve_config(tmp_path / "v.sqlite")
    cfg.video.width, cfg.video.height, cfg.video.stride = 64, 48, 3
    state = build_state(cfg, engine=engine, progress=False)
    names = [state.videos.url(int(i)) for i in engine.study]
    try:
        with BackgroundServer(state) as url:

            async def main() -> tuple[list[httpx.Response], list[float], int]:
                limits = httpx.Limits(max_connections=200, max_keepalive_connections=200)
                async with httpx.AsyncClient(base_url=url, timeout=30, limits=limits) as c:
                    t0 = time.perf_counter()
                    videos = [asyncio.create_task(c.get(names[k % len(names)])) for k in range(80)]
                    await asyncio.sleep(0.5)  # all 80 are in the server now
                    waiting = state.video_waiters
                    lat = []
                    async with httpx.AsyncClient(base_url=url, timeout=30) as other:
                        for path, method in (("/healthz", "GET"), ("/api/participants", "POST"), ("/healthz", "GET")):
                            t = time.perf_counter()
                            r = await other.request(method, path, json={} if method == "POST" else None)
                            lat.append(time.perf_counter() - t)
                            assert r.status_code == 200, r.text
                    done = await asyncio.gather(*videos)
                    assert time.perf_counter() - t0 < sapp.VIDEO_WAIT_S + 10
                    return done, lat, waiting

            done, lat, waiting = asyncio.run(main())
    finally:
        state.videos.close()
    assert max(lat) < 1.0, lat
    assert waiting <= sapp.MAX_VIDEO_WAITERS
    statuses = {r.status_code for r in done}
    assert statuses <= {200, 503}, statuses
    for r in done:
        if r.status_code == 503:
            assert r.headers["retry-after"].isdigit() and "being made" in r.json()["error"]
        else:
            assert r.headers["content-type"] == "video/webm"
    assert 503 in statuses  # 16 videos cannot all be made in 2 s: the rest are told to come back


def test_a_video_is_served_once_made(client, study_state):
    """A 503 while it is made, then the file (the page retries after Retry-After)."""
    url = study_state.videos.url(int(study_state.engine.study[0]))
    deadline = time.time() + 120
    while True:
        r = client.get(url)
        if r.status_code == 200:
            break
        assert r.status_code == 503 and int(r.headers["retry-after"]) > 0
        assert time.time() < deadline
        time.sleep(0.2)
    assert r.content[:4] == b"\x1a\x45\xdf\xa3"


def test_video_names_take_ascii_digits_and_nothing_after(study_state, client):
    index = int(study_state.engine.study[0])
    name = study_state.videos.name(index)
    assert study_state.videos.index_of(name) == index
    digits = name[4:10]
    wide = "".join(chr(0xFF10 + int(d)) for d in digits)  # full-width digits: `\d` took them
    arabic = "".join(chr(0x0660 + int(d)) for d in digits)
    for bad in (name + "\n", name.replace(digits, wide), name.replace(digits, arabic), " " + name, name + "x"):
        assert study_state.videos.index_of(bad) is None, ascii(bad)
    assert client.get(f"/videos/{name}%0A").status_code == 404


def test_a_failed_job_is_one_line_and_a_broken_worker_pool_is_dropped():
    from types import SimpleNamespace

    from langpref.study.session.workers import job_failure

    live, broken = SimpleNamespace(_broken=False), SimpleNamespace(_broken="a worker died")
    assert job_failure(ValueError("bad row"), live) == ("ValueError: bad row", live)
    why, pool = job_failure(RuntimeError("x" * 1000), broken)
    assert pool is None and len(why) == 300 and why.startswith("RuntimeError: xxx")
    assert job_failure(OSError("gone"), None) == ("OSError: gone", None)
