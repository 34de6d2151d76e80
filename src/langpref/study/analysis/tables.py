"""A study's database as tables of rows, and those rows as CSV files.

`read_tables` reads every table (credentials never leave: `PRIVATE`), `resolve_exclusions` says who is left out of
the analyses, `survey_answers` and `free_texts` read the questionnaires, `write_csvs` writes one CSV per table with
spreadsheet formulas defused (`csv_cell`).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.study.protocol import db as sdb
from langpref.study.protocol import schema
from langpref.study.protocol.flow import SURROGATES

Tables = dict[str, list[dict[str, Any]]]
"""Table name -> its rows, each a dict of column -> value."""

PRIVATE = {"participants": ("token_sha256", "resume_code", "user_agent")}
"""Columns never exported: credentials (token hash, resume code) and the User-Agent an older version stored."""

FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def read_tables(conn) -> Tables:
    """Every table as a list of rows (dicts), without the `PRIVATE` columns; the tables of kinds beyond the paper's
    (`langpref.study.protocol.db.kind_tables`) after the schema's."""
    out = {}
    for table in (*schema.TABLES, *sdb.kind_tables(conn)):
        rows = sdb.rows(conn, f"SELECT * FROM {table}")
        for r in rows:
            for col in PRIVATE.get(table, ()):
                r.pop(col, None)
        out[table] = rows
    return out


def table_columns(conn, names: Collection[str]) -> dict[str, list[str]]:
    """Each table's columns in the schema's order (the CSV header, also for a table without rows)."""
    return {name: [d[1] for d in conn.execute(f"PRAGMA table_info({name})")] for name in names}


def stored_value(text: str) -> Any:
    """A stored answer value (JSON), its text made writable: a lone surrogate (which the server took before issue
    31) becomes U+FFFD, so one bad row cannot stop the export."""
    return _writable(json.loads(text))


def _writable(value: Any) -> Any:
    if isinstance(value, str):
        return SURROGATES.sub("\ufffd", value)
    if isinstance(value, list):
        return [_writable(v) for v in value]
    return value


def survey_answers(tables: Tables, survey: str) -> dict[str, dict[str, Any]]:
    """One survey's answers: participant -> {question_id: value}."""
    out: dict[str, dict[str, Any]] = {}
    for r in tables["survey_responses"]:
        if r["survey"] == survey:
            out.setdefault(r["participant_id"], {})[r["question_id"]] = stored_value(r["value"])
    return out


def free_texts(tables: Tables, excluded: Collection[str]) -> list[tuple[str, str, str]]:
    """Every non-empty answer to a free-text survey question, as (participant, question, text), in stored order,
    without the `excluded` participants (the report's last table)."""
    from langpref.study.protocol.surveys import SURVEYS

    text_ids = {(s, q["id"]) for s, qs in SURVEYS.items() for q in qs if q["type"] == "text"}
    return [
        (r["participant_id"], r["question_id"], stored_value(r["value"]))
        for r in tables["survey_responses"]
        if (r["survey"], r["question_id"]) in text_ids
        and json.loads(r["value"])
        and r["participant_id"] not in excluded
    ]


def resolve_exclusions(participants: list[dict[str, Any]], given: Sequence[str | int] = ()) -> dict[str, str]:
    """Participants left out of the analyses: id -> why. Those marked on the dashboard, and `given` (arrival numbers,
    ids, or id prefixes of 8 or more characters as the dashboard shows them); an unknown one is an error."""
    out = {
        p["id"]: f"excluded on the dashboard: {p.get('excluded_reason') or 'no reason given'}"
        for p in participants
        if p.get("excluded")
    }
    for item in given:
        text = str(item).strip().rstrip("\u2026")
        if text.isdigit():
            found = [p for p in participants if int(p["number"]) == int(text)]
        else:
            found = [p for p in participants if len(text) >= 8 and p["id"].startswith(text)]
        if len(found) != 1:
            raise LangprefError(
                f"--exclude {item}: no single participant has this number or id (prefix of 8+ "
                "characters); see the dashboard or tables/participants.csv"
            )
        out.setdefault(found[0]["id"], "excluded on the command line (--exclude)")
    return out


def without(tables: Tables, excluded: Collection[str]) -> Tables:
    """The tables without the rows of the `excluded` participants (`meta` whole: it belongs to no one)."""
    return {
        name: [r for r in rows if r.get("participant_id", r.get("id")) not in excluded] if name != "meta" else rows
        for name, rows in tables.items()
    }


def csv_cell(value: Any) -> Any:
    """A value as written to a CSV: text a spreadsheet would run as a formula (`=HYPERLINK(...)`, `+`, `-`, `@`, a
    leading tab or carriage return) gets a leading apostrophe, so it shows as the text it is. Numbers stay numbers."""
    if isinstance(value, str) and (value.startswith(FORMULA_START) or value.lstrip().startswith(FORMULA_START[:4])):
        return "'" + value
    return value


def write_csvs(tables: Tables, columns: dict[str, list[str]], out: Path) -> None:
    """One CSV per table in `out`, headed by its `columns` less the `PRIVATE` ones."""
    out.mkdir(parents=True, exist_ok=True)
    for name, rows in tables.items():
        # UTF-8 whatever the locale; a character that has none (a lone surrogate) is written as "?"
        with open(out / f"{name}.csv", "w", newline="", encoding="utf-8", errors="replace") as fh:
            w = csv.DictWriter(fh, fieldnames=[c for c in columns[name] if c not in PRIVATE.get(name, ())])
            w.writeheader()
            w.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows)
