"""Ask when unsure (`--confirm-margin`): a Study-2 language answer whose reading is uncertain is followed by a confirm
step; the meaning chosen is what the learner receives (either learner, a rebuilt one too), "none of these" is stored
and not learned from, a malformed confirm body is a one-line 4xx, and the export reports the confirmations and writes
the confirmed phrasings as a file to review (no bank before `bank review`)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from langpref.feedback import LanguageAnswer, LanguageQuery
from langpref.reward.answer_model import AnswerModelLearner
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.flow import Participant
from langpref.study.server.app import create_app
from langpref.study.server.serve import build_state
from langpref.study.session.engine import StudyRobot

TINY = {"split": "all", "improve_max_iterations": 3, "pref_queries": 4, "rating_every": 2, "num_negatives": 5}
TEXTS = ["Move faster.", "Go up more.", "Stay away from the button.", "Slow down.", "Get closer to the button."]


@pytest.fixture
def serve(engine, h, tmp_path):
    states = []

    def start(name="study", **study):
        state = build_state(h.serve_config(tmp_path / f"{name}.sqlite", **study), engine=engine, progress=False)
        states.append(state)
        return state, TestClient(create_app(state))

    yield start
    for state in states:
        state.videos.close()


def _post(client, pid, headers, body):
    return client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)


def _walk(client, h, pid, headers, until, choose=lambda step: step["options"][0]["meaning"]):
    """Answer until `until(step)`; Study-2 language query n says TEXTS[n - 1], confirm steps are answered by
    `choose`."""
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != "done" and not until(step):
        if step["kind"] == "confirm":
            body = {"meaning": choose(step), "seq": step["seq"]}
        else:
            text = TEXTS[(step["number"] - 1) % len(TEXTS)] if step["phase"] == "pref_language" else "Move faster."
            body = h.answer_for(step, text)
        r = _post(client, pid, headers, body)
        assert r.status_code == 200, r.text
        step = r.json()
    return step


def _kinds(db) -> list[tuple[str, str]]:
    conn = sdb.connect(db)
    try:
        return [(r["phase"], r["kind"]) for r in conn.execute("SELECT phase, kind FROM steps ORDER BY seq")]
    finally:
        conn.close()


@pytest.mark.parametrize("margin", [None, 0.0])
def test_without_a_margin_nobody_is_asked(serve, h, tmp_path, margin):
    state, client = serve(confirm_margin=margin)
    with client:
        pid, headers = h.join(client)
        assert _walk(client, h, pid, headers, lambda s: False)["kind"] == "done"
    assert ("pref_language", "confirm") not in _kinds(state.db_path)


def test_a_margin_of_one_asks_after_every_study2_language_answer(serve, h):
    state, client = serve(confirm_margin=1.0)
    with client:
        pid, headers = h.join(client)
        step = _walk(client, h, pid, headers, lambda s: s["kind"] == "confirm")
        again = client.get(f"/api/participants/{pid}/step", headers=headers).json()
        assert step == again and step["phase"] == "pref_language" and step["videos"] == []
        assert step["said"] == "Move faster." and step["progress"]["done"] == step["number"] - 1
        options = step["options"]
        assert len(options) == 4 and options[-1] == {"meaning": None, "text": "none of these"}
        meanings = state.engine.meanings
        for o in options[:3]:
            feature, direction = meanings.feature(o["meaning"]), meanings.direction(o["meaning"])
            assert o["text"].endswith(f" ({feature}, {direction})")
        assert not {"margin", "confirm", "p"} & set(step)  # what the model's reading says stays on the server
        assert _walk(client, h, pid, headers, lambda s: False)["kind"] == "done"
    kinds = _kinds(state.db_path)
    assert kinds.count(("pref_language", "confirm")) == 4  # one per query of Study 2, none in Study 1
    assert ("improve", "confirm") not in kinds
    i = kinds.index(("pref_language", "confirm"))
    assert kinds[i - 1] == ("pref_language", "language")


def test_the_margin_decides_who_is_asked(engine):
    p = Participant("p", 1, ("language", "comparison"), 1)
    texts = [*TEXTS, "Hmm, not like that.", "Better.", "Faster and lower."]
    answers = [LanguageAnswer(LanguageQuery(int(engine.study[0])), t) for t in texts]
    margins = [engine.meanings.margin(engine.meanings.reading(engine.psi(a.text))) for a in answers]
    lo, hi = min(margins), max(margins)
    assert hi > lo
    cut = (lo + hi) / 2
    robot = StudyRobot(engine, lambda pid, m: [], cfg=StudyConfig(**TINY, confirm_margin=cut))
    for a, m in zip(answers, margins):
        asked = robot.confirm(p, "language", a)
        assert (asked is not None) == (m < cut)
        if asked is not None:
            assert asked["margin"] == pytest.approx(m, abs=1e-4) and len(asked["options"]) == 3
            ps = [o["p"] for o in asked["options"]]
            assert ps == sorted(ps, reverse=True) and ps[0] - ps[1] == pytest.approx(m, abs=2e-4)


@pytest.mark.parametrize("learner", ["paper", "answer-model"])
def test_the_confirmed_meaning_is_what_the_learner_receives(serve, h, learner):
    state, client = serve(name=learner, confirm_margin=1.0, learner=learner)
    with client:
        pid, headers = h.join(client)
        step = _walk(client, h, pid, headers, lambda s: s["kind"] == "confirm")
        second = step["options"][1]["meaning"]  # not the model's top reading
        r = _post(client, pid, headers, {"meaning": second, "seq": step["seq"]})
        assert r.status_code == 200, r.text
    conn = state.connect()
    shown = conn.execute("SELECT shown FROM feedback WHERE phase='pref_language' AND number=1").fetchone()[0]
    row = dict(conn.execute("SELECT * FROM confirmations").fetchone())
    meanings = state.engine.meanings
    assert (row["meaning"], row["rank"], row["text"], row["shown"]) == (second, 2, "Move faster.", shown)
    assert (row["feature"], row["direction"]) == (meanings.feature(second), meanings.direction(second))
    p = state.participant(conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone())
    kept = state.robot._learners[(pid, "language")][0]
    rebuilt = StudyRobot(state.engine, state._history, cfg=state.cfg, confirmations=state._confirmations)
    again = rebuilt._learner(p, "language", 1)
    for x in (kept, again):
        if learner == "answer-model":
            assert isinstance(x, AnswerModelLearner)
            reading = x.answers[-1][2]
            assert reading[second] == 1.0 and reading.sum() == 1.0
        else:  # the answer's pairs with psi the bank's mean psi of the confirmed meaning
            winners = x.batches[-1].winners
            np.testing.assert_allclose(winners[0], state.engine.space.phi[shown] + meanings.psi[second])
    if learner == "answer-model":
        np.testing.assert_array_equal(kept.v, again.v)
    reward = conn.execute("SELECT number, learner FROM rewards ORDER BY seq").fetchall()
    assert [tuple(r) for r in reward] == [(1, learner)]


def test_none_of_these_is_stored_and_not_learned_from(serve, h):
    state, client = serve(confirm_margin=1.0, learner="answer-model")
    with client:
        pid, headers = h.join(client)
        step = _walk(client, h, pid, headers, lambda s: s["kind"] == "confirm")
        before = state.robot._learners.get((pid, "language"))
        r = _post(client, pid, headers, {"meaning": None, "seq": step["seq"]})
        assert r.status_code == 200, r.text
        assert r.json()["kind"] == "language" and r.json()["number"] == 2
    learner, seen, _ = state.robot._learners[(pid, "language")]
    assert seen == 1 and len(learner.answers) == 0  # counted as answered, learned nothing
    assert before is None or before[0] is learner
    conn = state.connect()
    row = dict(conn.execute("SELECT * FROM confirmations").fetchone())
    assert row["meaning"] is None and row["rank"] is None and row["feature"] is None and row["text"] == "Move faster."
    assert conn.execute("SELECT count(*) FROM feedback WHERE phase='pref_language'").fetchone()[0] == 1
    p = state.participant(conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone())
    rebuilt = StudyRobot(state.engine, state._history, cfg=state.cfg, confirmations=state._confirmations)
    assert len(rebuilt._learner(p, "language", 1).answers) == 0


@pytest.mark.parametrize(
    "body, status",
    [
        ({"meaning": "fast"}, 400),
        ({"meaning": 999}, 400),
        ({"meaning": True}, 400),
        ({"meaning": 1.5}, 400),
        ({"meaning": [0]}, 400),
        ({"seq": 0}, 400),
        ({"feedback": "Move faster.", "client_ms": 1.0}, 409),
        ({"meaning": None, "choice": 1}, 400),
    ],
)
def test_a_malformed_confirm_body_is_a_one_line_4xx(serve, h, body, status):
    state, client = serve(confirm_margin=1.0)
    with client:
        pid, headers = h.join(client)
        step = _walk(client, h, pid, headers, lambda s: s["kind"] == "confirm")
        r = _post(client, pid, headers, {**body, "seq": step["seq"]} if "seq" not in body else body)
        assert r.status_code == status, r.text
        assert list(r.json()) == ["error"] and "\n" not in r.json()["error"]
        assert client.get(f"/api/participants/{pid}/step", headers=headers).json() == step
    assert state.connect().execute("SELECT count(*) FROM confirmations").fetchone()[0] == 0


def test_the_export_reports_confirmations_and_writes_bank_additions(serve, h, tmp_path):
    from langpref.errors import LangprefError
    from langpref.language.bank import load_user_utterances
    from langpref.study.analysis.export import export

    state, client = serve(confirm_margin=1.0)
    picks = iter([0, 3, 1, 0])  # option positions: the top reading, none of these, the second, the top
    chosen = []

    def choose(step):
        o = step["options"][next(picks)]
        chosen.append((step["said"], o["meaning"]))
        return o["meaning"]

    started = time.time()
    with client:
        pid, headers = h.join(client)
        assert _walk(client, h, pid, headers, lambda s: False, choose)["kind"] == "done"
    took = time.time() - started
    bank_file = tmp_path / "review" / "additions.json"
    out = export(state.db_path, tmp_path / "out", bank_additions_file=bank_file)
    assert out["bank_additions_phrasings"] == len({(t, m) for t, m in chosen if m is not None})
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())["study2_confirmations"]
    assert summary["margin"] == 1.0 and summary["asked"] == summary["answered"] == summary["language_answers"] == 4
    assert summary["chosen_rank"] == {"1": 2, "2": 1} and summary["none_of_these"] == 1
    assert summary["per_participant"][pid] == {"asked": 4, "answered": 4, "none_of_these": 1}
    assert summary["time_s"]["n"] == 4 and 0 < summary["time_s"]["mean"] < took  # each confirm, shown to answered
    raw = json.loads(bank_file.read_text())
    env = state.engine.env
    assert (raw["format"], raw["task"]) == ("langpref-bank-additions/1", env)
    assert raw["source"]["db"] == str(Path(state.db_path).resolve()) and raw["source"]["participants"] == 1
    meanings = state.engine.meanings
    got = {(a["text"], a["feature"], a["direction"]): a for a in raw["additions"]}
    for text, meaning in chosen:
        if meaning is None:  # each query said another text: "none of these" adds nothing
            assert all(t != text for t, _, _ in got)
            continue
        a = got[(text, meanings.feature(meaning), meanings.direction(meaning))]
        assert a["count"] == 1 and a["participants"] == [1] and a["accept"] is None
        (c,) = a["confirmations"]
        assert c["participant"] == 1 and c["method"] == "language" and 0 <= c["margin"] <= 1 and c["rank"] in (1, 2)
    with pytest.raises(LangprefError, match="not reviewed"):  # no reader takes it as a bank before the review
        load_user_utterances(bank_file, env)
    report = (tmp_path / "out" / "report.html").read_text()
    assert "Asked what they meant" in report


def test_a_margin_outside_0_to_1_is_one_line():
    from langpref.errors import LangprefError

    for bad in (-0.1, 1.5, "x", True):
        with pytest.raises(LangprefError, match="--confirm-margin must be a number from 0 to 1") as err:
            StudyConfig(confirm_margin=bad).validate()
        assert "\n" not in str(err.value)
