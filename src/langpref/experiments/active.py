"""`langpref experiment active --env ENV`: active queries against random ones, for language and for comparisons,
and a learner that asks either kind.

The learner is a dimension. Under the paper's learner (Eq. 9 / Bradley-Terry, L-BFGS, L2 prior): language x {random
(the paper's), lal-infogain (the authors' follow-up), infogain (the latent Eq. 10 answer model,
`langpref.reward.selection`)}, comparisons x {random, infogain (mutual information), volume-removal}, and
mixed-infogain (both kinds in one learner, each query of the kind and item with the most information per modelled
second, `langpref.reward.mixed`). Under the answer-model learner (`langpref.reward.answer_model`, methods prefixed
`am-`): language x {random, infogain}, comparisons x infogain and mixed-infogain, all asking and learning under the
one answer model. 10 synthetic humans x 3 seeds, Q = 40.

Over queries and over the person's time. A query's modelled seconds are its kind's (`langpref.reward.cost`: the
paper's measurement, language 11.3% faster than a comparison, unless given), so every run also has a curve over
modelled seconds (a step function: at time t, the metrics after the last query finished by t). These are compared up
to the horizon every run reaches (the least total time of any run: Q queries of the cheaper kind, which no mixed run
can undercut), by their mean over that time (AUC per second), with the same paired intervals as per query.

Writes into its output directory (default `results/active/ENV`): `active.json` (curves and summaries per method,
per-run AUCs per query and per modelled second, paired 95% intervals between strategies, the mixed learner's share of
language queries, the targets of issue 21 checked, the config), `active.png` (cross-entropy and true reward of the
best test trajectory per query and over modelled seconds), `active.md` (a section for docs/results.md) and
`runs.json` (finished runs; an interrupted experiment resumes).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from langpref.experiments.common import Inputs, figure_link, space_experiment
from langpref.experiments.reward import (
    curves_table,
    paired_difference,
    per_human,
    run_methods,
    save_summary,
    section_head,
)
from langpref.extras import pyplot, save_figure
from langpref.feedback.kind import MIXED as BOTH
from langpref.feedback.kind import PAPER_KINDS
from langpref.reward.cost import elapsed, on_time_grid, time_average

CONFIRM_MARGIN = 0.5
"""The `am-...-confirm` method's margin: people confirm a sentence whose top two readings are closer than this.
Chosen on the val protocol of the drawer recording (margins 0.2, 0.3, 0.5, 0.7, 1.0: 0.5 is the smallest with the
best AUC; docs/results.md)."""

LANGUAGE, COMPARISON = PAPER_KINDS
"""The registered kinds the experiment compares (`langpref.feedback.kind`)."""
ACTIVE_METHODS = {
    "language-random": (LANGUAGE, None, "paper", None),
    "language-lal-infogain": (LANGUAGE, "lal-infogain", "paper", None),
    "language-infogain": (LANGUAGE, "infogain", "paper", None),
    "comparison-random": (COMPARISON, None, "paper", None),
    "comparison-infogain": (COMPARISON, "infogain", "paper", None),
    "comparison-volume-removal": (COMPARISON, "volume-removal", "paper", None),
    "mixed-infogain": (BOTH, "infogain", "paper", None),
    "am-language-random": (LANGUAGE, None, "answer-model", None),
    "am-language-infogain": (LANGUAGE, "infogain", "answer-model", None),
    "am-language-infogain-confirm": (LANGUAGE, "infogain", "answer-model", CONFIRM_MARGIN),
    "am-comparison-infogain": (COMPARISON, "infogain", "answer-model", None),
    "am-mixed-infogain": (BOTH, "infogain", "answer-model", None),
}
"""Method name -> (feedback, query selection, learner, confirm margin); None is random, and never asking. Data: each
feedback is a registered kind or `mixed`, each selection one of its `strategies` (tests/experiments/test_active.py)."""
OURS, LAL, LANG_RANDOM = "language-infogain", "language-lal-infogain", "language-random"
COMP, MIXED = "comparison-infogain", "mixed-infogain"
AM_LANG, AM_RANDOM, AM_COMP, AM_MIXED = (
    "am-language-infogain",
    "am-language-random",
    "am-comparison-infogain",
    ("am-mixed-infogain"),
)
CONTRASTS = (
    (OURS, LANG_RANDOM),
    (OURS, LAL),
    (LAL, LANG_RANDOM),
    (OURS, COMP),
    (COMP, "comparison-random"),
    ("comparison-volume-removal", "comparison-random"),
    (MIXED, OURS),
    (MIXED, COMP),
    (AM_LANG, COMP),
    (AM_LANG, AM_COMP),
    (AM_LANG, AM_RANDOM),
    (AM_RANDOM, LANG_RANDOM),
    (AM_LANG, LANG_RANDOM),
    (AM_MIXED, AM_LANG),
    (AM_MIXED, AM_COMP),
    (f"{AM_LANG}-confirm", AM_LANG),
    (f"{AM_LANG}-confirm", COMP),
    (f"{AM_LANG}-confirm", AM_COMP),
)
"""Paired differences reported (first minus second)."""
METRICS = {"true_reward_of_best": "auc_true_reward", "cross_entropy": "auc_cross_entropy"}
"""Each curve and the name of its area."""
GRID_POINTS = 201
"""Points of the modelled-time axis of the curves over seconds (the AUC per second is exact, not read off it)."""


def _per_run(runs: dict, method: str, keys: list[str], key: str) -> np.ndarray:
    """(runs, 1): each run's mean of curve `key` over query counts 0..Q (its AUC per query)."""
    return np.array([[float(np.mean(runs[f"{method}/{k}"][key]))] for k in keys])


def _interval(a: np.ndarray, b: np.ndarray, seeds: int) -> dict[str, float]:
    """The paired difference of two methods' per-run areas with its t-interval over the humans (`per_human`)."""
    d = paired_difference(per_human(a, seeds), per_human(b, seeds))
    return {k: float(v[0]) for k, v in d.items()}


def run_seconds(run: dict, feedback: str, costs: dict[str, float]) -> list[float]:
    """A run's modelled seconds after 0..Q queries: as recorded, or (a run recorded before they were kept) Q queries
    of its one kind."""
    q = len(run["cross_entropy"]) - 1
    seconds = run.get("seconds") or []
    return list(seconds) if len(seconds) == q + 1 else elapsed([feedback] * q, costs)


def per_second(runs: dict, methods: dict, keys: list[str]) -> dict[str, Any]:
    """The curves over modelled seconds, up to the horizon every run reaches: per method the mean and std of each
    metric on a grid, the time average of each run (`per_run`, the AUC per second) and its mean, and the seconds Q
    queries took (mean over runs)."""
    seconds = {m: [run_seconds(runs[f"{m}/{k}"], cfg.feedback, cfg.costs) for k in keys] for m, cfg in methods.items()}
    horizon = min(s[-1] for m in methods for s in seconds[m])
    grid = np.linspace(0.0, horizon, GRID_POINTS)
    out: dict[str, Any] = {"horizon": horizon, "grid": grid.tolist(), "methods": {}}
    for m in methods:
        res: dict[str, Any] = {"seconds_for_q": float(np.mean([s[-1] for s in seconds[m]])), "per_run": {}}
        for key in METRICS:
            curves = [runs[f"{m}/{k}"][key] for k in keys]
            on_grid = np.array([on_time_grid(c, s, grid) for c, s in zip(curves, seconds[m])])
            per_run = [time_average(c, s, horizon) for c, s in zip(curves, seconds[m])]
            res[key] = on_grid.mean(axis=0).tolist()
            res[f"{key}_std"] = on_grid.std(axis=0).tolist()
            res[METRICS[key]] = float(np.mean(per_run))
            res["per_run"][key] = per_run
        out["methods"][m] = res
    return out


def language_share(runs: dict, method: str, keys: list[str]) -> float | None:
    """The share of language queries over all runs of `method` (None for runs recorded before kinds were kept)."""
    kinds = [runs[f"{method}/{k}"].get("kinds") or [] for k in keys]
    if not all(kinds):
        return None
    return float(np.mean([kind == LANGUAGE for ks in kinds for kind in ks]))


@space_experiment
def run_active_experiment(run: Inputs, humans: int | None = None, seeds: int | None = None) -> dict[str, Any]:
    """Every method of `ACTIVE_METHODS` on `env` (`config`, a `LearnRewardConfig`, sets the rest: humans and seeds
    (default 10 x 3), queries, candidates, posterior samples, the human); writes active.json/.png/.md."""
    from langpref.reward import LearnRewardConfig

    base = run.config or LearnRewardConfig(humans=10, seeds=3)
    base = replace(base, humans=base.humans if humans is None else humans, seeds=base.seeds if seeds is None else seeds)
    methods = {
        name: replace(base, feedback=fb, query_selection=sel, learner=learner, confirm_margin=margin)
        for name, (fb, sel, learner, margin) in ACTIVE_METHODS.items()
    }
    results, runs, space, run = run_methods("active", run, methods)
    keys = [f"{h}/{s}" for h in range(base.humans) for s in range(base.seeds)]
    timed = per_second(runs, methods, keys)
    auc, auc_s, contrasts = _contrasts(runs, methods, keys, timed, base.seeds)
    targets = {**paper_learner_targets(results, contrasts, base.queries), **answer_model_targets(results, contrasts)}
    title = f"Active queries, {run.env}" + (" (perfect latent)" if run.model is None else "")
    figure = plot_active(results, timed, run.out / "active.png", title)
    fields = {
        "methods": results,
        "targets": targets,
        "contrasts": contrasts,
        "per_second": timed,
        "language_share": {m: language_share(runs, m, keys) for m in methods},
        "costs": base.costs,
        "query_batch": base.batch,
        "figure": str(figure),
        "per_run_auc": {m: auc[m][:, 0].tolist() for m in methods},
        "per_run_auc_per_second": {m: auc_s[m][:, 0].tolist() for m in methods},
    }
    return save_summary("active", run, space, base, fields, _markdown)


def _contrasts(runs: dict[str, dict], methods: dict[str, Any], keys: list[str], timed: dict[str, Any], seeds: int):
    """Per method the per-run areas (true reward of the best, per query and per modelled second), and the paired
    intervals of `CONTRASTS` on all four areas (cross-entropy too), over the humans (`keys` ordered human by human,
    `seeds` runs each)."""
    auc = {m: _per_run(runs, m, keys, "true_reward_of_best") for m in methods}
    auc_ce = {m: _per_run(runs, m, keys, "cross_entropy") for m in methods}
    auc_s = {m: np.array(timed["methods"][m]["per_run"]["true_reward_of_best"])[:, None] for m in methods}
    auc_ce_s = {m: np.array(timed["methods"][m]["per_run"]["cross_entropy"])[:, None] for m in methods}
    contrasts = {
        f"{a} - {b}": {
            "auc_true_reward": _interval(auc[a], auc[b], seeds),
            "auc_cross_entropy": _interval(auc_ce[a], auc_ce[b], seeds),
            "auc_true_reward_per_second": _interval(auc_s[a], auc_s[b], seeds),
            "auc_cross_entropy_per_second": _interval(auc_ce_s[a], auc_ce_s[b], seeds),
        }
        for a, b in CONTRASTS
    }
    return auc, auc_s, contrasts


def paper_learner_targets(results: dict[str, dict], contrasts: dict[str, dict], q: int) -> dict[str, bool]:
    """The targets of active queries with the paper's learner, from the summaries and the paired intervals."""
    ours, rand = results[OURS], results[LANG_RANDOM]
    half = q // 2
    ours_auc_half = float(np.mean(ours["true_reward_of_best"][: half + 1]))
    oq, rq = ours["queries_to_0.95"], rand["queries_to_0.95"]
    best_comp = max(
        (m for m in results if m.startswith("comparison-") and m != "comparison-random"),
        key=lambda m: results[m]["auc_true_reward"],
    )
    vs_lal = contrasts[f"{OURS} - {LAL}"]["auc_true_reward"]
    return {
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


def answer_model_targets(results: dict[str, dict], contrasts: dict[str, dict]) -> dict[str, bool]:
    """Issue 29's targets for the answer-model learner, from the summaries and the paired intervals."""

    def above(a: str, b: str, per: str = "") -> bool:
        return contrasts[f"{a} - {b}"][f"auc_true_reward{per}"]["low"] > 0

    def not_below(a: str, b: str) -> bool:
        return contrasts[f"{a} - {b}"]["auc_true_reward"]["high"] >= 0

    am_q, rand_q = results[AM_LANG]["queries_to_0.95"], results["comparison-random"]["queries_to_0.95"]
    better = max((AM_LANG, AM_COMP), key=lambda m: results[m]["auc_true_reward"])
    return {
        f"answer-model active language beats active comparisons ({COMP}, {AM_COMP}) on AUC, interval above 0, per "
        "query and per second": all(above(AM_LANG, c, per) for c in (COMP, AM_COMP) for per in ("", "_per_second")),
        "answer-model active language beats answer-model random language, interval above 0": above(AM_LANG, AM_RANDOM),
        "answer-model active language not significantly worse than its random language": not_below(AM_LANG, AM_RANDOM),
        "answer-model random language not below the paper's random language": not_below(AM_RANDOM, LANG_RANDOM),
        f"answer-model active language reaches 0.95 in at most half the queries random comparisons need ({am_q} vs "
        f"{rand_q})": am_q is not None and (rand_q is None or am_q <= rand_q / 2),
        f"answer-model mixed at least as good as the better single kind ({better})": results[AM_MIXED][
            "auc_true_reward"
        ]
        >= results[better]["auc_true_reward"] - 1e-9,
    }


def plot_active(results: dict[str, dict], timed: dict[str, Any], out: str | Path, title: str = "") -> Path:
    """Four panels: cross-entropy and true reward of the best test trajectory per query (as Fig. 5), and the same
    over modelled seconds of the person's time, up to the horizon every run reaches; mean with a +-std band."""
    plt = pyplot("the active-queries figure")

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.2))
    grid = np.array(timed["grid"])
    panels = (
        (axes[0, 0], results, None, "cross_entropy", "(a) cross-entropy per query"),
        (axes[0, 1], results, None, "true_reward_of_best", "(b) true reward of the best test trajectory per query"),
        (axes[1, 0], timed["methods"], grid, "cross_entropy", "(c) cross-entropy over modelled seconds"),
        (axes[1, 1], timed["methods"], grid, "true_reward_of_best", "(d) true reward of the best per modelled second"),
    )
    for ax, curves, x, key, label in panels:
        for name, res in curves.items():
            mean, std = np.array(res[key]), np.array(res[f"{key}_std"])
            xs = np.arange(len(mean)) if x is None else x
            ax.plot(xs, mean, label=name, drawstyle="default" if x is None else "steps-post")
            ax.fill_between(xs, mean - std, mean + std, alpha=0.15, step=None if x is None else "post")
        ax.set_xlabel("queries" if x is None else "modelled seconds (unit: one comparison unless set)")
        ax.set_title(label, fontsize=10)
        if key == "true_reward_of_best":
            ax.set_ylim(-0.05, 1.05)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title)
    return save_figure(fig, out, dpi=120, trim=False)


def _markdown(summary: dict[str, Any]) -> str:
    at, lines = section_head(
        "Active queries",
        summary,
        "metrics on the test split; methods without `am-` fit the paper's learner and differ only in the queries, "
        "`am-` ones the answer-model learner). CE: cross-entropy to the human's P_w; best: normalised true reward of "
        "the test trajectory r_xi ranks first; AUC: mean of the best curve over query counts 0..Q.",
    )
    lines += ["", *curves_table(summary["methods"], at)]
    lines += ["", *_time_table(summary)]
    lines += [
        "",
        "Paired differences, 95% t-intervals over the humans (each human's seeds averaged first); per query (over "
        "query counts 0..Q) "
        "and per modelled second (over 0..T):",
        "",
        "| contrast | AUC best | mean CE | AUC best per second | mean CE per second |",
        "|---|---|---|---|---|",
    ]
    for name, c in summary["contrasts"].items():
        cells = [_cell(c[f"{k}{per}"]) for per in ("", "_per_second") for k in METRICS.values() if f"{k}{per}" in c]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Targets: " + "; ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in summary["targets"].items()),
        "",
        f"![Active queries {summary['env']}]({figure_link(summary['figure'])})",
    ]
    return "\n".join(lines) + "\n"


def _cell(d: dict[str, float]) -> str:
    return f"{d['mean']:+.3f} ({d['low']:+.3f} to {d['high']:+.3f})"


def _time_table(summary: dict[str, Any]) -> list[str]:
    """Per method: modelled seconds for Q queries, its share of language queries and its areas per modelled second."""
    timed = summary["per_second"]
    costs = summary["costs"]
    lines = [
        f"Over the person's time: modelled seconds per query language {costs['language']:g}, comparison "
        f"{costs['comparison']:g} (the paper's ratio unless set); T = {timed['horizon']:.2f}, the time every run "
        "reaches; AUC per second: mean of the curve over modelled time 0..T (at t, the metrics after the last query "
        "finished by t).",
        "",
        "| method | seconds for Q queries | language share | AUC best per query | AUC best per second | mean CE per "
        "second |",
        "|---|---|---|---|---|---|",
    ]
    for name, res in timed["methods"].items():
        share = summary["language_share"].get(name)
        lines.append(
            f"| {name} | {res['seconds_for_q']:.2f} | {'n/a' if share is None else f'{share:.2f}'} | "
            f"{summary['methods'][name]['auc_true_reward']:.3f} | {res['auc_true_reward']:.3f} | "
            f"{res['auc_cross_entropy']:.3f} |"
        )
    return lines
