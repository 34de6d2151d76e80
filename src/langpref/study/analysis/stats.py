"""The paper's analyses of a study (Sec. 5.2, Fig. 7-9, Table 1), from its tables (`tables.read_tables`).

`analyse` gives the summary that `summary.json` holds, section by section: who took part; Study 1's attribute scores
and iterations to satisfaction; Study 2's per-attribute scores of both methods, the aspects table (time efficient /
convenient / adaptable) and the overall preference; time per query per method and per participant; the rating curves
at every rating point with each method's area under the curve (trapezoid over the query counts) and paired tests of
the areas (t-test and Wilcoxon signed-rank, scipy); and the meanings participants were asked to confirm.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from langpref.feedback.kind import get_kind
from langpref.study.analysis.learned import confirmations
from langpref.study.analysis.tables import Tables, resolve_exclusions, survey_answers, without
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import METHODS
from langpref.study.protocol.surveys import ASPECTS, IMPROVE, METHOD_LABELS, NONE_OF_THEM, PREF_LIKERT


def describe(values: Iterable[float | None]) -> dict[str, Any]:
    """Mean, sample std, n and median of the values that are not None (mean and std None when there are none)."""
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if len(v) == 0:
        return {"mean": None, "std": None, "n": 0}
    return {
        "mean": float(v.mean()),
        "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
        "n": len(v),
        "median": float(np.median(v)),
    }


def paired_tests(a: list[float], b: list[float]) -> dict[str, Any]:
    """Paired t-test and Wilcoxon signed-rank test of a against b (None where undefined: n < 2, equal differences,
    or, for Wilcoxon, no difference at all)."""
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


def trapezoid(ys: list[float], xs: list[int]) -> float:
    """Area under the piecewise-linear curve through (xs, ys); one point: its value."""
    if len(ys) == 1:
        return float(ys[0])
    return float(sum((ys[i] + ys[i + 1]) / 2.0 * (xs[i + 1] - xs[i]) for i in range(len(ys) - 1)))


def json_safe(obj: Any) -> Any:
    """JSON-safe: NaN and infinities become None, keys text."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def analyse(tables: Tables, exclude: Sequence[str | int] = ()) -> dict[str, Any]:
    """The paper's analyses of a study from its tables (see the module docstring), without the excluded
    participants (`resolve_exclusions`). The keys keep the order summary.json has always had."""
    excluded = resolve_exclusions(tables["participants"], exclude)
    kept = without(tables, excluded)
    meta = {r["key"]: json.loads(r["value"]) for r in kept["meta"]} if kept.get("meta") else {}
    study = meta.get("study", {})
    out = overview(tables["participants"], excluded, study, meta.get("env"))
    out.update(study1(kept, study.get("improve_max_iterations", 10)))
    out.update(study2_survey(kept))
    out["study2_time_per_query_s"] = time_per_query(kept)
    out["study2_ratings"] = ratings(kept)
    out["study2_confirmations"] = confirmations(kept, study)
    return json_safe(out)


def overview(every: list[dict[str, Any]], excluded: dict[str, str], study: dict, env: str | None) -> dict[str, Any]:
    """Who took part: counts, the excluded with why, the Study-2 orders, the protocol and the env."""
    participants = [p for p in every if p["id"] not in excluded]
    return {
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
        "env": env,
    }


def study1(tables: Tables, max_iter: int) -> dict[str, Any]:
    """Study 1: the survey's attribute scores, whether it was effective, the iterations people reported, and the
    iterations to satisfaction as recorded (None for a participant not satisfied within the rounds)."""
    improve = survey_answers(tables, "improve")
    likert = [q for q in IMPROVE if q["type"] == "likert"]
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
    return {
        "study1_attributes": {
            q["id"]: {"text": q["text"], **describe([a.get(q["id"]) for a in improve.values()])} for q in likert
        },
        "study1_effective": {o: sum(1 for a in improve.values() if a.get("effective") == o) for o in ("Yes", "No")},
        "study1_iterations_reported": {
            o: sum(1 for a in improve.values() if a.get("iterations_to_adapt") == o)
            for o in [str(i) for i in range(1, 11)] + ["It did not adapt"]
        },
        "study1_iterations_to_satisfaction": {
            "per_participant": iters,
            "histogram": {str(i): reached.count(i) for i in range(1, max_iter + 1)},
            "not_satisfied": sum(1 for v in iters.values() if v is None),
            **describe(reached),
        },
    }


def study2_survey(tables: Tables) -> dict[str, Any]:
    """Study 2's questionnaire: per-attribute scores of both methods and their average, the aspects table and the
    overall preference."""
    pref = survey_answers(tables, "pref")
    attrs: dict[str, Any] = {}
    for stem, item, text, _ in PREF_LIKERT:
        attrs[stem] = {"item": item, "text": text}
        for m in METHODS:
            attrs[stem][m] = describe([a.get(f"{stem}_{m}") for a in pref.values()])
    means = {m: [attrs[s][m]["mean"] for s, *_ in PREF_LIKERT if attrs[s][m]["mean"] is not None] for m in METHODS}
    overall = {m: (float(np.mean(v)) if v else None) for m, v in means.items()}
    lang, comp = overall["language"], overall["comparison"]
    return {
        "study2_attributes": attrs,
        "study2_attribute_average": {
            **overall,
            "language_vs_comparison_percent": 100.0 * (lang / comp - 1.0) if lang and comp else None,
        },
        "study2_aspects": {
            "respondents": len(pref),
            **{
                m: {
                    a: sum(1 for x in pref.values() if a in (x.get(f"aspects_{m}") or []))
                    for a in (*ASPECTS, NONE_OF_THEM)
                }
                for m in METHODS
            },
        },
        "study2_preference": {
            METHOD_LABELS[m]: sum(1 for x in pref.values() if x.get("preferred") == METHOD_LABELS[m]) for m in METHODS
        },
    }


def time_per_query(tables: Tables) -> dict[str, Any]:
    """Study 2's seconds per query, per method and per participant, with a paired test of the per-participant means.

    The page's own clock (from the videos playing to the answer) where it agrees with the server's (step handed out
    -> answer received, at most the server's tolerance over it); the server's time where it does not, or is missing.
    """
    consistent = {(r["participant_id"], r["seq"]): r["time_consistent"] for r in tables["answers"]}
    times: dict[str, dict[str, list[float]]] = {m: {} for m in METHODS}
    sources = {m: {"client_ms": 0, "server_ms": 0} for m in METHODS}
    for m in METHODS:
        for r in sdb.method_rows(tables[get_kind(m).table], m):
            use_client = r["client_ms"] is not None and consistent.get((r["participant_id"], r["seq"])) != 0
            sources[m]["client_ms" if use_client else "server_ms"] += 1
            times[m].setdefault(r["participant_id"], []).append(r["client_ms"] if use_client else r["server_ms"])
    out: dict[str, Any] = {}
    for m in METHODS:
        out[m] = {
            **describe([t / 1000.0 for ts in times[m].values() for t in ts]),
            "per_participant_s": {p: float(np.mean(ts) / 1000.0) for p, ts in times[m].items()},
        }
    lm, cm = out["language"]["mean"], out["comparison"]["mean"]
    out["language_less_time_percent"] = 100.0 * (1.0 - lm / cm) if lm and cm else None
    both = sorted(set(times["language"]) & set(times["comparison"]))
    out["paired"] = paired_tests(
        [out["language"]["per_participant_s"][p] for p in both],
        [out["comparison"]["per_participant_s"][p] for p in both],
    )
    checked = [r for r in tables["answers"] if r["time_consistent"] is not None]
    out["client_times_consistent_with_server"] = {
        "checked": len(checked),
        "consistent": sum(r["time_consistent"] for r in checked),
    }
    out["source"] = {
        **sources,
        "rule": "the page's time (client_ms) where it is consistent with the server's "
        "clock, else the server's time from handing out the step to receiving the answer (server_ms)",
    }
    return out


def ratings(tables: Tables) -> dict[str, Any]:
    """Study 2's ratings of the best trajectory: per rating point and method, each participant's area under their
    rating curve (only those rated at every point), and a paired test of the areas."""
    points = sorted({int(r["after_queries"]) for r in tables["ratings"]})
    curves: dict[str, dict[str, dict[int, int]]] = {m: {} for m in METHODS}
    for r in tables["ratings"]:
        if r["method"] not in curves:  # a kind beyond the paper's two, which these analyses compare
            continue
        curves[r["method"]].setdefault(r["participant_id"], {})[int(r["after_queries"])] = int(r["rating"])
    out: dict[str, Any] = {"points": points}
    aucs: dict[str, dict[str, float]] = {m: {} for m in METHODS}
    for m in METHODS:
        per_point = {str(q): describe([c.get(q) for c in curves[m].values()]) for q in points}
        for pid, c in curves[m].items():
            if points and all(q in c for q in points):
                aucs[m][pid] = trapezoid([c[q] for q in points], points)
        out[m] = {"per_point": per_point, "auc": describe(list(aucs[m].values())), "auc_per_participant": aucs[m]}
    paired = sorted(set(aucs["language"]) & set(aucs["comparison"]))
    out["auc_paired_test"] = paired_tests(
        [aucs["language"][p] for p in paired], [aucs["comparison"][p] for p in paired]
    )
    return out
