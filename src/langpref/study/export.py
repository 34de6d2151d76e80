"""`langpref study export --db study.sqlite --out DIR`: every table as CSV, the paper's analyses as JSON and an HTML
report with PNG figures (Sec. 5.2, Fig. 7-9, Table 1 and Appendix E's time-per-query figure).

    DIR/tables/*.csv     one per database table (token hashes left out)
    DIR/summary.json     the numbers of the report
    DIR/learned_rewards.json  every participant's learned reward per Study-2 method (`langpref.study.learned`)
    DIR/report.html      tables and figures, self-contained apart from the PNGs beside it
    DIR/*.png            study1_attributes, study1_iterations, study2_attributes, study2_ratings, study2_time

Analyses: Study 1 attribute scores and iterations to satisfaction; Study 2 per-attribute scores of both methods, time
per query per method and per participant, the rating curves at every rating point with each method's area under the
curve (trapezoid over the query counts) and paired tests of the areas (t-test and Wilcoxon signed-rank, scipy), the
aspects table (time efficient / convenient / adaptable) and the overall preference.
"""

from __future__ import annotations

import csv
import html
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind
from langpref.study import db as sdb
from langpref.study.config import METHODS
from langpref.study.flow import SURROGATES
from langpref.study.learned import bank_additions, confirmations, confirmations_html, learned_rewards
from langpref.study.surveys import ASPECTS, IMPROVE, METHOD_LABELS, NONE_OF_THEM, PREF_LIKERT

FIGURES = ("study1_attributes", "study1_iterations", "study2_attributes", "study2_ratings", "study2_time")


PRIVATE = {"participants": ("token_sha256", "resume_code", "user_agent")}
"""Columns never exported: credentials (token hash, resume code) and the User-Agent an older version stored."""


def read_tables(conn) -> dict[str, list[dict[str, Any]]]:
    """Every table as a list of rows (dicts), without the `PRIVATE` columns."""
    out = {}
    for table in sdb.TABLES:
        rows = sdb.rows(conn, f"SELECT * FROM {table}")
        for r in rows:
            for col in PRIVATE.get(table, ()):
                r.pop(col, None)
        out[table] = rows
    return out


def _stats(values) -> dict[str, Any]:
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if len(v) == 0:
        return {"mean": None, "std": None, "n": 0}
    return {
        "mean": float(v.mean()),
        "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
        "n": len(v),
        "median": float(np.median(v)),
    }


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


def _survey(tables, survey: str) -> dict[str, dict[str, Any]]:
    """participant -> {question_id: value}."""
    out: dict[str, dict[str, Any]] = {}
    for r in tables["survey_responses"]:
        if r["survey"] == survey:
            out.setdefault(r["participant_id"], {})[r["question_id"]] = stored_value(r["value"])
    return out


def _paired_tests(a: list[float], b: list[float]) -> dict[str, Any]:
    from scipy import stats

    out: dict[str, Any] = {
        "n": len(a),
        "t_statistic": None,
        "t_p_value": None,
        "wilcoxon_statistic": None,
        "wilcoxon_p_value": None,
    }
    if len(a) < 2:
        return out
    diff = np.asarray(a) - np.asarray(b)
    if np.allclose(diff, diff[0]):
        out["note"] = "the differences are all equal; the tests are undefined"
        return out
    t = stats.ttest_rel(a, b)
    out.update(t_statistic=float(t.statistic), t_p_value=float(t.pvalue))
    if np.any(diff != 0):
        w = stats.wilcoxon(a, b)
        out.update(wilcoxon_statistic=float(w.statistic), wilcoxon_p_value=float(w.pvalue))
    return out


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


def analyse(tables: dict[str, list[dict[str, Any]]], exclude: Sequence[str | int] = ()) -> dict[str, Any]:
    """The paper's analyses of a study from its tables (see the module docstring), without the excluded
    participants (`resolve_exclusions`)."""
    excluded = resolve_exclusions(tables["participants"], exclude)
    every = tables["participants"]
    tables = {
        name: [r for r in rows if r.get("participant_id", r.get("id")) not in excluded] if name != "meta" else rows
        for name, rows in tables.items()
    }
    participants = tables["participants"]
    meta = {r["key"]: json.loads(r["value"]) for r in tables["meta"]} if tables.get("meta") else {}
    study = meta.get("study", {})
    max_iter = study.get("improve_max_iterations", 10)
    out: dict[str, Any] = {
        "participants": len(participants),
        "participants_total": len(every),
        "excluded": [
            {"number": p["number"], "participant_id": p["id"], "why": excluded[p["id"]]}
            for p in every
            if p["id"] in excluded
        ],
        "finished": sum(1 for p in participants if p["finished_at"]),
        "method_order": {
            o: sum(1 for p in participants if p["method_order"] == o)
            for o in sorted({p["method_order"] for p in participants})
        },
        "study": study,
        "env": meta.get("env"),
    }

    # ---- Study 1 ----
    improve = _survey(tables, "improve")
    likert = [q for q in IMPROVE if q["type"] == "likert"]
    out["study1_attributes"] = {
        q["id"]: {"text": q["text"], **_stats([a.get(q["id"]) for a in improve.values()])} for q in likert
    }
    out["study1_effective"] = {o: sum(1 for a in improve.values() if a.get("effective") == o) for o in ("Yes", "No")}
    out["study1_iterations_reported"] = {
        o: sum(1 for a in improve.values() if a.get("iterations_to_adapt") == o)
        for o in [str(i) for i in range(1, 11)] + ["It did not adapt"]
    }
    iters: dict[str, int | None] = {}
    by_p: dict[str, list[dict]] = {}
    for r in tables["satisfaction"]:
        by_p.setdefault(r["participant_id"], []).append(r)
    for pid, rs in by_p.items():
        rs.sort(key=lambda r: r["iteration"])
        sat = [r["iteration"] for r in rs if r["satisfied"]]
        if sat:
            iters[pid] = int(sat[0])
        elif rs and rs[-1]["iteration"] >= max_iter:
            iters[pid] = None  # not satisfied within the rounds
    reached = [v for v in iters.values() if v is not None]
    out["study1_iterations_to_satisfaction"] = {
        "per_participant": iters,
        "histogram": {str(i): reached.count(i) for i in range(1, max_iter + 1)},
        "not_satisfied": sum(1 for v in iters.values() if v is None),
        **_stats(reached),
    }

    # ---- Study 2: survey ----
    pref = _survey(tables, "pref")
    attrs: dict[str, Any] = {}
    for stem, item, text, _ in PREF_LIKERT:
        attrs[stem] = {"item": item, "text": text}
        for m in METHODS:
            attrs[stem][m] = _stats([a.get(f"{stem}_{m}") for a in pref.values()])
    means = {m: [attrs[s][m]["mean"] for s, *_ in PREF_LIKERT if attrs[s][m]["mean"] is not None] for m in METHODS}
    overall = {m: (float(np.mean(v)) if v else None) for m, v in means.items()}
    out["study2_attributes"] = attrs
    out["study2_attribute_average"] = {
        **overall,
        "language_vs_comparison_percent": (
            100.0 * (overall["language"] / overall["comparison"] - 1.0)
            if overall["language"] and overall["comparison"]
            else None
        ),
    }
    n_pref = len(pref)
    out["study2_aspects"] = {
        "respondents": n_pref,
        **{
            m: {
                a: sum(1 for x in pref.values() if a in (x.get(f"aspects_{m}") or [])) for a in (*ASPECTS, NONE_OF_THEM)
            }
            for m in METHODS
        },
    }
    out["study2_preference"] = {
        METHOD_LABELS[m]: sum(1 for x in pref.values() if x.get("preferred") == METHOD_LABELS[m]) for m in METHODS
    }

    # ---- Study 2: time per query ----
    # the page's own clock (from the videos playing to the answer) where it agrees with the server's (step handed
    # out -> answer received, at most TIME_TOLERANCE over it); the server's time where it does not, or is missing
    consistent = {(r["participant_id"], r["seq"]): r["time_consistent"] for r in tables["answers"]}
    times: dict[str, dict[str, list[float]]] = {m: {} for m in METHODS}
    sources = {m: {"client_ms": 0, "server_ms": 0} for m in METHODS}
    for m in METHODS:
        for r in sdb.method_rows(tables[get_kind(m).table], m):
            use_client = r["client_ms"] is not None and consistent.get((r["participant_id"], r["seq"])) != 0
            sources[m]["client_ms" if use_client else "server_ms"] += 1
            times[m].setdefault(r["participant_id"], []).append(r["client_ms"] if use_client else r["server_ms"])
    t_out: dict[str, Any] = {}
    for m in METHODS:
        every = [t / 1000.0 for ts in times[m].values() for t in ts]
        t_out[m] = {
            **_stats(every),
            "per_participant_s": {p: float(np.mean(ts) / 1000.0) for p, ts in times[m].items()},
        }
    lm, cm = t_out["language"]["mean"], t_out["comparison"]["mean"]
    t_out["language_less_time_percent"] = 100.0 * (1.0 - lm / cm) if lm and cm else None
    both = sorted(set(times["language"]) & set(times["comparison"]))
    t_out["paired"] = _paired_tests(
        [t_out["language"]["per_participant_s"][p] for p in both],
        [t_out["comparison"]["per_participant_s"][p] for p in both],
    )
    checked = [r for r in tables["answers"] if r["time_consistent"] is not None]
    t_out["client_times_consistent_with_server"] = {
        "checked": len(checked),
        "consistent": sum(r["time_consistent"] for r in checked),
    }
    t_out["source"] = {
        **sources,
        "rule": "the page's time (client_ms) where it is consistent with the server's "
        "clock, else the server's time from handing out the step to receiving the answer (server_ms)",
    }
    out["study2_time_per_query_s"] = t_out

    # ---- Study 2: ratings and their area under the curve ----
    points = sorted({int(r["after_queries"]) for r in tables["ratings"]})
    curves: dict[str, dict[str, dict[int, int]]] = {m: {} for m in METHODS}
    for r in tables["ratings"]:
        curves[r["method"]].setdefault(r["participant_id"], {})[int(r["after_queries"])] = int(r["rating"])
    rating_out: dict[str, Any] = {"points": points}
    aucs: dict[str, dict[str, float]] = {m: {} for m in METHODS}
    for m in METHODS:
        per_point = {str(q): _stats([c.get(q) for c in curves[m].values()]) for q in points}
        for pid, c in curves[m].items():
            if points and all(q in c for q in points):
                ys = [c[q] for q in points]
                aucs[m][pid] = _trapezoid(ys, points)
        rating_out[m] = {"per_point": per_point, "auc": _stats(list(aucs[m].values())), "auc_per_participant": aucs[m]}
    paired = sorted(set(aucs["language"]) & set(aucs["comparison"]))
    rating_out["auc_paired_test"] = _paired_tests(
        [aucs["language"][p] for p in paired], [aucs["comparison"][p] for p in paired]
    )
    out["study2_ratings"] = rating_out
    out["study2_confirmations"] = confirmations(tables, study)
    return _clean(out)


def _trapezoid(ys: list[float], xs: list[int]) -> float:
    """Area under the piecewise-linear curve through (xs, ys); one point: its value."""
    if len(ys) == 1:
        return float(ys[0])
    return float(sum((ys[i] + ys[i + 1]) / 2.0 * (xs[i + 1] - xs[i]) for i in range(len(ys) - 1)))


def _clean(obj: Any) -> Any:
    """JSON-safe: NaN and infinities become None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


# ---- figures -------------------------------------------------------------------------------------------------


def _bar_err(ax, x, stats_list, label=None, width=0.8, offset=0.0, color=None):
    mean = [s["mean"] if s["mean"] is not None else 0.0 for s in stats_list]
    err = [s["std"] if s["std"] is not None else 0.0 for s in stats_list]
    ax.bar(np.asarray(x) + offset, mean, width, yerr=err, capsize=3, label=label, color=color)


def figures(summary: dict[str, Any], out: Path) -> dict[str, str]:
    from langpref.extras import pyplot

    plt = pyplot("the study's figures")

    colors = {"language": "#1f77b4", "comparison": "#ff7f0e"}
    made = {}

    def save(fig, name: str) -> None:
        path = out / f"{name}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        made[name] = path.name

    a1 = summary["study1_attributes"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    _bar_err(ax, range(len(a1)), list(a1.values()), color="#2ca02c")
    ax.set_xticks(range(len(a1)), ["Satisfaction", "Adaptation speed", "Experience"][: len(a1)])
    ax.set_ylim(0, 5.5)
    ax.set_ylabel("score (1-5)")
    ax.set_title("Study 1: attribute scores")
    save(fig, "study1_attributes")

    it = summary["study1_iterations_to_satisfaction"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    keys = list(it["histogram"]) + ["never"]
    ax.bar(range(len(keys)), list(it["histogram"].values()) + [it["not_satisfied"]], color="#2ca02c")
    ax.set_xticks(range(len(keys)), keys)
    ax.set_xlabel("iterations to satisfaction")
    ax.set_ylabel("participants")
    ax.set_title("Study 1: iterations to satisfaction")
    save(fig, "study1_iterations")

    a2 = summary["study2_attributes"]
    fig, ax = plt.subplots(figsize=(6, 3.4))
    x = np.arange(len(a2))
    for k, m in enumerate(METHODS):
        _bar_err(
            ax, x, [a2[s][m] for s in a2], label=METHOD_LABELS[m], width=0.38, offset=(k - 0.5) * 0.4, color=colors[m]
        )
    ax.set_xticks(x, ["Adaptation speed", "Experience", "Noticed learning", "Trust"][: len(a2)])
    ax.set_ylim(0, 5.5)
    ax.set_ylabel("score (1-5)")
    ax.legend(fontsize=8)
    ax.set_title("Study 2: attribute scores")
    save(fig, "study2_attributes")

    r = summary["study2_ratings"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    for m in METHODS:
        pts = [int(q) for q in r["points"]]
        stats_m = [r[m]["per_point"][str(q)] for q in pts]
        mean = np.array([s["mean"] if s["mean"] is not None else np.nan for s in stats_m])
        std = np.array([s["std"] if s["std"] is not None else 0.0 for s in stats_m])
        ax.plot(pts, mean, "o-", color=colors[m], label=METHOD_LABELS[m])
        ax.fill_between(pts, mean - std, mean + std, color=colors[m], alpha=0.2)
    ax.set_xlabel("queries")
    ax.set_ylabel("rating of the best trajectory (1-5)")
    ax.set_ylim(0.5, 5.5)
    ax.legend(fontsize=8)
    ax.set_title("Study 2: ratings")
    save(fig, "study2_ratings")

    t = summary["study2_time_per_query_s"]
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), gridspec_kw={"width_ratios": [3, 1]})
    pids = sorted(set(t["language"]["per_participant_s"]) | set(t["comparison"]["per_participant_s"]))
    x = np.arange(len(pids))
    for k, m in enumerate(METHODS):
        axes[0].bar(
            x + (k - 0.5) * 0.4,
            [t[m]["per_participant_s"].get(p, 0.0) for p in pids],
            0.38,
            color=colors[m],
            label=METHOD_LABELS[m],
        )
    top = max([t[m]["per_participant_s"].get(p, 0.0) for m in METHODS for p in pids] or [1.0])
    axes[0].set_ylim(0, 1.35 * top if top > 0 else 1.0)  # room for the legend
    axes[0].set_xticks(x, [str(i + 1) for i in range(len(pids))])
    axes[0].set_xlabel("participant")
    axes[0].set_ylabel("seconds per query")
    axes[0].legend(fontsize=8, ncol=2, loc="upper left")
    _bar_err(axes[1], range(2), [t[m] for m in METHODS], color=[colors[m] for m in METHODS])
    axes[1].set_xticks(range(2), ["Language", "Comparison"])
    axes[1].set_title("mean")
    fig.suptitle("Study 2: time per query")
    save(fig, "study2_time")
    return made


# ---- report --------------------------------------------------------------------------------------------------


def _fmt(x: Any, digits: int = 2) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return html.escape(str(x))


def _ms(s: dict[str, Any]) -> str:
    return "-" if s.get("mean") is None else f"{s['mean']:.2f} &plusmn; {s['std']:.2f} (n={s['n']})"


def report_html(summary: dict[str, Any], figs: dict[str, str], texts: list[tuple[str, str, str]]) -> str:
    s = summary
    rows = []
    a2 = s["study2_attributes"]
    for v in a2.values():
        rows.append(
            f"<tr><td>{html.escape(v['text'])}</td><td>{_ms(v['language'])}</td><td>{_ms(v['comparison'])}</td></tr>"
        )
    asp = s["study2_aspects"]
    n = asp["respondents"]
    aspect_rows = "".join(
        f"<tr><td>{html.escape(label)}</td><td>{asp['language'][a]} / {n}</td>"
        f"<td>{asp['comparison'][a]} / {n}</td></tr>"
        for a, label in (
            ("Time efficiency", "Time efficient"),
            ("Convenience", "Convenient"),
            ("Adaptability", "Adaptable"),
        )
    )
    r = s["study2_ratings"]
    rating_rows = "".join(
        f"<tr><td>{q}</td><td>{_ms(r['language']['per_point'][str(q)])}</td>"
        f"<td>{_ms(r['comparison']['per_point'][str(q)])}</td></tr>"
        for q in r["points"]
    )
    t = s["study2_time_per_query_s"]
    test = r["auc_paired_test"]
    img = "".join(f'<figure><img src="{html.escape(f)}" alt="{html.escape(k)}"></figure>' for k, f in figs.items())
    text_rows = "".join(
        f"<tr><td>{html.escape(p[:8])}</td><td>{html.escape(q)}</td><td>{html.escape(v)}</td></tr>" for p, q, v in texts
    )
    a1 = s["study1_attributes"]
    it = s["study1_iterations_to_satisfaction"]
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>langpref study report</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto;padding:0 1em}}table{{border-collapse:collapse;
margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;text-align:left}}figure{{display:inline-block;margin:.5em}}
img{{max-width:460px}}</style></head><body>
<h1>Study report</h1>
<p>{s["participants"]} participants ({s["finished"]} finished), env {_fmt(s.get("env"))}; excluded from the
analyses: {len(s["excluded"])}{
        html.escape(" (#" + ", #".join(str(e["number"]) for e in s["excluded"]) + ")") if s["excluded"] else ""
    };
Study-2 orders: {html.escape(json.dumps(s["method_order"]))}.</p>
<h2>Study 1: trajectory improvement</h2>
<table><tr><th>attribute</th><th>score</th></tr>
{"".join(f"<tr><td>{html.escape(v['text'])}</td><td>{_ms(v)}</td></tr>" for v in a1.values())}
</table>
<p>Iterations to satisfaction: mean {_fmt(it.get("mean"))} (n={it.get("n", 0)}), not satisfied within the rounds:
{it["not_satisfied"]}. Effective: {html.escape(json.dumps(s["study1_effective"]))}.</p>
<h2>Study 2: preference learning</h2>
<h3>Attribute scores (1-5)</h3>
<table><tr><th>question</th><th>language</th><th>comparison</th></tr>{"".join(rows)}</table>
<p>Average over attributes: language {_fmt(s["study2_attribute_average"]["language"])}, comparison
{_fmt(s["study2_attribute_average"]["comparison"])} (language higher by
{_fmt(s["study2_attribute_average"]["language_vs_comparison_percent"], 1)}%).</p>
<h3>Satisfactory aspects (not exclusive between methods)</h3>
<table><tr><th></th><th>language</th><th>comparison</th></tr>{aspect_rows}</table>
<p>Overall preference: {html.escape(json.dumps(s["study2_preference"]))}</p>
<h3>Time per query (s)</h3>
<p>Language {_ms(t["language"])}; comparison {_ms(t["comparison"])}; language takes
{_fmt(t["language_less_time_percent"], 1)}% less time. Timing used: the page's clock for
{t["source"]["language"]["client_ms"] + t["source"]["comparison"]["client_ms"]} answers, the server's for
{t["source"]["language"]["server_ms"] + t["source"]["comparison"]["server_ms"]} (where the page's was inconsistent
with it or missing).</p>
{confirmations_html(s["study2_confirmations"], _fmt)}
<h3>Ratings of the best trajectory under the learned reward</h3>
<table><tr><th>queries</th><th>language</th><th>comparison</th></tr>{rating_rows}</table>
<p>Area under the rating curve: language {_ms(r["language"]["auc"])}, comparison {_ms(r["comparison"]["auc"])};
paired t-test p = {_fmt(test["t_p_value"], 4)}, Wilcoxon p = {_fmt(test["wilcoxon_p_value"], 4)}
(n = {test["n"]}).</p>
<h2>Figures</h2>{img}
<h2>Free-text answers</h2>
<table><tr><th>participant</th><th>question</th><th>answer</th></tr>{text_rows}</table>
</body></html>
"""


FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: Any) -> Any:
    """A value as written to a CSV: text a spreadsheet would run as a formula (`=HYPERLINK(...)`, `+`, `-`, `@`, a
    leading tab or carriage return) gets a leading apostrophe, so it shows as the text it is. Numbers stay numbers."""
    if isinstance(value, str) and (value.startswith(FORMULA_START) or value.lstrip().startswith(FORMULA_START[:4])):
        return "'" + value
    return value


def export(
    db_path: str | Path,
    out: str | Path,
    exclude: Sequence[str | int] = (),
    bank_additions_file: str | Path | None = None,
) -> dict[str, Any]:
    """Write the CSVs, summary.json, learned_rewards.json, the figures and report.html of the study in `db_path` into
    `out`; the analyses leave out the participants excluded on the dashboard and those in `exclude` (numbers or ids).
    With `bank_additions_file`, also the confirmed phrasings as a bank file there (`bank_additions`)."""
    from langpref.study.surveys import SURVEYS

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise LangprefError(f"--out {out} is a file; pass a directory (it is created if missing)")
    conn = sdb.open_existing(db_path)
    try:
        tables = read_tables(conn)
        columns = {name: [d[1] for d in conn.execute(f"PRAGMA table_info({name})")] for name in tables}
    finally:
        conn.close()
    summary = analyse(tables, exclude)  # first: a bad --exclude writes nothing
    if bank_additions_file is not None and Path(bank_additions_file).is_dir():
        raise LangprefError(f"--bank-additions {bank_additions_file} is a directory; pass a JSON file to write")
    try:
        (out / "tables").mkdir(parents=True, exist_ok=True)
        for name, rows_ in tables.items():
            # UTF-8 whatever the locale; a character that has none (a lone surrogate) is written as "?"
            with open(out / "tables" / f"{name}.csv", "w", newline="", encoding="utf-8", errors="replace") as fh:
                w = csv.DictWriter(fh, fieldnames=[c for c in columns[name] if c not in PRIVATE.get(name, ())])
                w.writeheader()
                w.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows_)
        figs = figures(summary, out)
        excluded = {e["participant_id"] for e in summary["excluded"]}
        text_ids = {(s, q["id"]) for s, qs in SURVEYS.items() for q in qs if q["type"] == "text"}
        texts = [
            (r["participant_id"], r["question_id"], stored_value(r["value"]))
            for r in tables["survey_responses"]
            if (r["survey"], r["question_id"]) in text_ids
            and json.loads(r["value"])
            and r["participant_id"] not in excluded
        ]
        (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        excluded_ids = resolve_exclusions(tables["participants"], exclude)
        rewards = learned_rewards(tables, excluded_ids)
        (out / "learned_rewards.json").write_text(json.dumps(rewards) + "\n", encoding="utf-8")
        added = None
        if bank_additions_file is not None:
            bank, added = bank_additions(tables, summary.get("env") or "", excluded_ids)
            Path(bank_additions_file).parent.mkdir(parents=True, exist_ok=True)
            Path(bank_additions_file).write_text(json.dumps(bank, indent=2) + "\n", encoding="utf-8")
        (out / "report.html").write_text(report_html(summary, figs, texts), encoding="utf-8", errors="replace")
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
        **(
            {"bank_additions": str(bank_additions_file), "bank_additions_phrasings": added}
            if bank_additions_file is not None
            else {}
        ),
    }
