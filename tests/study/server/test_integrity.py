"""What is stored and exported is clean: spreadsheet formulas are neutralised in every CSV, control characters are
refused and bidirectional overrides removed, only the contract's fields are stored, `seq`, when sent, must be the
current step's (an old answer sent again with its seq is not taken), time per query uses the server's timing where the
page's is inconsistent (and says so), and excluded participants (dashboard, `--exclude`) are left out of the
analyses."""

from __future__ import annotations

import csv
import json

import pytest


def to_kind(client, h, pid, headers, kind: str) -> dict:
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != kind:
        step = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers).json()
    return step


def finish(client, h, pid, headers) -> None:
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != "done":
        r = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers)
        assert r.status_code == 200, r.text
        step = r.json()


def test_formulas_are_neutralised_in_every_csv(client, h, study_state, tmp_path):
    from langpref.study.analysis.export import export

    pid, headers = h.join(client)
    step = to_kind(client, h, pid, headers, "language")
    formula = '=HYPERLINK("http://evil.example","x") move faster'
    r = client.post(
        f"/api/participants/{pid}/answer",
        json={"feedback": formula, "client_ms": 3, "seq": step["seq"]},
        headers=headers,
    )
    assert r.status_code == 200, r.text
    export(study_state.db_path, tmp_path / "out")
    risky = ("=", "+", "-", "@", "\t", "\r")
    seen = 0
    for path in (tmp_path / "out" / "tables").glob("*.csv"):
        with open(path, newline="") as fh:
            for row in csv.reader(fh):
                for cell in row:
                    assert not cell.startswith(risky) and not cell.lstrip().startswith(risky[:4]), (path.name, cell)
                    seen += formula in cell
    assert seen >= 1  # the text is kept, as text: '=HYPERLINK(...)
    conn = study_state.connect()
    assert conn.execute("SELECT text FROM feedback").fetchone()[0] == formula  # the database keeps it as typed


def test_csv_cell():
    from langpref.study.analysis.tables import csv_cell

    assert csv_cell("=1+1") == "'=1+1" and csv_cell("  @SUM(A1)") == "'  @SUM(A1)" and csv_cell("\tx") == "'\tx"
    assert csv_cell("-2") == "'-2" and csv_cell(-2) == -2 and csv_cell(1.5) == 1.5 and csv_cell("Move up") == "Move up"


def test_control_characters_refused_bidi_removed_unknown_fields_dropped(client, h, study_state):
    pid, headers = h.join(client)
    step = to_kind(client, h, pid, headers, "language")
    url = f"/api/participants/{pid}/answer"
    for bad in ("Move\x00 faster", "Move \x1b[31mfaster"):
        r = client.post(url, json={"feedback": bad, "client_ms": 3, "seq": step["seq"]}, headers=headers)
        assert r.status_code == 400 and "control characters" in r.json()["error"]
    body = {
        "feedback": "\u202eMove faster.\u202c",
        "client_ms": 3,
        "seq": step["seq"],
        "junk": "j" * 60000,
        "more": {"a": [1, 2]},
    }
    assert client.post(url, json=body, headers=headers).status_code == 200
    conn = study_state.connect()
    assert conn.execute("SELECT text FROM feedback").fetchone()[0] == "Move faster."
    stored = json.loads(conn.execute("SELECT body FROM answers WHERE kind='language'").fetchone()[0])
    assert stored == {"seq": step["seq"], "feedback": "Move faster.", "client_ms": 3.0}


def test_an_old_answer_sent_again_is_not_taken(client, h, study_state):
    pid, headers = h.join(client)
    step = to_kind(client, h, pid, headers, "language")
    url = f"/api/participants/{pid}/answer"
    body = {"feedback": "Move faster.", "client_ms": 3, "seq": step["seq"]}
    nxt = client.post(url, json=body, headers=headers).json()
    nxt = client.post(url, json={"satisfied": False, "seq": nxt["seq"]}, headers=headers).json()
    assert nxt["kind"] == "language"
    conn = study_state.connect()
    before = conn.execute("SELECT count(*) FROM answers").fetchone()[0]
    assert client.post(url, json=body, headers=headers).status_code == 409  # replay with its own seq
    assert conn.execute("SELECT count(*) FROM answers").fetchone()[0] == before


def test_a_client_of_the_design_contract_needs_no_seq(client, h, study_state):
    """docs/design.md's answer bodies carry no `seq`: a client written from the contract alone answers the current
    step."""
    pid, headers = h.join(client)
    step = to_kind(client, h, pid, headers, "language")
    url = f"/api/participants/{pid}/answer"
    nxt = client.post(url, json={"feedback": "Move faster.", "client_ms": 3}, headers=headers)
    assert nxt.status_code == 200 and nxt.json()["seq"] == step["seq"] + 1
    assert client.post(url, json={"satisfied": "yes"}, headers=headers).status_code == 400


def test_time_per_query_uses_server_time_where_the_page_is_inconsistent(client, h, study_state):
    from langpref.study.analysis.stats import analyse
    from langpref.study.analysis.tables import read_tables

    pid, headers = h.join(client)
    step = to_kind(client, h, pid, headers, "comparison")
    url = f"/api/participants/{pid}/answer"
    # a page clock far beyond the server's (a day): inconsistent, so the server's time is used
    r = client.post(url, json={"choice": 0, "client_ms": 86_000_000, "seq": step["seq"]}, headers=headers)
    assert r.status_code == 200
    s = analyse(read_tables(study_state.connect()))
    t = s["study2_time_per_query_s"]
    assert t["source"]["comparison"] == {"client_ms": 0, "server_ms": 1}
    assert t["comparison"]["mean"] < 60  # not the page's 86,000 s
    assert "server" in t["source"]["rule"]


def test_excluded_participants_are_left_out(client, h, study_state, tmp_path):
    from langpref.errors import LangprefError
    from langpref.study.analysis.export import export
    from langpref.study.analysis.stats import analyse
    from langpref.study.analysis.tables import read_tables

    people = [h.join(client) for _ in range(3)]
    for pid, headers in people:
        finish(client, h, pid, headers)
    assert analyse(read_tables(study_state.connect()))["participants"] == 3
    # the dashboard marks #1 as a test participant (admin only; a reason is kept)
    first = people[0][0]
    r = client.post(f"/api/admin/participants/{first}/exclude", json={"excluded": True, "reason": "a test run"})
    assert r.status_code == 401
    r = client.post(
        f"/api/admin/participants/{first}/exclude", json={"excluded": True, "reason": "a test run"}, headers=h.admin
    )
    assert r.status_code == 200, r.text
    rows = client.get("/api/admin/participants", headers=h.admin).json()["participants"]
    assert [p["excluded"] for p in rows] == [True, False, False] and rows[0]["excluded_reason"] == "a test run"
    s = analyse(read_tables(study_state.connect()))
    assert s["participants"] == 2 and s["participants_total"] == 3 and s["excluded"][0]["number"] == 1
    assert s["study2_time_per_query_s"]["language"]["n"] == 2 * 4
    # and #3 on the command line, by number; the tables keep every row
    out = export(study_state.db_path, tmp_path / "out", exclude=["3"])
    assert out["participants"] == 1 and out["excluded"] == 2
    with open(tmp_path / "out" / "tables" / "participants.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 3
    assert "excluded from the\nanalyses: 2" in (tmp_path / "out" / "report.html").read_text()
    with pytest.raises(LangprefError, match="--exclude 99"):
        export(study_state.db_path, tmp_path / "out2", exclude=["99"])
    assert not (tmp_path / "out2").exists()


def test_export_to_an_existing_file_is_one_line(study_state, tmp_path, capsys):
    from langpref.cli import main

    target = tmp_path / "report.txt"
    target.write_text("keep me")
    assert main(["study", "export", "--db", study_state.db_path, "--out", str(target)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "is a file" in err and len(err.splitlines()) == 1
    assert target.read_text() == "keep me"
