"""`langpref experiment reward|ablation --env ENV`: the paper's Fig. 5 (reward learning from language vs
comparisons) and Fig. 6 (ablation of L_Explicit / L_Implicit), 3 synthetic humans x 3 seeds, Q = 40 queries. The
methods' sweep (`run_methods`) and the summary file (`save_summary`) are shared with `experiments.prior`.

Each writes into its output directory (default `results/reward/ENV`, `results/ablation/ENV`): `NAME.json` (curves
per method, summaries, the targets checked, the config; per method also the mean cross-entropy over 1..Q, "queries
to 0.95" read as first touch and as stays-above (`queries_to`) and the curves of each synthetic human (`per_human`);
for `reward` also `ce_difference`, language minus comparison cross-entropy per query count with a paired 95%
interval, and `ce_language_lower`, at how many query counts 1..Q language's mean cross-entropy is the lower),
`NAME.png` (two panels: (a) cross-entropy, (b) normalised true reward of r_xi's best test trajectory; mean with a
+-std band), `NAME.md` (a section for docs/results.md) and `runs.json` (finished runs; an interrupted experiment
resumes without rerunning them).
"""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from langpref.experiments.common import (
    Inputs,
    RunCache,
    SweepConfig,
    base_command,
    figure_link,
    phrasing_variant,
    run_sweep,
    space_experiment,
    summary_head,
    title_suffix,
)

PAPER_FIG5 = (
    "Fig. 5 (no numbers printed): the cross-entropy of language feedback falls faster than that of "
    "comparisons in both envs, and the true reward of the learned reward's best trajectory reaches 1 in "
    "fewer queries with language, especially in Meta-World."
)
PAPER_FIG6 = "Fig. 6 (no numbers printed): L_Explicit + L_Implicit beats each alone on both metrics."


def run_methods(
    kind: str, run: Inputs, methods: dict[str, Any], named_for=None
) -> tuple[dict[str, dict], dict[str, dict], Any, Inputs]:
    """Run every (method, human, seed) not yet in the cache; the summary of each method, every run's curves (keyed
    METHOD/HUMAN/SEED), the latent space and `run` with its paths resolved. The default output directory is named
    for the human `named_for` (default the methods')."""
    from langpref.feedback.space import load_space

    reward_models = {cfg.reward.model for cfg in methods.values()} - {"linear"}
    human = next(iter(methods.values())).human
    phrasings = human.phrasings
    data, model, out = run.paths(kind, "-".join(sorted(reward_models) + phrasing_variant(named_for or human)))
    env, perfect = run.env, run.perfect
    space = load_space(data, model, env=env, perfect=perfect, phrasings=phrasings, feature_scale=human.feature_scale)
    streams = {c.eval_split for c in methods.values()} - {"test"}  # refuses val caches from before their own humans
    key = {"space": space.description, **{m: asdict(c) for m, c in methods.items()}}
    cache = RunCache(out / "runs.json", {**key, "humans_of": sorted(streams)} if streams else key, force=run.force)
    for cfg in methods.values():
        cfg.validate()
    todo = [
        (f"{name}/{h}/{s}", cfg, h, s)
        for name, cfg in methods.items()
        for h in range(cfg.humans)
        for s in range(cfg.seeds)
        if f"{name}/{h}/{s}" not in cache
    ]
    run_sweep(
        _reward_job,
        todo,
        space,
        (data, model, env, perfect, phrasings, human.feature_scale),
        cache,
        run.sweep or SweepConfig(),
        f"{kind} {env}",
        run.progress,
    )
    results = {
        name: {**_summary(cache.runs, name, cfg.humans, cfg.seeds), "config": asdict(cfg)}
        for name, cfg in methods.items()
    }
    return results, cache.runs, space, replace(run, data=data, model=model, out=out)


THRESHOLD = 0.95
"""The true reward of r_xi's best test trajectory that "queries to 0.95" asks for."""


def queries_to(curve, threshold: float = THRESHOLD) -> dict[str, int | None]:
    """Two readings of when a mean curve (query counts 0..Q) reaches `threshold`: `first_touch`, the first query count
    at which it is >= threshold, and `stays`, the first query count from which it never falls below it again up to Q
    (None when it never does, or for `stays`, when it is below at Q)."""
    above = np.asarray(curve, dtype=np.float64) >= threshold
    touch = np.flatnonzero(above)
    below = np.flatnonzero(~above)
    stays = (0 if len(below) == 0 else int(below[-1]) + 1) if above[-1] else None
    return {"first_touch": int(touch[0]) if len(touch) else None, "stays": stays}


def _summary(runs: dict[str, dict], name: str, humans: int, seeds: int) -> dict[str, Any]:
    """`langpref.reward.summarise_curves` of one method's runs, plus the numbers the docs quote: the mean
    cross-entropy over query counts 1..Q, "queries to 0.95" in both readings of `queries_to`, and the curves of each
    synthetic human (its mean over seeds, keyed by the human's number)."""
    from langpref.reward import Curves, summarise_curves

    curves = {h: [Curves(**runs[f"{name}/{h}/{s}"]) for s in range(seeds)] for h in range(humans)}
    out = summarise_curves([c for h in range(humans) for c in curves[h]])
    reached = queries_to(out["true_reward_of_best"])
    out.update(
        {
            "mean_cross_entropy_1_to_q": float(np.mean(out["cross_entropy"][1:])),
            f"queries_to_{THRESHOLD:g}_first_touch": reached["first_touch"],
            f"queries_to_{THRESHOLD:g}_stays": reached["stays"],
            "per_human": {
                str(h): {
                    "cross_entropy": np.mean([c.cross_entropy for c in cs], axis=0).tolist(),
                    "true_reward_of_best": np.mean([c.true_reward_of_best for c in cs], axis=0).tolist(),
                    "auc_true_reward": float(np.mean([c.true_reward_of_best for c in cs])),
                    "mean_cross_entropy_1_to_q": float(np.mean([c.cross_entropy[1:] for c in cs])),
                    **{
                        f"queries_to_{THRESHOLD:g}_{k}": v
                        for k, v in queries_to(np.mean([c.true_reward_of_best for c in cs], axis=0)).items()
                    },
                }
                for h, cs in curves.items()
            },
        }
    )
    return out


def ce_lower_count(a: dict, b: dict) -> dict[str, int]:
    """At how many query counts 1..Q the mean cross-entropy of method `a` is lower than that of `b` (and higher)."""
    ca, cb = np.array(a["cross_entropy"][1:]), np.array(b["cross_entropy"][1:])
    return {"lower": int((ca < cb).sum()), "higher": int((ca > cb).sum()), "of": len(ca)}


def _reward_job(space, job) -> tuple[str, dict]:
    from langpref.reward import human_weights, run_reward_learning
    from langpref.reward.loop import human_stream

    key, cfg, h, s = job
    stream = human_stream(cfg.seed, cfg.eval_split)  # val: other humans than the test runs'
    w = human_weights(len(space.feature_names), stream, h)
    return key, asdict(run_reward_learning(space, w, cfg, (*stream, h, s)))


def per_human(x: np.ndarray, seeds: int) -> np.ndarray:
    """(humans, ...) the mean over each human's seeds of per-run rows ordered human by human (the keys HUMAN/SEED of
    `run_methods`): the unit of an interval, since a human's seeds share its weights and are not more people."""
    x = np.asarray(x, dtype=np.float64)
    return x.reshape(len(x) // seeds, seeds, *x.shape[1:]).mean(axis=1)


def paired_difference(a: np.ndarray, b: np.ndarray, confidence: float = 0.95) -> dict[str, list]:
    """Mean of a - b per column over paired rows (the same synthetic human, its seeds averaged: `per_human`), with
    the two-sided t-interval at `confidence`: how far one method's curve lies from another's, and whether that is
    more than the spread between humans."""
    from scipy import stats

    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    n = len(d)
    mean = d.mean(axis=0)
    half = (
        stats.t.ppf(0.5 + confidence / 2, n - 1) * d.std(axis=0, ddof=1) / np.sqrt(n)
        if n > 1
        else np.full_like(mean, np.inf)
    )
    return {"mean": mean.tolist(), "low": (mean - half).tolist(), "high": (mean + half).tolist()}


def _ce_difference_line(diff: dict[str, list]) -> str:
    mean, low, high = (np.array(diff[k][1:]) for k in ("mean", "low", "high"))
    q = len(mean)
    worst = int(np.argmax(mean)) + 1
    return (
        f"Language minus comparison CE, paired by human (each human's seeds averaged), 95% t-interval over the "
        f"humans per query count: language "
        f"significantly lower at {int((high < 0).sum())} of {q}, comparisons significantly lower at "
        f"{int((low > 0).sum())} of {q}; most in comparisons' favour at q = {worst} "
        f"({mean[worst - 1]:+.3f}, interval {low[worst - 1]:+.3f} to {high[worst - 1]:+.3f})."
    )


def curves_table(results: dict[str, dict], at: list[int]) -> list[str]:
    """Markdown rows of each method's curves at the query counts `at` (cross-entropy, true reward of the best)."""
    lines = [
        "| method | "
        + " | ".join(f"CE q={q}" for q in at)
        + " | mean CE 1..Q | "
        + " | ".join(f"best q={q}" for q in at)
        + " | AUC best | queries to 0.95 (first touch) | "
        "queries to 0.95 (stays) |",
        "|---|" + "---|" * (2 * len(at) + 4),
    ]
    for name, r in results.items():
        ce = " | ".join(f"{r['cross_entropy'][q]:.3f}" for q in at)
        best = " | ".join(f"{r['true_reward_of_best'][q]:.3f}" for q in at)
        lines.append(
            f"| {name} | {ce} | {mean_cross_entropy(r):.3f} | {best} | {r['auc_true_reward']:.3f} | "
            f"{_reached(r, 'first_touch')} | {_reached(r, 'stays')} |"
        )
    return lines


def mean_cross_entropy(result: dict) -> float:
    """A method's mean cross-entropy over queries 1..Q (query 0, before any answer, left out)."""
    return float(np.mean(result["cross_entropy"][1:]))


def _reached(r: dict, reading: str) -> str:
    q = r.get(f"queries_to_{THRESHOLD:g}_{reading}")
    return "not reached" if q is None else str(q)


def _per_human_table(results: dict[str, dict]) -> list[str]:
    """Each synthetic human's numbers (its mean over seeds) per method: AUC of the best curve, mean CE over 1..Q and
    queries to 0.95 (first touch / stays)."""
    humans = list(next(iter(results.values())).get("per_human", {}))
    if not humans:
        return []
    lines = [
        "Per synthetic human (mean over its seeds): AUC best / mean CE 1..Q / queries to 0.95 (first touch, stays).",
        "",
        "| method | " + " | ".join(f"human {h}" for h in humans) + " |",
        "|---|" + "---|" * len(humans),
    ]
    for name, r in results.items():
        cells = [
            f"{p['auc_true_reward']:.3f} / {p['mean_cross_entropy_1_to_q']:.3f} / {_reached(p, 'first_touch')}, "
            f"{_reached(p, 'stays')}"
            for p in (r["per_human"][h] for h in humans)
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def section_head(title: str, summary: dict[str, Any], about: str) -> tuple[list[int], list[str]]:
    """The query counts a results table shows (0, 1, 5, 10, Q/2, Q) and the first lines of a results section: its
    heading, and the command, date, space and runs, then `about` (the metrics' legend) after the run counts."""
    q = len(next(iter(summary["methods"].values()))["cross_entropy"]) - 1
    at = sorted({x for x in (0, 1, 5, 10, q // 2, q) if x <= q})
    return at, [
        f"### {title}, {summary['env']}" + (" (perfect latent space, oracle)" if summary["perfect"] else ""),
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['humans']} humans x "
        f"{summary['seeds']} seeds, Q = {q}; {about}",
    ]


def _markdown(title: str, summary: dict[str, Any], paper: str) -> str:
    at, lines = section_head(
        title,
        summary,
        "metrics on the test split). CE: cross-entropy to the human's P_w over all test pairs; best: normalised "
        "true reward of the test trajectory r_xi ranks first; AUC: the mean of the best curve over query counts "
        "0..Q; queries to 0.95: the first query count at which the mean best curve reaches 0.95 (first touch), and "
        "the first from which it stays at or above 0.95 up to Q (stays).",
    )
    lines += ["", *curves_table(summary["methods"], at)]
    lines += ["", "Targets: " + "; ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in summary["targets"].items())]
    if "ce_language_lower" in summary:
        c = summary["ce_language_lower"]
        lines += [
            "",
            f"Mean cross-entropy: language lower than comparisons at {c['lower']} of {c['of']} query counts "
            f"(1..Q), higher at {c['higher']}.",
        ]
    if "ce_difference" in summary:
        lines += ["", _ce_difference_line(summary["ce_difference"])]
    per_human = _per_human_table(summary["methods"])
    lines += ["", *per_human] if per_human else []
    lines += ["", f"![{title} {summary['env']}]({figure_link(summary['figure'])})", "", f"Paper: {paper}"]
    return "\n".join(lines) + "\n"


def save_summary(kind: str, run: Inputs, space, base, fields: dict[str, Any], markdown) -> dict[str, Any]:
    """The summary of an experiment (what every kind records, then `fields`), written as KIND.json and, through
    `markdown(summary)`, KIND.md into `run.out` (resolved, `run_methods`). `run.command`: the command line that ran
    it (`langpref experiment` passes its own; None, from Python: the experiment's base command, whose options the
    summary's configs hold)."""
    env, data, model, out = run.env, run.data, run.model, run.out
    summary = {
        **summary_head(env, data, model, space, base),
        **fields,
        "command": run.command or base_command(kind, env, data, model, out),
        "date": datetime.date.today().isoformat(),
    }
    (out / f"{kind}.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / f"{kind}.md").write_text(markdown(summary))
    return summary


def _finish(
    kind: str, title: str, paper: str, run: Inputs, results, space, base, targets, **extra: Any
) -> dict[str, Any]:
    """The figure and the summary of the reward experiment or the ablation."""
    from langpref.reward.figures import plot_reward_curves

    title_at = f"{title}, {run.env}" + title_suffix(run.model is None, base.human)
    figure = plot_reward_curves(results, run.out / f"{kind}.png", title_at)
    fields = {"methods": results, "targets": targets, "figure": str(figure), "paper": paper, **extra}
    return save_summary(kind, run, space, base, fields, lambda s: _markdown(title, s, paper))


@space_experiment
def run_reward_experiment(run: Inputs) -> dict[str, Any]:
    """Language (L_Explicit + L_Implicit) vs comparisons with the paper's settings (or `config`, a
    `LearnRewardConfig` whose feedback is replaced); writes reward.json/.png/.md."""
    from langpref.reward import LearnRewardConfig

    base = run.config or LearnRewardConfig()
    methods = {"language": replace(base, feedback="language"), "comparison": replace(base, feedback="comparison")}
    results, runs, space, run = run_methods("reward", run, methods)
    lang, comp = results["language"], results["comparison"]
    lq, cq = lang["queries_to_0.95"], comp["queries_to_0.95"]
    targets = {
        "language CE < comparison CE at every query count 1..Q": bool(
            np.all(np.array(lang["cross_entropy"][1:]) < np.array(comp["cross_entropy"][1:]))
        ),
        "language AUC of true reward > comparison": lang["auc_true_reward"] > comp["auc_true_reward"],
        "language reaches 0.95 in fewer queries": lq is not None and (cq is None or lq < cq),
    }
    keys = [f"{h}/{s}" for h in range(base.humans) for s in range(base.seeds)]
    ce = {m: np.array([runs[f"{m}/{k}"]["cross_entropy"] for k in keys]) for m in methods}
    return _finish(
        "reward",
        "Reward learning: language vs comparisons",
        PAPER_FIG5,
        run,
        results,
        space,
        base,
        targets,
        ce_difference=paired_difference(per_human(ce["language"], base.seeds), per_human(ce["comparison"], base.seeds)),
        ce_language_lower=ce_lower_count(lang, comp),
    )


@space_experiment
def run_ablation_experiment(run: Inputs) -> dict[str, Any]:
    """Language feedback with L_Explicit + L_Implicit, L_Explicit alone and L_Implicit alone; writes
    ablation.json/.png/.md."""
    from langpref.reward import LearnRewardConfig

    base = replace(run.config or LearnRewardConfig(), feedback="language")
    methods = {loss: replace(base, reward=replace(base.reward, loss=loss)) for loss in ("both", "explicit", "implicit")}
    results, _, space, run = run_methods("ablation", run, methods)
    b, e, i = results["both"], results["explicit"], results["implicit"]
    targets = {
        "both has a higher AUC of true reward than explicit and implicit alone": b["auc_true_reward"]
        > max(e["auc_true_reward"], i["auc_true_reward"]),
        "both has a lower mean cross-entropy (AUC) than explicit and implicit alone": b["auc_cross_entropy"]
        < min(e["auc_cross_entropy"], i["auc_cross_entropy"]),
    }
    return _finish("ablation", "Ablation of the language reward loss", PAPER_FIG6, run, results, space, base, targets)
