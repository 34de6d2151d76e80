"""The kinds a study runs are data (`StudyConfig.kinds`): feedback kinds from an installed package (entry-point group
`langpref.feedback`, faked by monkeypatching its entry points as tests/feedback/test_plugins.py does) run through
Study 2 over HTTP with no edit in `langpref.study`: a choice among three shown trajectories and a typed verdict on
one, beside the paper's language. Their pages, answers, storage, replay after a restart and export; a kind's own
active query selection choosing its queries (`langpref.study.protocol.queries`), and a simulated participant answering
with the kind's own synthetic human (`langpref.study.server.simulate`)."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pytest

import langpref.registry
from langpref.errors import LangprefError
from langpref.feedback import KINDS, FeedbackKind, PairBatch, StudyPage, kind
from langpref.reward.batch import Scored
from langpref.reward.selection import Selector

# ---- the fake package: two kinds -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ThreeQuery:
    a: int
    b: int
    c: int


@dataclass(frozen=True)
class ThreeAnswer:
    query: ThreeQuery
    best: int


def _three_pairs(space, answer: ThreeAnswer, cfg, rng) -> PairBatch:
    shown = (answer.query.a, answer.query.b, answer.query.c)
    others = [i for k, i in enumerate(shown) if k != answer.best]
    winner = space.phi[shown[answer.best]]
    return PairBatch(np.stack([winner, winner]), space.phi[others], np.full(2, 0.5))


def _three_parse(value: Any, query: ThreeQuery) -> ThreeAnswer:
    if isinstance(value, bool) or value not in (0, 1, 2):
        raise LangprefError("'best' must be 0, 1 or 2")
    return ThreeAnswer(query, int(value))


def _three_from_record(row: Mapping[str, Any]) -> ThreeAnswer:
    return ThreeAnswer(ThreeQuery(row["a"], row["b"], row["c"]), row["best"])


BEST = FeedbackKind(
    name="best_of_three",
    query=ThreeQuery,
    answer=ThreeAnswer,
    shows=3,
    make_human=lambda *args: None,
    pairs=_three_pairs,
    answer_key="best",
    parse=_three_parse,
    value=lambda answer: answer.best,
    table="triples",
    to_record=lambda ans: {"a": ans.query.a, "b": ans.query.b, "c": ans.query.c, "best": ans.best},
    from_record=_three_from_record,
    page=StudyPage("choice", "Best of three", "Which of the three is best?", "Each query shows three trajectories."),
)


@dataclass(frozen=True)
class VerdictQuery:
    shown: int


@dataclass(frozen=True)
class VerdictAnswer:
    query: VerdictQuery
    text: str


def _verdict_parse(value: Any, query: VerdictQuery) -> VerdictAnswer:
    if not isinstance(value, str) or value.strip().lower() not in ("good", "bad"):
        raise LangprefError("'verdict' must be the word good or bad")
    return VerdictAnswer(query, value.strip().lower())


class _VerdictHuman:
    """Says good of a trajectory whose true reward w . theta is at least the median of its candidates'."""

    def __init__(self, w, space, candidates, cfg, rng):
        self.reward = space.theta @ w
        self.bar = float(np.median(self.reward[np.asarray(candidates)]))

    def answer(self, query: VerdictQuery) -> VerdictAnswer:
        return VerdictAnswer(query, "good" if self.reward[query.shown] >= self.bar else "bad")


def _verdict_pairs(space, answer: VerdictAnswer, cfg, rng) -> PairBatch:
    """good: the shown trajectory beats the mean one; bad: the mean one beats it."""
    shown, mean = space.phi[answer.query.shown][None], space.phi.mean(axis=0)[None]
    winner, loser = (shown, mean) if answer.text == "good" else (mean, shown)
    return PairBatch(winner, loser, np.ones(1))


VERDICT = FeedbackKind(
    name="verdict",
    query=VerdictQuery,
    answer=VerdictAnswer,
    shows=1,
    make_human=_VerdictHuman,
    pairs=_verdict_pairs,
    answer_key="verdict",
    parse=_verdict_parse,
    value=lambda answer: answer.text,
    table="verdicts",
    to_record=lambda ans: {"shown": ans.query.shown, "text": ans.text},
    from_record=lambda row: VerdictAnswer(VerdictQuery(row["shown"]), row["text"]),
    page=StudyPage("text", "Verdict", "Is this trajectory good or bad?", "Type good or bad for each trajectory."),
)
STUDY = ("language", "best_of_three", "verdict")


class _Highest(Selector):
    """`highest`: the trajectory furthest along the first latent axis; it records what the study gave it."""

    name = "highest"
    calls: list[tuple[tuple[int, ...], str]] = []

    def __init__(self, space, pool, reward, candidates, samples):
        self.space = space

    def score_rows(self, learner, rows, rng) -> Scored:
        _Highest.calls.append((tuple(int(r) for r in rows), type(learner).__name__))
        n = len(rows)
        zeros = np.zeros(n, dtype=np.int64)
        gains = self.space.phi[rows, 0]
        return Scored(("picky",), zeros, np.asarray(rows), zeros - 1, gains, self.space.phi[rows], zeros, zeros)


class _Opaque(Selector):
    """A selector the reward loop could run (`score`) but the study cannot (no `score_rows`)."""

    def __init__(self, *args):
        pass


PICKY = {"random": None, "highest": _Highest, "opaque": _Opaque}
"""The strategies of a kind with active selections of its own."""


class _EntryPoint:
    def __init__(self, name: str, load):
        self.name, self.value, self.load = name, f"fake_pkg:{name}", load


@pytest.fixture
def installed(monkeypatch):
    """The fake package's entry points: a kind, a function returning one, and a kind without a study page."""
    eps = [
        _EntryPoint("best_of_three", lambda: BEST),
        _EntryPoint("verdict", lambda: lambda: VERDICT),
        _EntryPoint("pageless", lambda: replace(BEST, name="pageless", table="pageless", page=None)),
        _EntryPoint("picky", lambda: replace(VERDICT, name="picky", strategies=PICKY)),
    ]
    monkeypatch.setattr(langpref.registry, "entry_points", lambda group: eps if group == kind.ENTRY_POINT_GROUP else [])
    monkeypatch.setattr(kind.REGISTRY, "loaded", False)
    yield
    for name in ("best_of_three", "verdict", "pageless", "picky"):
        KINDS.pop(name, None)


def answer(step: dict, h) -> dict:
    """The answer to any step: a widget's (the best is the third; verdict good), else the conftest's."""
    w = step.get("widget")
    if w is None or step["kind"] == "language":
        return h.answer_for(step)
    value = {"choice": 2, "text": "Good"}[w["type"]]
    return {w["answer_key"]: value, "client_ms": 5.0, "seq": step["seq"]}


def walk(client, h, pid: str, headers: dict) -> list[dict]:
    steps = [client.get(f"/api/participants/{pid}/step", headers=headers).json()]
    while steps[-1]["kind"] != "done":
        r = client.post(f"/api/participants/{pid}/answer", json=answer(steps[-1], h), headers=headers)
        assert r.status_code == 200, r.text
        steps.append(r.json())
    return steps


@pytest.fixture
def plugin_state(installed, engine, h, tmp_path):
    from langpref.study.server.serve import build_state

    state = build_state(h.serve_config(tmp_path / "kinds.sqlite", kinds=STUDY), engine=engine, progress=False)
    yield state
    state.videos.close()


@pytest.fixture
def plugin_client(plugin_state):
    from fastapi.testclient import TestClient

    from langpref.study.server.app import create_app

    with TestClient(create_app(plugin_state)) as c:
        yield c


def test_an_installed_kind_is_a_study_kind_and_a_serve_flag(installed):
    from langpref.study.protocol.config import StudyConfig
    from tests.factories import parsers

    cfg = StudyConfig(kinds=["verdict", "best_of_three"])
    cfg.validate()
    assert cfg.kinds == ("verdict", "best_of_three") and StudyConfig().kinds == ("language", "comparison")
    flags = {a.option_strings[0]: a for a in parsers()["study serve"]._actions if a.option_strings}
    assert flags["--kinds"].type("language,best_of_three") == ("language", "best_of_three")
    refused = {
        ("pageless",): "no study page",
        ("nothing",): "unknown feedback 'nothing'",
        ("verdict", "verdict"): "each once",
        ("comparison", "best_of_three", "language", "comparison"): "each once",
    }
    for kinds, message in refused.items():
        with pytest.raises(LangprefError, match=message):
            StudyConfig(kinds=kinds).validate()
    StudyConfig(kinds=("comparison", "picky"), query_selection="comparison=infogain,picky=highest").validate()
    with pytest.raises(LangprefError, match="not defined for verdict"):
        StudyConfig(kinds=("verdict",), query_selection="highest").validate()
    with pytest.raises(LangprefError, match="both store their answers in table 'verdicts'"):
        StudyConfig(kinds=("verdict", "picky"), query_selection="random").validate()
    with pytest.raises(LangprefError, match="each once"):
        StudyConfig(kinds=()).validate()
    with pytest.raises(LangprefError, match="not defined for verdict"):
        StudyConfig(kinds=("verdict",), query_selection="infogain").validate()
    with pytest.raises(LangprefError, match="answer-model reads language and comparison only"):
        StudyConfig(kinds=("best_of_three",), learner="answer-model").validate()


def test_plugin_kinds_run_through_study_2_over_http(plugin_client, plugin_state, h):
    client = plugin_client
    info = client.get("/api/info").json()
    assert info["methods"] == {"language": "Language feedback", "best_of_three": "Best of three", "verdict": "Verdict"}
    assert info["study"]["kinds"] == list(STUDY)
    guidelines = client.get("/").text
    assert "with three methods" in guidelines and "<strong>Best of three:</strong>" in guidelines

    pid, headers = h.join(client)
    steps = walk(client, h, pid, headers)
    phases = list(dict.fromkeys(s["phase"] for s in steps))
    assert phases == ["pre_survey", "improve", "improve_survey", *(f"pref_{k}" for k in STUDY), "pref_survey", "done"]
    for name, n_videos, widget in (("best_of_three", 3, "choice"), ("verdict", 1, "text")):
        queries = [s for s in steps if s["kind"] == name]
        assert [s["number"] for s in queries] == [1, 2, 3, 4] and {s["phase"] for s in queries} == {f"pref_{name}"}
        assert all(len(s["videos"]) == n_videos and s["widget"]["type"] == widget for s in queries)
        assert queries[0]["method_position"] == STUDY.index(name) + 1 and queries[0]["methods"] == 3
        ratings = [s for s in steps if s["kind"] == "rating" and s["phase"] == f"pref_{name}"]
        assert [s["progress"]["done"] for s in ratings] == [2, 4]
        assert ratings[0]["method_label"] == {"best_of_three": "Best of three", "verdict": "Verdict"}[name]
    pref = next(s for s in steps if s["phase"] == "pref_survey")
    ids = {q["id"] for q in pref["questions"]}
    assert {"aspects_best_of_three", "trust_verdict", "aspects_language"} <= ids and "trust_comparison" not in ids
    preferred = next(q for q in pref["questions"] if q["id"] == "preferred")
    assert preferred["options"] == ["Verdict", "Best of three", "Language feedback"]

    conn = plugin_state.connect()
    stored = [json.loads(r[0]) for r in conn.execute("SELECT answer FROM triples ORDER BY seq")]
    assert len(stored) == 4 and all(r["best"] == 2 for r in stored)
    verdicts = [json.loads(r[0]) for r in conn.execute("SELECT answer FROM verdicts")]
    assert len(verdicts) == 4 and all(v["text"] == "good" for v in verdicts)  # as the kind parsed it
    servers = conn.execute("SELECT count(*) FROM verdicts WHERE server_ms >= 0 AND client_ms = 5.0").fetchone()[0]
    assert servers == 4
    rewards = conn.execute("SELECT method, count(*) FROM rewards GROUP BY method ORDER BY method").fetchall()
    assert [tuple(r) for r in rewards] == [("best_of_three", 4), ("language", 4), ("verdict", 4)]


def test_plugin_answers_are_checked_by_their_kind(plugin_client, h):
    client = plugin_client
    client.post("/api/participants", json={})  # the second arrival starts with best_of_three
    pid, headers = h.join(client)
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != "best_of_three":
        step = client.post(f"/api/participants/{pid}/answer", json=answer(step, h), headers=headers).json()
    assert step["method_position"] == 1 and step["phase"] == "pref_best_of_three"
    post = lambda body: client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)  # noqa: E731
    r = post({"best": 3, "client_ms": 1.0})
    assert r.status_code == 400 and r.json() == {"error": "'best' must be 0, 1 or 2"}
    r = post({"verdict": "good", "client_ms": 1.0})
    assert r.status_code == 409 and "best_of_three step, not verdict" in r.json()["error"]
    r = post({"choice": 1, "client_ms": 1.0})  # comparisons are no method of this study
    assert r.status_code == 400 and "'best'" in r.json()["error"]
    assert post({"best": 0}).status_code == 400  # client_ms, as every feedback answer
    assert post({"best": 0, "client_ms": 2.0}).status_code == 200


def test_plugin_answers_replay_after_a_restart_and_export(plugin_client, plugin_state, h, engine, tmp_path):
    from langpref.study.analysis.export import export
    from langpref.study.server.state import StudyApp

    pid, headers = h.join(plugin_client)
    walk(plugin_client, h, pid, headers)
    conn = plugin_state.connect()
    p = plugin_state.participant(conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone())
    fresh = StudyApp(plugin_state.db_path, engine, plugin_state.videos, "x" * 20, plugin_state.cfg)
    for method in ("best_of_three", "verdict"):
        last = conn.execute(
            "SELECT latent_weights FROM rewards WHERE method=? ORDER BY number DESC LIMIT 1", (method,)
        ).fetchone()[0]
        rebuilt = fresh.robot.reward(p, method)["latent_weights"]  # replayed from the stored answers
        assert np.allclose(rebuilt, json.loads(last), atol=1e-6)
    out = export(plugin_state.db_path, tmp_path / "out")
    assert {"tables/triples.csv", "tables/verdicts.csv"} <= set(out["tables"])
    assert (tmp_path / "out" / "tables" / "triples.csv").read_text().count("\n") == 1 + 4


def test_a_plugin_kinds_own_selection_chooses_its_study_queries(installed, engine, h, tmp_path):
    """The kind's `highest` runs in Study 2 as the paper's strategies do: over the study set less what the participant
    already answered about (a query that shows one trajectory), from the participant's learner; each choice stored
    with its score. A strategy whose selector cannot score given rows is refused at start in one line."""
    from langpref.study.protocol import db as sdb
    from langpref.study.server.serve import build_state

    _Highest.calls.clear()
    cfg = h.serve_config(tmp_path / "picky.sqlite", kinds=("language", "picky"), query_selection="picky=highest")
    state = build_state(cfg, engine=engine, progress=False)
    try:
        from fastapi.testclient import TestClient

        from langpref.study.server.app import create_app

        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            steps = walk(client, h, pid, headers)
    finally:
        state.videos.close()
    phi, study = engine.space.phi, np.asarray(engine.study)
    expected = study[np.argsort(-phi[study, 0], kind="stable")][:4].tolist()
    shown = [int(s["videos"][0].split("traj")[1][:6]) for s in steps if s["kind"] == "picky"]
    assert shown == expected
    conn = sdb.connect(tmp_path / "picky.sqlite")
    rows = conn.execute("SELECT number, a, b, strategy, score, candidates FROM queries WHERE method='picky'").fetchall()
    conn.close()
    assert [(r["number"], r["a"], r["b"], r["strategy"]) for r in rows] == [
        (n, a, None, "highest") for n, a in enumerate(expected, start=1)
    ]
    assert [r["score"] for r in rows] == pytest.approx(phi[expected, 0].tolist())
    assert [r["candidates"] for r in rows] == [len(study) - n for n in range(4)]
    for n, (rows_given, learner) in enumerate(_Highest.calls[:4]):
        assert set(rows_given) == set(study.tolist()) - set(expected[:n]) and learner == "RewardLearner"
    with pytest.raises(LangprefError, match="picky=opaque: its selector cannot score the study's candidates"):
        build_state(
            h.serve_config(tmp_path / "opaque.sqlite", kinds=("picky",), query_selection="opaque"),
            engine=engine,
            progress=False,
        )


def test_a_simulated_participant_answers_a_plugin_kind_with_its_own_human(installed, study_data):
    """Given the dataset, it answers with the kind's synthetic human (`make_human`) under its own reward; without it,
    at random by the kind's widget."""
    from langpref.study.protocol.kinds import widget
    from langpref.study.server import simulate as sim

    world = sim._World(study_data, "all")
    p = sim.SimParticipant("http://study.test", sim.SimConfig(), 0, world)
    bar = np.median(p.reward[world.study])
    said = set()
    for row in world.study.tolist():
        step = {"kind": "verdict", "seq": row, "videos": [f"/videos/traj{row:06d}-x.webm"], "widget": widget("verdict")}
        body = p._body(step, time.perf_counter(), [row])
        assert body["verdict"] == ("good" if p.reward[row] >= bar else "bad") and body["seq"] == row
        said.add(body["verdict"])
    assert said == {"good", "bad"}
    blind = sim.SimParticipant("http://study.test", sim.SimConfig(), 0, None)
    three = {"kind": "best_of_three", "seq": 1, "videos": ["a", "b", "c"], "widget": widget("best_of_three")}
    assert {blind._body(three, time.perf_counter(), [])["best"] for _ in range(40)} == {0, 1, 2}
    text = {"kind": "verdict", "seq": 2, "videos": ["a"]}  # no widget in the step: the kind's own
    assert blind._body(text, time.perf_counter(), [])["verdict"] in sim.SAYINGS
