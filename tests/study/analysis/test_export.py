"""`langpref study export`: CSV of every table, the paper's analyses as JSON, an HTML report with PNG figures."""

from __future__ import annotations

import csv
import json
import sqlite3

import numpy as np
import pytest

from langpref.study.protocol import db as sdb
from langpref.study.protocol import schema


@pytest.fixture(scope="module")
def simulated_db(engine, h, tmp_path_factory):
    """Four simulated participants (synthetic humans) through the real HTTP server."""
    from langpref.study.server.serve import BackgroundServer, build_state
    from langpref.study.server.simulate import SimConfig, simulate

    db = tmp_path_factory.mktemp("export") / "study.sqlite"
    state = build_state(h.serve_config(db), engine=engine, progress=False)
    with BackgroundServer(state) as url:
        result = simulate(url, SimConfig(participants=4, seed=1), data_dir=h.data, split="all")
    assert result["completed"] == 4, result["errors"]
    return db


def test_export_writes_tables_report_and_figures(simulated_db, tmp_path):
    from langpref.study.analysis.export import FIGURES, export

    out = export(simulated_db, tmp_path / "out")
    assert out["participants"] == 4 and out["finished"] == 4
    for table in schema.TABLES:
        with open(tmp_path / "out" / "tables" / f"{table}.csv") as fh:
            rows = list(csv.DictReader(fh))
        # generated: Study 1 with --improve-candidates generated; confirmations: Study 2 with --confirm-margin
        assert rows or table in ("meta", "generated", "confirmations")
        assert "token_sha256" not in (rows[0] if rows else {})
    with open(tmp_path / "out" / "tables" / "answers.csv") as fh:
        answers = list(csv.DictReader(fh))
    conn = sqlite3.connect(simulated_db)
    assert len(answers) == conn.execute("SELECT count(*) FROM answers").fetchone()[0]
    for name in FIGURES:
        assert (tmp_path / "out" / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Study 1" in html and "Area under the rating curve" in html and "study2_ratings.png" in html


def test_summary_holds_the_papers_analyses(simulated_db, tmp_path):
    from langpref.study.analysis.export import export

    export(simulated_db, tmp_path / "out")
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["participants"] == 4 and s["method_order"] == {"comparison,language": 2, "language,comparison": 2}
    assert set(s["study2_attributes"]) == {"adapt_speed", "experience", "noticed_learning", "trust"}
    for attr in s["study2_attributes"].values():
        assert attr["language"]["n"] == 4 and 1 <= attr["language"]["mean"] <= 5
    assert s["study2_ratings"]["points"] == [2, 4]
    for m in ("language", "comparison"):
        assert s["study2_ratings"][m]["auc"]["n"] == 4
        assert all(1 <= v <= 5 * 2 for v in s["study2_ratings"][m]["auc_per_participant"].values())
        assert s["study2_time_per_query_s"][m]["n"] == 16  # 4 participants x 4 queries
    test = s["study2_ratings"]["auc_paired_test"]
    # the paired test of the participants' own areas (language against comparison), as scipy computes it
    from scipy import stats

    lang, comp = (s["study2_ratings"][m]["auc_per_participant"] for m in ("language", "comparison"))
    a, b = [lang[p] for p in sorted(lang)], [comp[p] for p in sorted(lang)]
    assert test["n"] == 4 and sorted(lang) == sorted(comp)
    if np.allclose(np.subtract(a, b), a[0] - b[0]):
        assert "note" in test and test["t_p_value"] is None
    else:
        assert test["t_p_value"] == pytest.approx(stats.ttest_rel(a, b).pvalue)
    aspects = s["study2_aspects"]
    assert aspects["respondents"] == 4 and set(aspects["language"]) >= {
        "Time efficiency",
        "Convenience",
        "Adaptability",
    }
    assert sum(s["study2_preference"].values()) == 4
    it = s["study1_iterations_to_satisfaction"]
    assert len(it["per_participant"]) == 4 and it["not_satisfied"] + it["n"] == 4
    checked = s["study2_time_per_query_s"]["client_times_consistent_with_server"]
    assert checked["checked"] > 0 and checked["consistent"] == checked["checked"]


def test_paired_test_matches_scipy():
    from scipy import stats

    from langpref.study.analysis.stats import paired_tests

    a, b = [10.0, 12.0, 9.0, 14.0, 11.0], [8.0, 11.0, 9.5, 10.0, 7.0]
    got = paired_tests(a, b)
    assert got["t_p_value"] == pytest.approx(stats.ttest_rel(a, b).pvalue)
    assert got["wilcoxon_p_value"] == pytest.approx(stats.wilcoxon(a, b).pvalue)
    assert paired_tests([1.0], [2.0])["t_p_value"] is None


def test_cli_export_and_its_errors(simulated_db, tmp_path, capsys):
    from langpref.cli import main

    assert main(["study", "export", "--db", str(simulated_db), "--out", str(tmp_path / "o"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["participants"] == 4 and out["report"].endswith("report.html")
    assert main(["study", "export", "--db", str(tmp_path / "missing.sqlite"), "--out", str(tmp_path / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err
    other = tmp_path / "other.sqlite"
    sqlite3.connect(other).execute("CREATE TABLE t (x)").connection.commit()
    assert main(["study", "export", "--db", str(other), "--out", str(tmp_path / "y")]) == 2
    assert "schema version" in capsys.readouterr().err


def test_a_stored_lone_surrogate_does_not_stop_the_export(simulated_db, tmp_path):
    """A server before issue 31 stored `"3\\ud800"` (JSON-escaped) from a survey answer: the export still writes
    every file, the character shown as U+FFFD."""
    from langpref.study.analysis.export import export

    db = tmp_path / "bad.sqlite"
    conn = sqlite3.connect(db)
    with sqlite3.connect(simulated_db) as src:  # a copy of the WAL database as it reads
        src.backup(conn)
    with conn:
        n = conn.execute(
            "UPDATE survey_responses SET value=? WHERE survey='pre' AND question_id='age'", ('"3\\ud800"',)
        ).rowcount
    conn.close()
    assert n == 4
    out = export(db, tmp_path / "out")
    assert out["participants"] == 4
    html = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    assert "Study 1" in html and "3\ufffd" in html
    with open(tmp_path / "out" / "tables" / "survey_responses.csv", encoding="utf-8") as fh:
        assert sum('"3\\ud800"' in r["value"] for r in csv.DictReader(fh)) == 4  # the table as stored


@pytest.fixture
def empty_db(tmp_path):
    """A study database with no participants yet (the export of it is quick)."""
    db = tmp_path / "study.sqlite"
    sdb.init_db(db, {"env": "button-press"})
    return db


def test_bank_additions_never_overwrite_the_database(empty_db, tmp_path, capsys):
    """`--bank-additions study.sqlite` once wrote the bank over the database being read (every answer lost), with
    exit 0: the database, under any name that reaches it, is refused with one line, `--force` or not."""
    from langpref.cli import main

    before = empty_db.read_bytes()
    (tmp_path / "link.sqlite").symlink_to(empty_db)
    (tmp_path / "hard.sqlite").hardlink_to(empty_db)
    names = [str(empty_db), str(tmp_path / "link.sqlite"), str(tmp_path / "hard.sqlite"), f"{empty_db}-wal"]
    names.append(str(tmp_path / "sub" / ".." / "study.sqlite"))
    for name in names:
        for force in ([], ["--force"]):
            argv = ["study", "export", "--db", str(empty_db), "--out", str(tmp_path / "o"), "--bank-additions", name]
            assert main([*argv, *force]) == 2, name
            err = capsys.readouterr().err.strip()
            assert "is the study database" in err and "\n" not in err
    assert empty_db.read_bytes() == before
    assert not (tmp_path / "o").exists()  # refused before anything is written


def test_bank_additions_overwrite_an_existing_file_only_with_force(empty_db, tmp_path, capsys):
    from langpref.cli import main

    bank = tmp_path / "additions.json"
    bank.write_text("the lab's edits\n")
    argv = ["study", "export", "--db", str(empty_db), "--out", str(tmp_path / "o"), "--bank-additions", str(bank)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "already exists" in err and "--force" in err and "\n" not in err
    assert bank.read_text() == "the lab's edits\n"
    assert main([*argv, "--force", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["bank_additions"] == str(bank)
    assert json.loads(bank.read_text())  # the (empty) additions, in the bank's schema
    # nor a file the export itself writes, even new
    for name in ("summary.json", "tables/answers.csv"):
        argv = ["study", "export", "--db", str(empty_db), "--out", str(tmp_path / "p")]
        assert main([*argv, "--bank-additions", str(tmp_path / "p" / name), "--force"]) == 2
        assert "a file of the export" in capsys.readouterr().err


def test_the_report_shows_each_figure_in_its_section_linked_and_captioned(simulated_db, tmp_path):
    """Each figure sits in its section as a PNG beside report.html, linked at full size, with what it shows; with
    the participants' rewards written, also what each one wants, drawn and in words."""
    from html import escape

    from langpref.study.analysis.export import export
    from langpref.study.analysis.figures import CAPTIONS

    out = export(simulated_db, tmp_path / "out")
    html = (tmp_path / "out" / "report.html").read_text()
    for name in out["figures"]:
        stem = name.removesuffix(".png")
        caption = escape(CAPTIONS[stem].split(":")[0])
        assert f'<a href="{name}"><img src="{name}"' in html and caption in html, name
        assert (tmp_path / "out" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert html.index("study2_ratings.png") > html.index("Ratings of the best trajectory")
    assert "Other figures" not in html
    # the study's model and dataset are where it ran: each participant's reward is written, and what it wants drawn
    assert len(out["rewards"]) == 8 and "study2_rewards.png" in out["figures"]
    assert "What each learned reward wants" in html and html.count("; the features explain") == 8
