"""Simulated participants (`langpref.study.server.simulate`) against a scripted server (httpx's MockTransport, no
sockets): an answer refused with 503 is sent again after exactly the Retry-After it named (never past the deadline), a
503 without one is an error, and a generated trajectory without the server's database is one clear error."""

from __future__ import annotations

import json
import time

import httpx
import pytest

from langpref.study.server import simulate as sim

DONE = {"kind": "done", "videos": [], "seq": 2}


def scripted(monkeypatch, step: dict, answers: list[httpx.Response]) -> list[dict]:
    """Every participant's client talks to a server that hands out `step`, then answers each POSTed answer with the
    next of `answers`; the bodies posted."""
    posted: list[dict] = []

    def handle(request: httpx.Request) -> httpx.Response:
        path = request.url.path
        if path == "/api/participants":
            return httpx.Response(200, json={"participant_id": "p1", "token": "t"})
        if path.endswith("/step"):
            return httpx.Response(200, json=step)
        if path.endswith("/answer"):
            posted.append(json.loads(request.content))
            return answers[len(posted) - 1]
        return httpx.Response(404, json={"error": "not found"})

    monkeypatch.setattr(httpx, "HTTPTransport", lambda **kw: httpx.MockTransport(handle))
    return posted


def participant(world=None, **cfg) -> tuple[sim.SimParticipant, list[float]]:
    """A simulated participant whose pauses are recorded, not slept."""
    p = sim.SimParticipant("http://study.test", sim.SimConfig(**cfg), 0, world)
    pauses: list[float] = []
    p.pause = pauses.append
    return p, pauses


def test_an_answer_refused_with_503_is_sent_again_after_its_retry_after(monkeypatch):
    busy = [httpx.Response(503, json={"error": "not yet"}, headers={"Retry-After": s}) for s in ("2", "0.5")]
    posted = scripted(monkeypatch, {"kind": "rating", "videos": [], "seq": 1}, [*busy, httpx.Response(200, json=DONE)])
    p, pauses = participant()
    p.run(stop_at=time.time() + 60)
    assert p.errors == [] and p.answers == 1 and p.retries == 2
    assert pauses == [2.0, 0.5]  # as long as the server asked, no longer
    assert len(posted) == 3 and posted[0] == posted[1] == posted[2] and posted[0]["seq"] == 1


def test_a_retry_never_waits_past_the_deadline_and_a_bare_503_is_an_error(monkeypatch):
    long = httpx.Response(503, json={"error": "not yet"}, headers={"Retry-After": "3600"})
    scripted(monkeypatch, {"kind": "rating", "videos": [], "seq": 1}, [long, httpx.Response(503, json={"e": 1})])
    p, pauses = participant()
    p.run(stop_at=time.time() + 30)
    assert len(pauses) == 1 and 0 < pauses[0] <= 30
    assert p.answers == 0 and p.errors and p.errors[0].startswith("503")


def test_a_generated_trajectory_without_the_servers_database_is_a_clear_error(monkeypatch, study_data):
    world = sim._World(study_data, "all")
    video = f"/videos/gen{len(world.dataset):06d}-0123456789.webm"
    posted = scripted(monkeypatch, {"kind": "satisfaction", "videos": [video], "seq": 1}, [])
    p, _ = participant(world)
    p.run(stop_at=time.time() + 30)
    assert posted == [] and len(p.errors) == 1
    assert "generated" in p.errors[0] and "--db" in p.errors[0]


def test_the_study_of_a_database_names_its_dataset_and_split(tmp_path):
    from langpref.errors import LangprefError
    from langpref.study.protocol import db as sdb

    db = tmp_path / "s.sqlite"
    sdb.init_db(db, {"data": "/data/mw", "study": {"split": "all"}})
    assert sim.study_of(db) == {"data": "/data/mw", "split": "all"}
    with pytest.raises(LangprefError, match="does not exist"):
        sim.study_of(tmp_path / "missing.sqlite")
