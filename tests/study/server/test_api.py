"""The HTTP contract of docs/design.md, on the tiny real setup: shapes, a whole session, counterbalancing,
persistence."""

from __future__ import annotations

import itertools
import re

STEP_KEYS = {"phase", "kind", "videos", "questions", "progress"}
PHASES = {"pre_survey", "improve", "improve_survey", "pref_language", "pref_comparison", "pref_survey", "done"}
KINDS = {"survey", "language", "comparison", "satisfaction", "rating", "done"}
N_VIDEOS = {"survey": 0, "language": 1, "comparison": 2, "satisfaction": 1, "rating": 1, "done": 0}


def check_step(step: dict) -> None:
    assert STEP_KEYS <= set(step), step
    assert step["phase"] in PHASES and step["kind"] in KINDS
    assert len(step["videos"]) == N_VIDEOS[step["kind"]]
    assert all(re.fullmatch(r"/videos/[A-Za-z0-9_.-]+", v) for v in step["videos"])
    assert set(step["progress"]) == {"done", "total"}
    assert all(isinstance(step["progress"][k], int) for k in ("done", "total"))
    if step["kind"] == "survey":
        assert step["questions"]
        for q in step["questions"]:
            assert {"id", "text", "type", "min", "max", "options"} <= set(q)
            assert q["type"] in ("likert", "text", "choice", "multi")
            if q["type"] == "likert":
                assert (q["min"], q["max"]) == (1, 5)
            if q["type"] in ("choice", "multi"):
                assert q["options"]
    else:
        assert step["questions"] == []


def walk(client, h, pid, headers, feedback="Move faster."):
    """Answer every step until done; the steps seen (first to done)."""
    steps = [client.get(f"/api/participants/{pid}/step", headers=headers).json()]
    while steps[-1]["kind"] != "done":
        check_step(steps[-1])
        r = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(steps[-1], feedback), headers=headers)
        assert r.status_code == 200, r.text
        steps.append(r.json())
    check_step(steps[-1])
    return steps


def test_create_participant_gives_unguessable_credentials(client, study_state):
    ids = [client.post("/api/participants", json={}).json() for _ in range(3)]
    assert all(set(x) == {"participant_id", "token"} for x in ids)
    assert len({x["participant_id"] for x in ids}) == 3
    assert all(re.fullmatch(r"[0-9a-f]{32}", x["participant_id"]) for x in ids)  # 128 random bits
    assert all(len(x["token"]) >= 40 for x in ids)  # 256 random bits, URL-safe base64
    conn = study_state.connect()
    stored = [r[0] for r in conn.execute("SELECT token_sha256 FROM participants")]
    assert not {x["token"] for x in ids} & set(stored)  # only hashes are stored
    assert client.post("/api/participants").status_code == 200  # an empty body is fine too


def test_whole_session_follows_the_contract(client, h, study_state):
    pid, headers = h.join(client)
    steps = walk(client, h, pid, headers)
    phases = list(dict.fromkeys(s["phase"] for s in steps))
    assert phases == [
        "pre_survey",
        "improve",
        "improve_survey",
        "pref_language",
        "pref_comparison",
        "pref_survey",
        "done",
    ]
    assert steps[-1]["kind"] == "done"
    # after each language answer the page learns how the robot understood it
    after = [b for a, b in itertools.pairwise(steps) if a["kind"] == "language"]
    assert after and all(set(b["understood"]) >= {"feature", "direction", "confidence"} for b in after)
    assert all(b["understood"]["feature"] in ("height", "speed", "distance_to_button") for b in after)
    # Study 2: 4 queries per method, a rating after queries 2 and 4
    for method in ("language", "comparison"):
        seq = [(s["kind"], s["progress"]["done"]) for s in steps if s["phase"] == f"pref_{method}"]
        assert seq == [(method, 0), (method, 1), ("rating", 2), (method, 2), (method, 3), ("rating", 4)]
    # every answer stored, with timestamps
    conn = study_state.connect()
    n_answers = conn.execute("SELECT count(*) FROM answers WHERE participant_id=?", (pid,)).fetchone()[0]
    assert n_answers == len(steps) - 1
    assert conn.execute("SELECT count(*) FROM feedback WHERE participant_id=?", (pid,)).fetchone()[0] == 3 + 4
    assert conn.execute("SELECT count(*) FROM comparisons WHERE participant_id=?", (pid,)).fetchone()[0] == 4
    assert conn.execute("SELECT count(*) FROM ratings WHERE participant_id=?", (pid,)).fetchone()[0] == 4
    assert (
        conn.execute("SELECT count(*) FROM answers WHERE answered_at IS NULL OR server_ms IS NULL").fetchone()[0] == 0
    )
    assert conn.execute("SELECT finished_at FROM participants WHERE id=?", (pid,)).fetchone()[0] is not None
    # a finished study takes no more answers
    r = client.post(f"/api/participants/{pid}/answer", json={"rating": 3, "seq": steps[-1]["seq"]}, headers=headers)
    assert r.status_code == 409 and "finished" in r.json()["error"]


def test_study_2_order_is_counterbalanced(client, h):
    firsts = []
    for _ in range(4):
        pid, headers = h.join(client)
        steps = walk(client, h, pid, headers)
        firsts.append(next(s["phase"] for s in steps if s["phase"].startswith("pref_")))
    assert firsts == ["pref_language", "pref_comparison", "pref_language", "pref_comparison"]


def test_reload_shows_the_same_step(client, h):
    pid, headers = h.join(client)
    url = f"/api/participants/{pid}/step"
    client.post(
        f"/api/participants/{pid}/answer", json=h.answer_for(client.get(url, headers=headers).json()), headers=headers
    )
    first = client.get(url, headers=headers).json()
    assert first["kind"] == "language" and first["phase"] == "improve"
    assert client.get(url, headers=headers).json() == first
    r = client.post(
        f"/api/participants/{pid}/answer",
        json={"feedback": "Go lower please", "client_ms": 5, "seq": first["seq"]},
        headers=headers,
    )
    step = r.json()
    assert step["kind"] == "satisfaction" and client.get(url, headers=headers).json() == step


def test_study_1_stops_when_satisfied(client, h):
    pid, headers = h.join(client)
    url = f"/api/participants/{pid}/answer"
    step = client.post(
        url, json=h.answer_for(client.get(f"/api/participants/{pid}/step", headers=headers).json()), headers=headers
    ).json()
    step = client.post(
        url, json={"feedback": "Move faster.", "client_ms": 3, "seq": step["seq"]}, headers=headers
    ).json()
    assert step["kind"] == "satisfaction" and step["progress"] == {"done": 1, "total": 3}
    assert step["videos"][0].startswith("/videos/traj")
    step = client.post(url, json={"satisfied": True, "seq": step["seq"]}, headers=headers).json()
    assert step["phase"] == "improve_survey"


def test_improvement_follows_equation_4(engine):
    """The improved trajectory is the study-set argmax of cos(phi' - phi0, psi) (the current one scores 0)."""
    import numpy as np

    phi, psi = engine.space.phi, engine.psi("Move faster.")
    for start in engine.study[:4]:
        got = engine.improve(int(start), "Move faster.")
        scores = [
            0.0
            if j == start
            else (phi[j] - phi[start]) @ psi / (np.linalg.norm(phi[j] - phi[start]) * np.linalg.norm(psi))
            for j in engine.study
        ]
        assert got == int(engine.study[int(np.argmax(scores))])


def test_pages_and_info(client):
    for path in ("/", "/study", "/admin"):
        r = client.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        assert "script-src 'self'" in r.headers["content-security-policy"]
        assert r.text.startswith("<!doctype html>\n") and "{{" not in r.text and "<title>" in r.text  # the shared head
    assert "Sawyer" in client.get("/").text
    assert client.get("/static/study.js").status_code == 200
    info = client.get("/api/info").json()
    assert info["env"] == "metaworld" and info["study"]["pref_queries"] == 4
    assert client.get("/?name=../../etc/passwd").text == client.get("/").text
