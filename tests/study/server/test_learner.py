"""Study 2 with either reward learner (`--learner paper|answer-model`): the answer-model learner takes language and
comparisons over HTTP and chooses its infogain queries under its own model, a learner rebuilt from the database
chooses the next query as the running one would, and the export holds every participant's learned reward."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

from langpref.errors import LangprefError
from langpref.reward.answer_model import AnswerModelLearner
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.server.app import create_app
from langpref.study.server.serve import build_state
from langpref.study.session.engine import StudyRobot

FEEDBACK = ["Move faster.", "Go up more.", "Stay away from the button.", "Slow down.", "Get closer to the button."]


def _answer(client, h, pid, headers, step):
    body = h.answer_for(step, FEEDBACK[step["seq"] % len(FEEDBACK)])
    r = client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)
    assert r.status_code == 200, r.text
    return r.json()


def _walk(client, h, pid, headers, stop=None):
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != "done" and not (stop and stop(step)):
        step = _answer(client, h, pid, headers, step)
    return step


def _participant(state, pid):
    row = state.connect().execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone()
    return state.participant(row)


def test_the_answer_model_learner_answers_language_and_comparisons_with_its_own_infogain(engine, h, tmp_path):
    db = tmp_path / "am.sqlite"
    state = build_state(
        h.serve_config(db, learner="answer-model", query_selection="infogain"), engine=engine, progress=False
    )
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            assert _walk(client, h, pid, headers)["kind"] == "done"
            learners = {m: state.robot._learners[(pid, m)][0] for m in ("language", "comparison")}
    finally:
        state.videos.close()
    assert all(isinstance(x, AnswerModelLearner) and len(x.answers) == 4 for x in learners.values())
    conn = sdb.connect(db)
    queries = sdb.rows(conn, "SELECT method, number, a, b, strategy, score FROM queries ORDER BY seq")
    rewards = sdb.rows(conn, "SELECT * FROM rewards ORDER BY seq")
    conn.close()
    assert [(q["method"], q["number"]) for q in queries] == [
        (m, n) for m in ("language", "comparison") for n in (1, 2, 3, 4)
    ]
    assert all(q["strategy"] == "infogain" and q["score"] >= 0 for q in queries)
    assert len({q["a"] for q in queries if q["method"] == "language"}) == 4  # never the same trajectory twice
    # the scores are the learner's own: mutual information under its answer model, at most log(2F) / log(2) nats
    assert max(q["score"] for q in queries if q["method"] == "language") <= np.log(len(engine.meanings)) + 1e-9
    assert max(q["score"] for q in queries if q["method"] == "comparison") <= np.log(2) + 1e-9
    assert [(r["method"], r["number"], r["learner"]) for r in rewards] == [
        (m, n, "answer-model") for m in ("language", "comparison") for n in (1, 2, 3, 4)
    ]
    last = json.loads(rewards[3]["feature_weights"])
    assert set(last) <= set(engine.space.feature_names) and len(last) == len(learners["language"].features)
    np.testing.assert_allclose(list(last.values()), learners["language"].mean())


def test_a_rebuilt_answer_model_learner_chooses_the_same_next_query(engine, h, tmp_path):
    db = tmp_path / "restart.sqlite"
    state = build_state(
        h.serve_config(db, learner="answer-model", query_selection="infogain"), engine=engine, progress=False
    )
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            for method in ("language", "comparison"):
                step = _walk(client, h, pid, headers, lambda s, m=method: s["kind"] == m and s["number"] == 4)
                assert step["kind"] == method
                p = _participant(state, pid)
                kept = state.robot._learners[(pid, method)][0]
                # a new server process on the same database: no learner in memory
                restarted = StudyRobot(state.engine, state._history, cfg=state.cfg)
                shown, _ = state.current_step(state.connect(), pid)
                chosen = restarted.query(p, method, 4)
                assert chosen.shown == shown.shown and chosen.record() == shown.selection
                rebuilt = restarted._learners[(pid, method)][0]
                assert rebuilt is not kept and len(rebuilt.answers) == len(kept.answers) == 3
                np.testing.assert_array_equal(rebuilt.v, kept.v)
                np.testing.assert_array_equal(rebuilt.log_weights, kept.log_weights)
                assert restarted.best(p, method) == state.robot.best(p, method)
                _answer(client, h, pid, headers, step)
    finally:
        state.videos.close()


@pytest.mark.parametrize("learner", ["paper", "answer-model"])
def test_the_export_holds_every_participants_learned_reward(engine, h, tmp_path, learner):
    from langpref.study.analysis.export import export

    db = tmp_path / f"{learner}.sqlite"
    state = build_state(h.serve_config(db, learner=learner), engine=engine, progress=False)
    try:
        with TestClient(create_app(state)) as client:
            pids = []
            for _ in range(2):
                pid, headers = h.join(client)
                assert _walk(client, h, pid, headers)["kind"] == "done"
                pids.append(pid)
            admin = client.get("/api/admin/export", headers=h.admin).json()["learned_rewards"]
            best = {
                (pid, m): state.robot.best(_participant(state, pid), m)
                for pid in pids
                for m in ("language", "comparison")
            }
    finally:
        state.videos.close()
    out = export(db, tmp_path / "out")
    saved = json.loads((tmp_path / "out" / "learned_rewards.json").read_text())
    assert out["learned_rewards"].endswith("learned_rewards.json") and saved == admin
    assert saved["learner"] == learner and len(saved["rewards"]) == 4
    study = sorted(int(i) for i in engine.study)
    phi = engine.space.phi
    for r in saved["rewards"]:
        assert r["learner"] == learner and r["after_answers"] == 4 and not r["excluded"]
        assert sorted(r["ranking"]) == study and r["ranking"][0] == best[(r["participant_id"], r["method"])]
        xi = np.asarray(r["latent_weights"])
        assert xi.shape == (engine.space.dim,) and np.abs(xi).max() > 0
        scores = phi[r["ranking"]] @ xi  # an outside analysis scores the study set with xi . phi
        assert np.all(np.diff(scores) <= 1e-6 * max(1.0, np.abs(scores).max()))
        if learner == "answer-model":
            assert set(r["feature_weights"]) <= set(engine.space.feature_names) and r["feature_weights"]
        else:
            assert r["feature_weights"] is None
    _the_export_takes_the_rewards_to_the_robot(engine, out, saved, tmp_path, learner)


def _the_export_takes_the_rewards_to_the_robot(engine, out, saved, tmp_path, learner):
    """The export's answers.jsonl holds every answer, and each participant's reward (and a pooled one per method)
    is a saved reward `langpref.reward.load` takes, equal to the learner's state after their last answer."""
    from langpref.cli import main
    from langpref.reward import load

    lines = [json.loads(line) for line in (tmp_path / "out" / "answers.jsonl").read_text().splitlines()]
    assert out["num_answers"] == len(lines) == 16
    assert {(a["participant"], a["kind"]) for a in lines} == {
        (p, k) for p in ("P1", "P2") for k in ("language", "comparison")
    }
    assert len(out["rewards"]) == 4 and [p["method"] for p in out["pooled"]] == ["language", "comparison"]
    xi_of = {(f"P{r['number']}", r["method"]): r["latent_weights"] for r in saved["rewards"]}
    traj = engine.dataset.load(int(engine.study[0]))
    for entry in out["rewards"]:
        reward = load(entry["path"])
        xi = xi_of[(entry["participant"], entry["method"])]
        assert reward.task == engine.env and np.allclose(reward.params["xi"], xi)
        value = reward.trajectory_reward(traj.observations, traj.actions)
        assert np.isclose(value, engine.space.phi[int(engine.study[0])] @ np.asarray(xi), rtol=1e-4, atol=1e-6)
        assert set(reward.doc["wants"]["features"]) == set(engine.space.feature_names)
    for entry in out["pooled"]:
        assert load(entry["path"]).doc["learned_from"]["participants"] == ["P1", "P2"] and entry["answers"] == 8
    # the answers file is what learn-reward --answers reads
    argv = ["learn-reward", "--model", saved["model"], "--data", saved["data"], "--learner", learner]
    answers = str(tmp_path / "out" / "answers.jsonl")
    assert main([*argv, "--answers", answers, "--feedback", "mixed", "--participant", "P2", "--json"]) == 0


@pytest.mark.parametrize(
    "study, says",
    [
        ({"learner": "bayes"}, "--learner must be paper or answer-model"),
        ({"learner": "answer-model", "query_selection": "language=lal-infogain"}, "not lal-infogain"),
        ({"learner": "answer-model", "query_selection": "comparison=volume-removal"}, "not volume-removal"),
    ],
)
def test_a_learner_it_does_not_know_or_cannot_ask_with_is_one_line(study, says):
    with pytest.raises(LangprefError, match=says) as err:
        StudyConfig(**study).validate()
    assert "\n" not in str(err.value)
    StudyConfig(learner="answer-model", query_selection="infogain").validate()


def test_a_database_made_before_the_learner_option_continues_with_the_papers(engine, h, tmp_path):
    from langpref.study.server.serve import resolve_study_config

    db = tmp_path / "older.sqlite"
    build_state(h.serve_config(db), engine=engine, progress=False).videos.close()
    conn = sdb.connect(db)
    study = json.loads(conn.execute("SELECT value FROM meta WHERE key='study'").fetchone()[0])
    study.pop("learner"), study.pop("confirm_margin")
    conn.execute("UPDATE meta SET value=? WHERE key='study'", (json.dumps(study),))
    conn.close()
    cfg = resolve_study_config(db, {"learner": None, "confirm_margin": None})
    assert cfg.learner == "paper" and cfg.confirm_margin is None
    build_state(h.serve_config(db), engine=engine, progress=False).videos.close()  # it continues
    with pytest.raises(LangprefError, match="--learner paper, not answer-model"):
        resolve_study_config(db, {"learner": "answer-model"})


@pytest.mark.parametrize("learner", ["paper", "answer-model"])
def test_good_as_it_is_is_a_study2_answer_and_not_a_study1_one(engine, h, tmp_path, learner):
    """ "That's good, no change" (`{"feedback": {"no_change": true}}`): refused where Study 1 asks how to change, taken
    in Study 2 without the feedback gate (which refuses typed praise), stored as its text, and read back from the
    database as the same answer: the answer model's own meaning, no pairs for Eq. 9."""
    from langpref.language.bank import NO_CHANGE_FEEDBACK

    db = tmp_path / f"{learner}.sqlite"
    state = build_state(h.serve_config(db, learner=learner), engine=engine, progress=False)
    good = {"no_change": True}
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            url = f"/api/participants/{pid}/answer"
            step = _walk(client, h, pid, headers, lambda s: s["kind"] == "language")
            assert step["phase"] == "improve"
            r = client.post(url, json={"feedback": good, "client_ms": 5, "seq": step["seq"]}, headers=headers)
            assert r.status_code == 400 and "satisfied" in r.json()["error"]
            step = _walk(client, h, pid, headers, lambda s: s["kind"] == "language" and s["phase"] == "pref_language")
            for bad in ({"no_change": False}, {"no_change": True, "text": "x"}, ["no_change"]):
                r = client.post(url, json={"feedback": bad, "client_ms": 5, "seq": step["seq"]}, headers=headers)
                assert r.status_code == 400 and "no_change" in r.json()["error"], r.text
            r = client.post(url, json={"feedback": good, "client_ms": 5, "seq": step["seq"]}, headers=headers)
            assert r.status_code == 200, r.text
            assert r.json()["understood"]["no_change"] is True
            kept = state.robot._learners[(pid, "language")][0]
            rebuilt = StudyRobot(state.engine, state._history, cfg=state.cfg)._learner(
                _participant(state, pid), "language", 1
            )
    finally:
        state.videos.close()
    conn = sdb.connect(db)
    text = conn.execute("SELECT text FROM feedback WHERE phase = 'pref_language'").fetchone()["text"]
    conn.close()
    assert text == NO_CHANGE_FEEDBACK
    from langpref.study.analysis.export import export

    export(db, tmp_path / "export")  # the answer with no reading of a feature exports like any other
    assert NO_CHANGE_FEEDBACK in (tmp_path / "export" / "tables" / "feedback.csv").read_text()
    if learner == "answer-model":
        for x in (kept, rebuilt):
            assert x.answers[-1][2][x.no_change] == 1.0  # its own meaning, not a reading of the text
    else:
        assert [len(b.weights) for b in kept.batches] == [0] == [len(b.weights) for b in rebuilt.batches]


def test_no_change_typed_as_people_type_it_is_the_no_change_answer(engine, h, tmp_path):
    """Typed in lower case it was read as a feature and learned; with a phone's apostrophe the feedback gate refused
    it. Both are the no-change answer, stored as its canonical text, as the button's."""
    from langpref.language.bank import NO_CHANGE_FEEDBACK

    typed = ["that's good, no change.", "That\u2019s good, no change.", "  \u201cTHAT\u2019S GOOD, NO CHANGE\u201d "]
    db = tmp_path / "typed.sqlite"
    state = build_state(h.serve_config(db, learner="answer-model"), engine=engine, progress=False)
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            for text in typed:
                step = _walk(
                    client, h, pid, headers, lambda s: s["phase"] == "pref_language" and s["kind"] == "language"
                )
                body = {"feedback": text, "client_ms": 5, "seq": step["seq"]}
                r = client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)
                assert r.status_code == 200, r.text
                assert r.json()["understood"]["no_change"] is True
            learner = state.robot._learners[(pid, "language")][0]
    finally:
        state.videos.close()
    assert [a[2][learner.no_change] for a in learner.answers] == [1.0] * len(typed)
    conn = sdb.connect(db)
    texts = [r["text"] for r in conn.execute("SELECT text FROM feedback WHERE phase = 'pref_language' ORDER BY seq")]
    conn.close()
    assert texts == [NO_CHANGE_FEEDBACK] * len(typed)
