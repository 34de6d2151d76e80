"""`langpref study export --db study.sqlite --out DIR`: every table as CSV, the paper's analyses as JSON and an HTML
report with PNG figures (Sec. 5.2, Fig. 7-9, Table 1 and Appendix E's time-per-query figure).

    DIR/tables/*.csv     one per database table (token hashes left out)
    DIR/summary.json     the numbers of the report
    DIR/learned_rewards.json  every participant's learned reward per Study-2 method (`langpref.study.analysis.learned`)
    DIR/answers.jsonl    every Study-2 answer, DIR/rewards/ every participant's reward
    (`langpref.study.analysis.rewards`) DIR/report.html      tables and figures, self-contained apart from the PNGs
    beside it DIR/*.png            study1_attributes, study1_iterations, study2_attributes, study2_ratings, study2_time,
                         and study2_rewards (what each participant's reward wants) where the rewards were written

The work is done in `langpref.study.analysis` (tables, stats, figures, report); this module writes it to disk.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.study.analysis.figures import FIGURES, figures, rewards_figure
from langpref.study.analysis.learned import bank_additions, learned_rewards
from langpref.study.analysis.report import report_html
from langpref.study.analysis.rewards import write_study_rewards
from langpref.study.analysis.stats import analyse
from langpref.study.analysis.tables import free_texts, read_tables, resolve_exclusions, table_columns, write_csvs
from langpref.study.protocol import db as sdb

__all__ = ["FIGURES", "export"]


def export(
    db_path: str | Path,
    out: str | Path,
    exclude: Sequence[str | int] = (),
    bank_additions_file: str | Path | None = None,
    force: bool = False,
    model: str | Path | None = None,
) -> dict[str, Any]:
    """Write the CSVs, summary.json, learned_rewards.json, the figures and report.html of the study in `db_path` into
    `out`; the analyses leave out the participants excluded on the dashboard and those in `exclude` (numbers or ids).
    With `bank_additions_file`, also the confirmed phrasings as a file to review there (`bank_additions`; no bank
    reader takes it before `langpref bank review`): an existing file
    only with `force`, and never the database itself (or its journal) nor a file the export writes. Also the answers
    and rewards of `langpref.study.analysis.rewards` (its model: `model`, else where the study ran)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise LangprefError(f"--out {out} is a file; pass a directory (it is created if missing)")
    if bank_additions_file is not None:
        _check_bank_additions(Path(bank_additions_file), Path(db_path), out, force)
    conn = sdb.open_existing(db_path)
    try:
        tables = read_tables(conn)
        columns = table_columns(conn, tables)
    finally:
        conn.close()
    summary = analyse(tables, exclude)  # first: a bad --exclude writes nothing
    excluded = resolve_exclusions(tables["participants"], exclude)
    added = None
    try:
        write_csvs(tables, columns, out / "tables")
        figs = figures(summary, out)
        (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        rewards = learned_rewards(tables, excluded)
        (out / "learned_rewards.json").write_text(json.dumps(rewards) + "\n", encoding="utf-8")
        if bank_additions_file is not None:
            added = _write_bank_additions(tables, summary.get("env") or "", excluded, db_path, bank_additions_file)
        taken = write_study_rewards(tables, out, excluded, model)
        wanted = _wanted(taken.get("rewards", []))
        drawn = rewards_figure(wanted, out)
        if drawn:
            figs["study2_rewards"] = drawn
        report = report_html(summary, figs, free_texts(tables, excluded), wanted)
        (out / "report.html").write_text(report, encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LangprefError(f"cannot write the export into {out} ({exc.strerror or exc}); pass another --out") from None
    return {
        "out": str(out),
        "report": str(out / "report.html"),
        "summary": str(out / "summary.json"),
        "learned_rewards": str(out / "learned_rewards.json"),
        "tables": sorted(f"tables/{t}.csv" for t in tables),
        "figures": sorted(figs.values()),
        "participants": summary["participants"],
        "finished": summary["finished"],
        "excluded": len(summary["excluded"]),
        **taken,
        **(added or {}),
    }


def _wanted(rewards: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each written participant reward (`write_study_rewards`) with what it wants, read back from its saved file
    (method, participant, wants); those saved without it (the study's dataset gone) are left out."""
    out = []
    for entry in rewards:
        wants = json.loads(Path(entry["path"]).read_text(encoding="utf-8")).get("wants")
        if wants:
            out.append({"method": entry["method"], "participant": entry["participant"], "wants": wants})
    return out


def _write_bank_additions(tables: dict, env: str, excluded, db_path: str | Path, file: str | Path) -> dict[str, Any]:
    """Write the bank additions file for the lab's review (`bank_additions`); what the export says of it."""
    bank, added = bank_additions(tables, env, excluded, str(Path(db_path).resolve()))
    Path(file).parent.mkdir(parents=True, exist_ok=True)
    Path(file).write_text(json.dumps(bank, indent=2) + "\n", encoding="utf-8")
    flagged = sum(bool(a["flags"]) for a in bank["additions"])
    return {"bank_additions": str(file), "bank_additions_phrasings": added, "bank_additions_flagged": flagged}


def _same_file(a: Path, b: Path) -> bool:
    """Whether `a` and `b` name one file: the same path once resolved, or (hard links) the same inode."""
    if a.resolve() == b.resolve():
        return True
    try:
        return a.samefile(b)
    except OSError:  # either is missing
        return False


def _check_bank_additions(path: Path, db_path: Path, out: Path, force: bool) -> None:
    """Refuse, before anything is read or written, a `--bank-additions` file that would overwrite the database being
    read (or its SQLite journal), a file of the export itself, or (without `force`) any existing file."""
    guarded = [db_path.with_name(db_path.name + suffix) for suffix in ("", "-wal", "-shm", "-journal")]
    if any(_same_file(path, g) for g in guarded):
        raise LangprefError(f"--bank-additions {path} is the study database {db_path}; pass another JSON file")
    if path.is_dir():
        raise LangprefError(f"--bank-additions {path} is a directory; pass a JSON file to write")
    own = {"summary.json", "learned_rewards.json", "answers.jsonl", "report.html", "export.config.json"}
    own |= {f"{n}.png" for n in (*FIGURES, "study2_rewards")}
    out_dir = out.resolve()
    where = path.resolve()
    inside = {out_dir / "tables", out_dir / "rewards"} & set(where.parents)
    if (where.parent == out_dir and where.name in own) or inside:
        raise LangprefError(f"--bank-additions {path} is a file of the export in {out}; pass another JSON file")
    if path.exists() and not force:
        raise LangprefError(f"--bank-additions {path} already exists; pass --force to overwrite it or another file")
