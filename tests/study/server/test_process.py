"""The server as a process: SIGTERM stops it in well under a second even while a video is being made and pages wait
for videos, keeping every answer it acknowledged, and neither a SIGTERM nor a SIGKILL leaves a process of it behind
(the render worker watches its parent). What can be checked before the model is loaded (a taken port, a directory as
--db) is refused at once, and --host 0.0.0.0 warns."""

from __future__ import annotations

import os
import signal
import socket
import time

import httpx
import pytest

from benchmarks.common import alive, descendants


def start_rendering(h, tmp_path, name: str):
    """A server with a video being made: (process, url, its render worker's pids)."""
    proc, url = h.run_server(
        tmp_path / f"{name}.sqlite", "--video-width", "64", "--video-height", "48", log=tmp_path / f"{name}.log"
    )
    pid, headers = h.join(httpx.Client(base_url=url, timeout=30))
    step = httpx.get(f"{url}/api/participants/{pid}/step", headers=headers).json()
    r = httpx.post(
        f"{url}/api/participants/{pid}/answer",
        json={**h.answer_for(step), "seq": step["seq"]},
        headers=headers,
        timeout=30,
    )
    assert r.status_code == 200, r.text
    video = r.json()["videos"][0]
    httpx.get(url + video, timeout=30)  # the worker starts
    deadline = time.time() + 60
    while not (workers := descendants(proc.pid)):
        assert time.time() < deadline, "no render worker started"
        time.sleep(0.05)
    return proc, url, workers


def test_sigterm_stops_the_server_in_seconds_and_leaves_nothing(h, tmp_path):
    proc, _, workers = start_rendering(h, tmp_path, "term")
    every = workers | descendants(proc.pid)
    t = time.time()
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=30)
    took = time.time() - t
    proc.stdout.close()
    assert took < 5.0, took
    assert proc.returncode == 0
    deadline = time.time() + 5
    while alive(every) and time.time() < deadline:
        time.sleep(0.05)
    assert not alive(every), "processes of the server are left after SIGTERM"


def test_sigterm_is_prompt_with_video_requests_waiting_and_keeps_every_acknowledged_answer(h, tmp_path):
    """A stop took 3.3-5.5 s: uvicorn's graceful stop waited for the requests waiting for a video (up to 2 s each),
    then the interpreter's teardown of torch, MuJoCo and EGL took one or more seconds. Now the waiting requests are
    answered at once and the process ends after its cleanup; an answer acknowledged before is in the database."""
    import sqlite3
    import threading

    db = tmp_path / "prompt.sqlite"
    proc, url = h.run_server(db, "--video-width", "160", "--video-height", "120", log=tmp_path / "prompt.log")
    every: set[int] = set()
    acknowledged: list[tuple[str, int]] = []
    answering, gone = threading.Event(), threading.Event()

    def participant():  # answers step after step until the server is gone
        try:
            with httpx.Client(base_url=url, timeout=30) as c:
                pid, headers = h.join(c)
                while not gone.is_set():
                    step = c.get(f"/api/participants/{pid}/step", headers=headers).json()
                    if step["kind"] == "done":
                        return
                    r = c.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers)
                    if r.status_code == 200:
                        acknowledged.append((pid, step["seq"]))
                        answering.set()
        except httpx.HTTPError:
            pass

    def page(name: str):  # a page waiting for a video: it asks again while the video is being made
        try:
            with httpx.Client(base_url=url, timeout=30) as c:
                while not gone.is_set() and c.get(name).status_code == 503:
                    pass
        except httpx.HTTPError:
            pass

    threads = [threading.Thread(target=participant, daemon=True) for _ in range(2)]
    for t in threads:
        t.start()
    assert answering.wait(60), "no answer was taken"
    with httpx.Client(base_url=url, timeout=30) as c:
        pid, headers = h.join(c)
        shown = c.get(f"/api/participants/{pid}/step", headers=headers).json()
        while not shown["videos"]:
            shown = c.post(f"/api/participants/{pid}/answer", json=h.answer_for(shown), headers=headers).json()
        name = shown["videos"][0]
        names = [name.replace(name[len("/videos/traj") :][:6], f"{i:06d}") for i in range(16)]
        pages = [threading.Thread(target=page, args=(n,), daemon=True) for n in names]
        for t in pages:
            t.start()
        deadline = time.time() + 60
        while c.get("/api/admin/status", headers=h.admin).json()["videos"]["waiting_requests"] == 0:
            assert time.time() < deadline, "no request waited for a video"
        every = descendants(proc.pid)
    t = time.time()
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=30)
    took = time.time() - t
    gone.set()
    proc.stdout.close()
    assert proc.returncode == 0 and took < 2.0, took
    for thread in threads:
        thread.join(30)
    conn = sqlite3.connect(db)
    stored = set(conn.execute("SELECT participant_id, seq FROM answers").fetchall())
    conn.close()
    assert acknowledged and set(acknowledged) <= stored
    deadline = time.time() + 5
    while alive(every) and time.time() < deadline:
        time.sleep(0.05)
    assert not alive(every), "processes of the server are left after SIGTERM"


def test_sigkill_leaves_no_process_behind(h, tmp_path):
    proc, _, workers = start_rendering(h, tmp_path, "kill")
    every = workers | descendants(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stdout.close()
    deadline = time.time() + 5
    while alive(every) and time.time() < deadline:
        time.sleep(0.05)
    assert not alive(every), "the render worker was orphaned"


def test_taken_port_and_directory_db_fail_before_the_model_loads(h, tmp_path, monkeypatch, capsys):
    from langpref.cli import main
    from langpref.study.session import engine as sengine

    def no_load(*a, **k):
        raise AssertionError("the model was loaded before the checks")

    monkeypatch.setattr(sengine.StudyEngine, "load", classmethod(no_load))
    base = ["study", "serve", "--model", str(h.model), "--data", str(h.data)]
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    try:
        port = taken.getsockname()[1]
        assert main([*base, "--db", str(tmp_path / "a.sqlite"), "--port", str(port)]) == 2
    finally:
        taken.close()
    err = capsys.readouterr().err
    assert "cannot listen" in err and len(err.strip().splitlines()) == 1
    folder = tmp_path / "folder"
    folder.mkdir()
    assert main([*base, "--db", str(folder), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "is a directory" in err and len(err.strip().splitlines()) == 1


def test_network_host_warns_and_loopback_does_not():
    from langpref.study.server.serve import network_warning

    assert network_warning("127.0.0.1") is None and network_warning("::1") is None
    assert network_warning("localhost") is None
    for host in ("0.0.0.0", "::", "192.168.1.20"):
        text = network_warning(host)
        assert text and "plain HTTP" in text and "reverse proxy" in text


def test_admin_token_from_environment_or_file(tmp_path, monkeypatch):
    from langpref.errors import LangprefError
    from langpref.study.server.settings import ADMIN_TOKEN_ENV, ServeConfig

    monkeypatch.delenv(ADMIN_TOKEN_ENV, raising=False)
    assert ServeConfig(model="m", data="d").resolve_admin_token() is None
    monkeypatch.setenv(ADMIN_TOKEN_ENV, "from-the-environment-123")
    assert ServeConfig(model="m", data="d").resolve_admin_token() == "from-the-environment-123"
    f = tmp_path / "token"
    f.write_text("from-a-file-0123456789\n")
    assert ServeConfig(model="m", data="d", admin_token_file=str(f)).resolve_admin_token() == "from-a-file-0123456789"
    with pytest.raises(LangprefError, match="at least 16"):
        ServeConfig(model="m", data="d", admin_token="short").resolve_admin_token()
    with pytest.raises(LangprefError, match="cannot read"):
        ServeConfig(model="m", data="d", admin_token_file=str(tmp_path / "none")).resolve_admin_token()
    assert os.environ[ADMIN_TOKEN_ENV]
