"""Study 2 with active query selection (`--query-selection`): each query's choice and score are stored and exported,
an active strategy chooses other queries than random's, the same seed chooses the same ones, a restarted server
continues as the running one would have, and a strategy a method does not have is one line at start."""

from __future__ import annotations

import csv
import subprocess
import sys

import pytest
from fastapi.testclient import TestClient

from langpref.errors import LangprefError
from langpref.study.protocol import db as sdb
from langpref.study.protocol import schema
from langpref.study.protocol.config import StudyConfig
from langpref.study.server.app import create_app
from langpref.study.server.serve import build_state

FEEDBACK = ["Move faster.", "Go up more.", "Stay away from the button.", "Slow down.", "Get closer to the button."]


def _state(engine, h, db, **study):
    return build_state(h.serve_config(db, **study), engine=engine, progress=False)


def _answer(client, h, pid, headers, step):
    """A valid answer; the feedback text depends on the step alone (a restarted walk says the same)."""
    body = h.answer_for(step, FEEDBACK[step["seq"] % len(FEEDBACK)])
    r = client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)
    assert r.status_code == 200, r.text
    return r.json()


def _walk(client, h, pid, headers, stop=None):
    """Answer until done, or until the current step satisfies `stop`; that step."""
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != "done" and not (stop and stop(step)):
        step = _answer(client, h, pid, headers, step)
    return step


def _queries(db) -> list[tuple]:
    conn = sdb.connect(db)
    try:
        return [
            (r["method"], r["number"], r["a"], r["b"], r["strategy"], r["score"], r["candidates"])
            for r in conn.execute("SELECT * FROM queries ORDER BY seq")
        ]
    finally:
        conn.close()


def _one_participant(engine, h, db, **study) -> list[tuple]:
    state = _state(engine, h, db, **study)
    try:
        with TestClient(create_app(state)) as client:
            pid, headers = h.join(client)
            assert _walk(client, h, pid, headers)["kind"] == "done"
    finally:
        state.videos.close()
    return _queries(db)


def test_each_query_stores_its_strategy_and_score_and_is_exported(engine, h, tmp_path):
    from langpref.study.analysis.export import export

    db = tmp_path / "info.sqlite"
    rows = _one_participant(engine, h, db, query_selection="infogain")
    n = len(engine.study)
    assert [(m, q) for m, q, *_ in rows] == [(m, q) for m in ("language", "comparison") for q in range(1, 5)]
    for method, number, a, b, strategy, score, candidates in rows:
        assert strategy == "infogain" and isinstance(score, float) and score >= 0
        if method == "language":
            assert b is None and candidates == n - (number - 1)  # never a trajectory it already gave feedback on
        else:
            assert b is not None and a != b and candidates == n * (n - 1) // 2
    assert len({a for m, _, a, *_ in rows if m == "language"}) == 4
    export(db, tmp_path / "out")
    with open(tmp_path / "out" / "tables" / "queries.csv") as fh:
        exported = list(csv.DictReader(fh))
    assert [(r["method"], r["strategy"], float(r["score"])) for r in exported] == [(r[0], r[4], r[5]) for r in rows]


def test_infogain_chooses_other_queries_than_random_and_the_same_with_the_same_seed(engine, h, tmp_path):
    random = _one_participant(engine, h, tmp_path / "random.sqlite")
    first = _one_participant(engine, h, tmp_path / "a.sqlite", query_selection="infogain")
    again = _one_participant(engine, h, tmp_path / "b.sqlite", query_selection="infogain")
    capped = _one_participant(engine, h, tmp_path / "c.sqlite", query_selection="infogain", seed=1, query_candidates=5)
    assert all(r[4] == "random" and r[5] is None for r in random)
    shown = [[r[2:4] for r in rows] for rows in (random, first, again, capped)]
    assert shown[0] != shown[1]
    assert first == again  # the same shows and scores, bit for bit
    assert shown[3] != shown[1]
    assert all(r[6] <= (5 if r[0] == "language" else 10) for r in capped)


def test_a_restarted_server_continues_with_the_same_selections(engine, h, tmp_path):
    study = {"query_selection": "language=lal-infogain,comparison=infogain"}
    straight = _one_participant(engine, h, tmp_path / "straight.sqlite", **study)
    assert {r[4] for r in straight} == {"lal-infogain", "infogain"}
    db = tmp_path / "restarted.sqlite"
    state = _state(engine, h, db, **study)
    with TestClient(create_app(state)) as client:
        pid, headers = h.join(client)
    state.videos.close()
    # new server processes on the same database (no learner in memory), stopped in the middle of each method
    for kind in ("language", "comparison", None):
        state = _state(engine, h, db, **study)
        with TestClient(create_app(state)) as client:
            step = _walk(client, h, pid, headers, kind and (lambda s, k=kind: s["kind"] == k and s["number"] == 3))
            assert step["kind"] == (kind or "done")
        state.videos.close()
    restarted = _queries(db)
    assert [r[:5] for r in restarted] == [r[:5] for r in straight]
    for x, y in zip(restarted, straight):
        assert x[5] == pytest.approx(y[5], rel=1e-4, abs=1e-6)


def test_the_participant_never_sees_why_a_query_was_chosen(engine, h, tmp_path):
    state = _state(engine, h, tmp_path / "blind.sqlite", query_selection="infogain")
    with TestClient(create_app(state)) as client:
        pid, headers = h.join(client)
        step = _walk(client, h, pid, headers, lambda s: s["kind"] == "language" and s["phase"] == "pref_language")
        again = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    state.videos.close()
    assert step == again
    assert not {"selection", "score", "strategy", "candidates"} & set(step)


@pytest.mark.parametrize(
    "value, says",
    [
        ("bogus", "unknown query selection 'bogus'"),
        ("lal-infogain", "not defined for comparison feedback"),
        ("volume-removal", "not defined for language feedback"),
        ("language=volume-removal", "not defined for language feedback"),
        ("robot=infogain", "'robot' is no Study-2 method"),
    ],
)
def test_a_strategy_a_method_does_not_have_is_one_line(value, says):
    with pytest.raises(LangprefError, match=says) as err:
        StudyConfig(query_selection=value).validate()
    assert "\n" not in str(err.value)
    StudyConfig(query_selection="language=lal-infogain,comparison=volume-removal").validate()


def test_serve_refuses_a_bad_strategy_at_start_in_one_line(h, tmp_path):
    args = ["--model", str(h.model), "--data", str(h.data), "--db", str(tmp_path / "x.sqlite")]
    proc = subprocess.run(
        [sys.executable, "-m", "langpref", "study", "serve", *args, "--query-selection", "lal-infogain"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "lal-infogain" in lines[0] and "language=NAME,comparison=NAME" in lines[0], lines
    assert not (tmp_path / "x.sqlite").exists()


def test_a_database_keeps_its_query_selection(engine, h, tmp_path):
    from langpref.study.server.serve import resolve_study_config

    db = tmp_path / "kept.sqlite"
    _state(engine, h, db, query_selection="infogain").videos.close()
    assert resolve_study_config(db, {"query_selection": None}).query_selection == "infogain"
    with pytest.raises(LangprefError, match="--query-selection infogain, not random"):
        resolve_study_config(db, {"query_selection": "random"})


def test_a_schema_2_database_gets_its_shown_queries_as_random(tmp_path):
    path = tmp_path / "old.sqlite"
    conn = sdb.connect(path)
    for v in (1, 2):
        for statement in filter(str.strip, schema.MIGRATIONS[v].split(";")):
            conn.execute(statement)
    conn.execute("INSERT INTO meta VALUES ('schema_version', '2')")
    conn.execute(
        "INSERT INTO participants (id, token_sha256, number, method_order, seed, created_at, resume_code) "
        "VALUES ('p1', 'h', 1, 'language,comparison', 1, 0, 'AAAAA-BBBBB')"
    )
    for seq, phase, kind, shown in (
        (5, "improve", "language", [3]),
        (9, "pref_language", "language", [4]),
        (10, "pref_comparison", "comparison", [1, 2]),
    ):
        payload = f'{{"shown": {shown}, "survey": null, "number": 1, "extra": {{}}}}'
        conn.execute("INSERT INTO steps VALUES ('p1', ?, ?, ?, ?, 0, NULL, NULL)", (seq, phase, kind, payload))
    conn.close()
    sdb.init_db(path, {})
    conn = sdb.connect(path)
    rows = sdb.rows(conn, "SELECT seq, method, a, b, strategy, score FROM queries ORDER BY seq")
    assert sdb.schema_version(conn) == schema.SCHEMA_VERSION
    conn.close()
    assert rows == [
        {"seq": 9, "method": "language", "a": 4, "b": None, "strategy": "random", "score": None},
        {"seq": 10, "method": "comparison", "a": 1, "b": 2, "strategy": "random", "score": None},
    ]


def test_a_study_made_before_the_new_options_continues_with_their_defaults(engine, h, tmp_path):
    """A protocol stored before `query_selection` (and Study 1's generated candidates) existed meant random queries
    and the study set: the study continues, and giving the new options' defaults is no contradiction."""
    import json

    from langpref.study.server.serve import resolve_study_config

    db = tmp_path / "older.sqlite"
    _state(engine, h, db).videos.close()
    conn = sdb.connect(db)
    study = json.loads(conn.execute("SELECT value FROM meta WHERE key='study'").fetchone()[0])
    new = (
        "query_selection",
        "query_candidates",
        "improve_candidates",
        "improve_rollouts",
        "improve_search_generations",
    )
    older = {k: v for k, v in study.items() if k not in new}
    conn.execute("UPDATE meta SET value=? WHERE key='study'", (json.dumps(older),))
    conn.close()
    cfg = resolve_study_config(db, {"query_selection": "random", "improve_candidates": None})
    assert cfg.query_selection == "random" and cfg.improve_candidates == "split"
    _state(engine, h, db).videos.close()
    with pytest.raises(LangprefError, match="--query-selection random, not infogain"):
        resolve_study_config(db, {"query_selection": "infogain"})
