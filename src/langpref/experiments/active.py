"""`langpref experiment active --env ENV`: active queries against random ones, for language and for comparisons.

Language x {random (the paper's), lal-infogain (the authors' follow-up), infogain (ours: the latent Eq. 10 answer
model, `langpref.feedback.selection`)} and comparisons x {random, infogain (mutual information), volume-removal},
10 synthetic humans x 3 seeds, Q = 40, the same learner (Eq. 9 / Bradley-Terry, L-BFGS, L2 prior) for all: only what
is shown differs. Writes into its output directory (default `results/active/ENV`): `active.json` (curves and
summaries per method, per-run AUCs, paired 95% intervals between strategies, the targets of issue 21 checked, the
config), `active.png` (cross-entropy and true reward of the best test trajectory per query), `active.md` (a section
for docs/results.md) and `runs.json` (finished runs; an interrupted experiment resumes).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from langpref.experiments.common import SweepConfig, figure_link
from langpref.experiments.reward import _run_methods, _save, _table, paired_difference, plot_reward_curves

METHODS = {
    "language-random": ("language", None),
    "language-lal-infogain": ("language", "lal-infogain"),
    "language-infogain": ("language", "infogain"),
    "comparison-random": ("comparison", None),
    "comparison-infogain": ("comparison", "infogain"),
    "comparison-volume-removal": ("comparison", "volume-removal"),
}
"""Method name -> (feedback, query selection); None is random."""
OURS, LAL, LANG_RANDOM = "language-infogain", "language-lal-infogain", "language-random"
CONTRASTS = (
    (OURS, LANG_RANDOM),
    (OURS, LAL),
    (LAL, LANG_RANDOM),
    (OURS, "comparison-infogain"),
    ("comparison-infogain", "comparison-random"),
    ("comparison-volume-removal", "comparison-random"),
)
"""Paired differences reported (first minus second)."""


def _per_run(runs: dict, method: str, keys: list[str], key: str, upto: int | None = None) -> np.ndarray:
    """(runs, 1): each run's mean of curve `key` over query counts 0..upto (all when None)."""
    return np.array([[float(np.mean(runs[f"{method}/{k}"][key][: None if upto is None else upto + 1]))] for k in keys])


def _interval(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    d = paired_difference(a, b)
    return {k: float(v[0]) for k, v in d.items()}


def run_active_experiment(
    env: str,
    data=None,
    model=None,
    out=None,
    *,
    perfect: bool = False,
    config=None,
    humans: int | None = None,
    seeds: int | None = None,
    force: bool = False,
    progress: bool = True,
    sweep: SweepConfig | None = None,
) -> dict[str, Any]:
    """Every method of `METHODS` on `env` (`config`, a `LearnRewardConfig`, sets the rest: humans and seeds (default
    10 x 3), queries, candidates, posterior samples, the human); writes active.json/.png/.md."""
    from langpref.reward import LearnRewardConfig

    base = config or LearnRewardConfig(humans=10, seeds=3)
    base = replace(base, humans=base.humans if humans is None else humans, seeds=base.seeds if seeds is None else seeds)
    methods = {name: replace(base, feedback=fb, query_selection=sel) for name, (fb, sel) in METHODS.items()}
    results, runs, space, data, model, out = _run_methods(
        "active", env, methods, data, model, out, perfect, force, progress, sweep
    )
    q = base.queries
    keys = [f"{h}/{s}" for h in range(base.humans) for s in range(base.seeds)]
    auc = {m: _per_run(runs, m, keys, "true_reward_of_best") for m in methods}
    auc_ce = {m: _per_run(runs, m, keys, "cross_entropy") for m in methods}
    contrasts = {
        f"{a} - {b}": {
            "auc_true_reward": _interval(auc[a], auc[b]),
            "auc_cross_entropy": _interval(auc_ce[a], auc_ce[b]),
        }
        for a, b in CONTRASTS
    }
    ours, rand = results[OURS], results[LANG_RANDOM]
    half = q // 2
    ours_auc_half = float(np.mean(ours["true_reward_of_best"][: half + 1]))
    oq, rq = ours["queries_to_0.95"], rand["queries_to_0.95"]
    best_comp = max(
        (m for m in methods if m.startswith("comparison-") and m != "comparison-random"),
        key=lambda m: results[m]["auc_true_reward"],
    )
    vs_lal = contrasts[f"{OURS} - {LAL}"]["auc_true_reward"]
    targets = {
        f"ours reaches random language's AUC at Q = {q} within {half} queries (ours' AUC over 0..{half}: "
        f"{ours_auc_half:.3f}, random's over 0..{q}: {rand['auc_true_reward']:.3f})": ours_auc_half
        >= rand["auc_true_reward"],
        f"ours reaches 0.95 in at most half the queries random needs (ours {oq}, random {rq})": oq is not None
        and (rq is None or oq <= rq / 2),
        "ours beats lal-infogain on AUC, paired interval above 0": vs_lal["low"] > 0,
        "ours not significantly worse than lal-infogain on AUC": vs_lal["high"] >= 0,
        f"active language (ours) beats active comparisons ({best_comp}) on AUC": ours["auc_true_reward"]
        > results[best_comp]["auc_true_reward"],
    }
    figure = plot_reward_curves(
        results, out / "active.png", f"Active queries, {env}" + (" (perfect latent)" if model is None else "")
    )
    fields = {
        "methods": results,
        "targets": targets,
        "contrasts": contrasts,
        "figure": str(figure),
        "per_run_auc": {m: auc[m][:, 0].tolist() for m in methods},
    }
    return _save("active", env, data, model, out, space, base, fields, _markdown)


def _markdown(summary: dict[str, Any]) -> str:
    q = len(next(iter(summary["methods"].values()))["cross_entropy"]) - 1
    at = sorted({x for x in (0, 1, 5, 10, q // 2, q) if x <= q})
    lines = [
        f"### Active queries, {summary['env']}" + (" (perfect latent space, oracle)" if summary["perfect"] else ""),
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['humans']} humans x "
        f"{summary['seeds']} seeds, Q = {q}; metrics on the test split; every method fits the same learner, "
        "only the queries differ). CE: cross-entropy to the human's P_w; best: normalised true reward of the "
        "test trajectory r_xi ranks first; AUC: mean of the best curve over query counts 0..Q.",
        "",
    ]
    lines += _table(summary["methods"], at)
    lines += [
        "",
        "Paired differences over runs (same human and seed), 95% t-intervals:",
        "",
        "| contrast | AUC best | mean CE |",
        "|---|---|---|",
    ]
    for name, c in summary["contrasts"].items():
        a, ce = c["auc_true_reward"], c["auc_cross_entropy"]
        lines.append(
            f"| {name} | {a['mean']:+.3f} ({a['low']:+.3f} to {a['high']:+.3f}) | "
            f"{ce['mean']:+.3f} ({ce['low']:+.3f} to {ce['high']:+.3f}) |"
        )
    lines += [
        "",
        "Targets: " + "; ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in summary["targets"].items()),
        "",
        f"![Active queries {summary['env']}]({figure_link(summary['figure'])})",
    ]
    return "\n".join(lines) + "\n"
