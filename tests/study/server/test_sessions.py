"""Sessions are never lost: a short resume code (on every step and on the dashboard) restores a participant's session
in any browser; the pages never delete the stored token. Unauthenticated requests cost no memory that stays."""

from __future__ import annotations

import gc
import re
import tracemalloc
from pathlib import Path

STATIC = Path(__file__).resolve().parents[3] / "src" / "langpref" / "study" / "static"


def test_resume_code_restores_the_session(client, h, study_state):
    pid, headers = h.join(client)
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    code = step["resume_code"]
    assert re.fullmatch(r"[A-Z2-9]{5}-[A-Z2-9]{5}", code)
    step = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers).json()
    # typed by hand, in lower case, without the dash: the same participant, at the same step, with a new token
    r = client.post("/api/participants/resume", json={"code": code.lower().replace("-", " ")})
    assert r.status_code == 200, r.text
    again = r.json()
    assert again["participant_id"] == pid and again["token"] != headers["X-Participant-Token"]
    new_headers = {"X-Participant-Token": again["token"]}
    assert client.get(f"/api/participants/{pid}/step", headers=new_headers).json() == step
    assert client.get(f"/api/participants/{pid}/step", headers=headers).json() == step  # the old one still works
    # the dashboard shows the code; the export does not
    rows = client.get("/api/admin/participants", headers=h.admin).json()["participants"]
    assert rows[0]["resume_code"] == code
    from langpref.study.analysis.tables import read_tables

    tables = read_tables(study_state.connect())
    assert "resume_code" not in tables["participants"][0] and "participant_tokens" not in tables


def test_wrong_resume_codes_are_refused_and_limited(client, h):
    h.join(client)
    for body in ({"code": "AAAAA-AAAAA"}, {"code": "nope"}, {"code": 5}, {}):
        r = client.post("/api/participants/resume", json=body)
        assert r.status_code == 404 and "resume code" in r.json()["error"]
    statuses = {client.post("/api/participants/resume", json={"code": "BBBBB-BBBBB"}).status_code for _ in range(20)}
    assert 429 in statuses


def test_the_pages_never_delete_the_stored_session():
    pages = sorted(STATIC.glob("study*.js")) + [STATIC / "index.js"]
    assert len(pages) >= 4  # the study page's three scripts and the index page's
    for path in pages:
        js = path.read_text()
        assert "removeItem" not in js and "localStorage.clear" not in js, path.name


def test_unknown_participant_ids_leave_no_memory_behind(client):
    ids = ["x" * 8000 + str(i) for i in range(1000)]
    client.post(f"/api/participants/{ids[0]}/answer", json={"rating": 1})  # warm up
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for pid in ids:
            r = client.post(f"/api/participants/{pid}/answer", json={"rating": 1}, headers={"X-Participant-Token": "t"})
            assert r.status_code == 404
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 1_000_000, grown  # was 8.2 MB: a lock per id, made before the token was checked


def test_a_schema_1_database_gets_resume_codes(tmp_path):
    """A study database of the previous schema is migrated on start: its participants get resume codes."""
    from langpref.study.protocol import db as sdb
    from langpref.study.protocol import schema

    path = tmp_path / "old.sqlite"
    conn = sdb.connect(path)
    for statement in filter(str.strip, schema.MIGRATIONS[1].split(";")):
        conn.execute(statement)
    conn.execute("INSERT INTO meta VALUES ('schema_version', '1')")
    conn.execute(
        "INSERT INTO participants (id, token_sha256, number, method_order, seed, created_at) "
        "VALUES ('p1', 'h', 1, 'language,comparison', 1, 0)"
    )
    conn.close()
    sdb.init_db(path, {})
    conn = sdb.connect(path)
    code, excluded = conn.execute("SELECT resume_code, excluded FROM participants").fetchone()
    assert sdb.normalise_resume_code(code) == code and excluded == 0
    assert sdb.schema_version(conn) == schema.SCHEMA_VERSION
