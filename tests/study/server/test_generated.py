"""Study 1 with generated candidates (`--improve-candidates generated`): each improvement step makes a new trajectory
in the simulator in the background (tiny search budget here), the page's video asks again (503, Retry-After) until
it is made and rendered, the trajectory is stored as a dataset with its row in the database, and a restarted server
makes the one it had not finished and serves the ones it had."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from langpref.errors import LangprefError
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.server.app import create_app
from langpref.study.server.serve import build_state

GENERATED = {"improve_candidates": "generated", "improve_rollouts": 2, "improve_search_generations": 3}


def _post(client, pid, headers, body):
    return client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)


def _video(client, url: str, timeout: float = 120.0) -> bytes:
    """The video at `url`, asking again while it is answered 503 (as the page does)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        r = client.get(url)
        if r.status_code == 200:
            return r.content
        assert r.status_code == 503 and r.headers["Retry-After"], r.text
        time.sleep(0.5)
    raise AssertionError(f"{url} was not made within {timeout} s")


def _close(state) -> None:
    state.generated.close()
    state.videos.close()


def test_study_1_shows_trajectories_made_in_the_simulator_and_a_restart_continues(engine, h, tmp_path):
    from langpref.dataset.storage import load_dataset

    db = tmp_path / "gen.sqlite"
    n = len(engine.dataset)
    state = build_state(h.serve_config(db, **GENERATED), engine=engine, progress=False)
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
            step = _post(client, pid, headers, h.answer_for(step)).json()
            assert (step["phase"], step["kind"]) == ("improve", "language")
            start = step["videos"][0]
            t0 = time.time()
            step = _post(client, pid, headers, h.answer_for(step, "Move faster.")).json()
            assert time.time() - t0 < 5  # the answer does not wait for the simulator
            assert step["kind"] == "satisfaction" and step["previous_video"] == start and not step["unchanged"]
            new = step["videos"][0]
            assert new.startswith("/videos/gen") and new != start
            # the worker is still starting: the video and an answer about it are "come back later", nothing stored
            r = client.get(new)
            assert r.status_code == 503 and "new trajectory" in r.json()["error"] and r.headers["Retry-After"]
            r = _post(client, pid, headers, h.answer_for(step))
            assert r.status_code == 503 and r.headers["Retry-After"]
            assert _video(client, new)[:4] == b"\x1a\x45\xdf\xa3"  # webm (EBML)
            conn = sdb.connect(db)
            made = sdb.rows(conn, "SELECT * FROM generated")
            improved = conn.execute("SELECT improved FROM feedback WHERE phase='improve'").fetchone()[0]
            conn.close()
            assert len(made) == 1 and made[0]["id"] == improved == n and made[0]["round"] == 1
            assert made[0]["store_index"] == 0 and isinstance(made[0]["score"], float)
            step = _post(client, pid, headers, h.answer_for(step)).json()  # not satisfied: another round
            assert step["kind"] == "language" and step["videos"] == [new]
            step = _post(client, pid, headers, h.answer_for(step, "Go up more.")).json()
            second = step["videos"][0]
            assert step["kind"] == "satisfaction" and step["previous_video"] == new and second != new
    finally:
        _close(state)  # stopped before the second trajectory is made
    assert sdb.rows(sdb.connect(db), "SELECT count(*) AS n FROM generated")[0]["n"] == 1

    state = build_state(h.serve_config(db, **GENERATED), engine=engine, progress=False)  # a new server process
    try:
        with TestClient(create_app(state)) as client:
            step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
            assert step["videos"] == [second] and step["previous_video"] == new
            assert client.get(new).status_code == 200  # made before the restart: its video is kept
            _video(client, second)
            step = _post(client, pid, headers, {"satisfied": True, "seq": step["seq"]}).json()
            assert step["kind"] == "survey"
    finally:
        _close(state)
    conn = sdb.connect(db)
    made = sdb.rows(conn, "SELECT id, round, shown, store_index FROM generated ORDER BY id")
    conn.close()
    assert made == [
        {"id": n, "round": 1, "shown": made[0]["shown"], "store_index": 0},
        {"id": n + 1, "round": 2, "shown": n, "store_index": 1},
    ]
    store = load_dataset(f"{db}.generated")
    assert len(store) == 2 and store.split("generated") == [0, 1]
    params = store.load(1).controller_params
    assert params["round"] == 2 and params["study_id"] == n + 1 and len(params["unit"]) > 0


def test_improve_candidates_are_checked_in_one_line():
    with pytest.raises(LangprefError, match="--improve-candidates must be split or generated") as err:
        StudyConfig(improve_candidates="test").validate()
    assert "\n" not in str(err.value)


def test_a_dataset_that_cannot_have_generated_candidates_is_refused_in_one_line(monkeypatch):
    from types import SimpleNamespace

    from langpref.propose import cannot_generate
    from langpref.study.session.generated import check_generation

    even = SimpleNamespace(env="metaworld", root="data/even", meta=SimpleNamespace(lengths=None))
    uneven = SimpleNamespace(env="metaworld", root="data/uneven", meta=SimpleNamespace(lengths=[3, 4]))
    assert cannot_generate(even) is None
    assert cannot_generate(uneven) == "dataset data/uneven has episodes of different lengths"
    monkeypatch.setattr("langpref.dataset.storage.load_dataset", lambda path: uneven)
    with pytest.raises(LangprefError, match="different lengths; drop the option") as err:
        check_generation("data/uneven")
    assert "\n" not in str(err.value)


def test_simulated_participants_answer_generated_trajectories_by_their_features(engine, h, tmp_path, capsys):
    """`langpref study simulate --db DB` beside a server with generated candidates: a synthetic human never satisfied
    (all rounds) and near-greedy in Eq. 10 names, about each generated trajectory, the feature and direction Eq. 10
    picks from that trajectory's own features (the generated dataset's, train-split scaled), and finishes."""
    import json

    import numpy as np

    from langpref.cli import main
    from langpref.dataset.storage import load_dataset
    from langpref.feedback.humans import sample_weights
    from langpref.feedback.space import FeatureScale, phrase_table
    from langpref.language.bank import load_bank
    from langpref.study.server.serve import BackgroundServer

    db = tmp_path / "sim.sqlite"
    state = build_state(h.serve_config(db, **GENERATED), engine=engine, progress=False)
    args = ["--participants", "1", "--seed", "5", "--temperature", "1e-6", "--satisfied-at", "inf", "--json"]
    try:
        with BackgroundServer(state) as url:
            assert main(["study", "simulate", "--url", url, "--db", str(db), "--deadline-s", "300", *args]) == 0
    finally:
        _close(state)
    out = json.loads(capsys.readouterr().out)
    assert out["errors"] == [] and out["completed"] == 1 and out["retries"] > 0  # waited for the simulator

    ds = load_dataset(h.data)  # data and split ("all") came from the database
    conn = sdb.connect(db)
    store_index = {r["id"]: r["store_index"] for r in sdb.rows(conn, "SELECT id, store_index FROM generated")}
    said = sdb.rows(conn, "SELECT shown, text FROM feedback WHERE phase='improve' AND shown >= ?", (len(ds),))
    conn.close()
    rounds = state.cfg.improve_max_iterations
    assert len(store_index) == rounds and len(said) == rounds - 1  # one per round; the last is not spoken of
    feats = np.asarray(ds.features)
    scale = FeatureScale.fit(feats[ds.split("train")])
    w = sample_weights(feats.shape[1], np.random.default_rng([5, 0]))  # participant 0 of seed 5
    best = scale(feats)[np.argmax(scale(feats) @ w)]
    store = load_dataset(f"{db}.generated")
    phrases = phrase_table(load_bank(ds.env), "test", ds.feature_names, lambda t: np.zeros((len(t), 1)))
    for row in said:
        theta = scale(store.features[store_index[row["shown"]]])
        feature = int(np.argmax(w * (best - theta)))  # Eq. 10 at temperature -> 0
        direction = 0 if w[feature] >= 0 else 1
        assert row["text"] in {phrases.texts[i] for i in phrases.rows(feature, direction)}, (row, feature)


def _queue_only():
    """A Generator with its queue and nothing else (no engine, worker or simulator)."""
    import threading
    from collections import deque

    from langpref.study.session.generated import Generator

    g = Generator.__new__(Generator)
    g._cond, g._queue, g._made, g._running, g._known = threading.Condition(), deque(), {}, None, set()
    g._failed, g._retry, g._thread, g._stopped = {}, {}, None, True
    return g


def test_a_later_round_is_made_before_sign_ups_first_feedback():
    """Made-up participants that each give one feedback queue one job each; a participant further into Study 1 is
    not held up behind them, nor is a new participant's first (the queue alone, without a simulator)."""
    from langpref.study.session.generated import Job

    g = _queue_only()
    for k in range(5):
        g.submit(Job(100 + k, f"junk{k}", k, 2, 1, 0, "Move faster."))
    g.submit(Job(200, "real", 9, 6, 3, 0, "Move faster."))
    g.submit(Job(201, "other", 8, 4, 2, 0, "Move faster."))
    g.submit(Job(202, "again", 6, 4, 2, 0, "Move faster."))  # later rounds: in the order of the answers
    g.submit(Job(105, "late", 7, 2, 1, 0, "Move faster."))
    assert [j.id for j in g._queue] == [200, 201, 202, 105, 104, 103, 102, 101, 100]
    assert g.status(200) == ("generating", 0) and g.status(100) == ("generating", 8)


def test_a_new_participants_first_trajectory_comes_next_after_sign_ups_first_feedback():
    """Issue 44: 12 sign-ups that each gave one feedback (48 requests in 0.6 s) made a new participant wait 234 s
    for their first generated trajectory (12 jobs ahead). It is now the next made after the job in flight."""
    from langpref.study.session.generated import Job

    g = _queue_only()
    g._running = Job(99, "first", 1, 2, 1, 0, "Move faster.")
    for k in range(12):
        g.submit(Job(100 + k, f"junk{k}", k, 2, 1, 0, "Move faster."))
    g.submit(Job(300, "new", 20, 2, 1, 0, "Move slower."))
    assert g.status(300) == ("generating", 1)  # only the job in flight ahead of it
    assert {j.id for j in g._queue} == {300, *range(100, 112)}  # the sign-ups' are made later, not dropped
