"""`langpref experiment improve --env ENV`: the paper's Fig. 4 (iterative improvement, N = 15, 100 seeds): Eq. 4 as
the paper's text describes it (`paper`) and as it prints it (`paper-printed`), and the history strategy beside them.

Writes into the output directory (default `results/improve/ENV`): `improve.json` (the curves and the config),
`improve.png` (mean +- std per iteration, dashed optimum), `improve.md` (a section for docs/results.md) and
`runs.json`, the finished runs. Interrupted, it resumes: a finished seed is not rerun (`experiments.common.RunCache`,
shared with the reward-learning experiments).
"""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from langpref.experiments.common import (
    Inputs,
    RunCache,
    SweepConfig,
    base_command,
    figure_link,
    improve_head,
    phrasing_variant,
    run_sweep,
    space_experiment,
    title_suffix,
)

PAPER_FIG4 = (
    "Fig. 4 (no numbers printed): in both envs the true reward rises consistently over 15 iterations but "
    "stays below the dashed average optimum, because each step uses only the last feedback and can loop "
    "between good, non-optimal trajectories."
)


CURVES: dict[str, dict[str, str]] = {
    "paper": {"strategy": "paper", "objective": "cosine"},
    "paper-printed": {"strategy": "paper", "objective": "printed"},
    "history": {"strategy": "history"},
}
"""The curves of the experiment: name -> the `ImproveConfig` fields that make it."""
CURVE_LABELS = {
    "paper": "Eq. 4, cosine of the difference",
    "paper-printed": "Eq. 4 as printed",
    "history": "feedback history",
}


def _improvement_job(space, job) -> tuple[str, dict]:
    from langpref.improve import human_weights, run_improvement

    key, cfg, s = job
    w = human_weights(len(space.feature_names), cfg.seed, s)
    return key, asdict(run_improvement(space, w, cfg, (cfg.seed, s)))


def _fmt(values: list[float], at: list[int]) -> str:
    return " | ".join(f"{values[i]:.3f}" for i in at)


def improve_markdown(summary: dict[str, Any]) -> str:
    env, strategies = summary["env"], summary["strategies"]
    n = len(next(iter(strategies.values()))["curve"]) - 1
    at = sorted({0, 1, n // 3, 2 * n // 3, n})
    lines = [
        f"### Iterative improvement, {env}" + (" (perfect latent space, oracle)" if summary["perfect"] else ""),
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['seeds']} seeds, candidates: "
        f"{summary['candidate_split']} split). Mean normalised true reward (0 = worst, 1 = best candidate) of the "
        "trajectory shown at each iteration, std in the figure.",
        "",
        "| curve | " + " | ".join(f"it. {i}" for i in at) + " | gain 0 to N |",
        "|---|" + "---|" * (len(at) + 1),
    ]
    for name, res in strategies.items():
        lines.append(f"| {name} | {_fmt(res['curve'], at)} | {res['gain']:+.3f} |")
    lines += ["", f"![improvement {env}]({figure_link(summary['figure'])})", "", f"Paper: {PAPER_FIG4}"]
    return "\n".join(lines) + "\n"


def _run_curves(
    cfgs: dict[str, Any],
    space,
    worker_args: tuple,
    out: Path,
    force: bool,
    sweep: SweepConfig | None,
    label: str,
    progress: bool,
) -> dict[str, dict]:
    """Run every (curve, seed) not yet in out/runs.json; each curve's summary with its config."""
    from langpref.improve import ImprovementRun, summarise_improvement

    cache = RunCache(
        out / "runs.json", {"space": space.description, **{s: asdict(c) for s, c in cfgs.items()}}, force=force
    )
    for cfg in cfgs.values():
        cfg.validate()
    todo = [
        (f"{name}/{s}", cfg, s) for name, cfg in cfgs.items() for s in range(cfg.seeds) if f"{name}/{s}" not in cache
    ]
    run_sweep(_improvement_job, todo, space, worker_args, cache, sweep or SweepConfig(), label, progress)
    return {
        name: {
            **summarise_improvement([ImprovementRun(**cache.runs[f"{name}/{s}"]) for s in range(cfg.seeds)]),
            "config": asdict(cfg),
        }
        for name, cfg in cfgs.items()
    }


@space_experiment
def run_improve_experiment(run: Inputs) -> dict[str, Any]:
    """Every curve of `CURVES` with the paper's settings (or `config`, an `ImproveConfig`); writes JSON, PNG and
    markdown."""
    from langpref.feedback.space import load_space
    from langpref.improve import ImproveConfig, plot_improvement

    base = run.config or ImproveConfig()
    phrasings, env, perfect = base.human.phrasings, run.env, run.perfect
    data, model, out = run.paths("improve", "-".join(phrasing_variant(base.human)))
    space = load_space(
        data, model, env=env, perfect=perfect, phrasings=phrasings, feature_scale=base.human.feature_scale
    )
    cfgs = {name: replace(base, **fields) for name, fields in CURVES.items()}
    worker_args = (data, model, env, perfect, phrasings, base.human.feature_scale)
    results = _run_curves(cfgs, space, worker_args, out, run.force, run.sweep, f"improve {env}", run.progress)
    figure = plot_improvement(
        {f"{n} ({CURVE_LABELS[n]})": r for n, r in results.items()},
        out / "improve.png",
        f"Iterative improvement, {env}" + title_suffix(perfect, base.human),
    )
    summary = {
        **improve_head(replace(run, data=data, model=model), space, base),
        "candidate_split": base.candidate_split,
        "strategies": results,
        "figure": str(figure),
        "paper": PAPER_FIG4,
        "command": run.command or base_command("improve", env, data, model, out),
        "date": datetime.date.today().isoformat(),
    }
    (out / "improve.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "improve.md").write_text(improve_markdown(summary))
    return summary
