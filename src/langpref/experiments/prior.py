"""`langpref experiment prior --env ENV`: how the L2 prior's strength, which the paper does not have, was chosen per
reward-learning method: every method at every weight decay of a grid, scored on the val split with other humans than
the test experiments'. Writes prior.json/.png/.md into its output directory (default `results/prior/ENV`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from langpref.experiments.common import Inputs, figure_link, space_experiment, title_suffix
from langpref.experiments.reward import mean_cross_entropy, run_methods, save_summary

PRIOR_GRID = (0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
PRIOR_SEED = 1
"""Seed of the prior experiment's humans and runs: the reward and ablation experiments use seed 0."""
PRIOR_METHODS = {
    "language": ("language", "both"),
    "comparison": ("comparison", "both"),
    "explicit": ("language", "explicit"),
    "implicit": ("language", "implicit"),
}


def plot_prior(results: dict[str, dict], grid: tuple[float, ...], out: str | Path, title: str = "") -> Path:
    """Mean cross-entropy over queries 1..Q (val split) against the weight decay, one line per method."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the prior figure")

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for name in PRIOR_METHODS:
        ax.plot(grid, [mean_cross_entropy(results[_prior_key(name, wd)]) for wd in grid], marker="o", label=name)
    ax.set_xscale("log")
    ax.minorticks_off()
    ax.set_xticks(grid, [f"{wd:g}" for wd in grid])
    ax.set_xlabel("weight_decay (L2 prior strength)")
    ax.set_ylabel("mean CE, queries 1..Q (val)")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    return save_figure(fig, out, dpi=120, trim=False)


def prior_human(human):
    """The prior experiment's synthetic humans: the given ones, with the language human on the bank's val phrasings
    (the test split's are for reporting only) unless they speak an utterance file."""
    return human if human.phrasings else replace(human, phrasing_split="val")


def _prior_key(name: str, wd: float) -> str:
    return f"{name} wd={wd:g}"


@space_experiment
def run_prior_experiment(run: Inputs, grid: tuple[float, ...] = PRIOR_GRID) -> dict[str, Any]:
    """Each method (language with both losses, comparisons, either language loss alone) at every weight decay of
    `grid`, scored on the val split with the humans of seed `PRIOR_SEED`, which the test experiments never meet, and
    whose language human speaks the bank's val phrasings (`prior_human`): nothing of the test split takes part in
    the choice. Each method's pick is the weight decay of its lowest mean cross-entropy over queries 1..Q; writes
    prior.json/.png/.md."""
    from langpref.reward import DEFAULT_WEIGHT_DECAY, LearnRewardConfig

    given = run.config or LearnRewardConfig()
    base = replace(given, eval_split="val", seed=PRIOR_SEED, human=prior_human(given.human))
    reward_model = base.reward.model
    methods = {
        _prior_key(name, wd): replace(base, feedback=fb, reward=replace(base.reward, loss=loss, weight_decay=wd))
        for name, (fb, loss) in PRIOR_METHODS.items()
        for wd in grid
    }
    results, _, space, run = run_methods("prior", run, methods, named_for=given.human)
    picks = {
        name: min(grid, key=lambda wd: mean_cross_entropy(results[_prior_key(name, wd)])) for name in PRIOR_METHODS
    }
    title = f"L2 prior strength, {run.env}, {reward_model} reward" + title_suffix(run.model is None, base.human)
    figure = plot_prior(results, grid, run.out / "prior.png", title)
    fields = {
        "seed": PRIOR_SEED,
        "eval_split": "val",
        "phrasings": base.human.phrase_source,
        "grid": list(grid),
        "reward_model": reward_model,
        "default": DEFAULT_WEIGHT_DECAY[reward_model],
        "picks": picks,
        "methods": results,
        "figure": str(figure),
    }
    return save_summary("prior", run, space, base, fields, _prior_markdown)


def _prior_markdown(summary: dict[str, Any]) -> str:
    grid, results = summary["grid"], summary["methods"]
    lines = [
        f"### L2 prior strength, {summary['env']}"
        + ("" if summary["reward_model"] == "linear" else f", {summary['reward_model']} reward")
        + (" (perfect latent space, oracle)" if summary["perfect"] else ""),
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['humans']} humans x "
        f"{summary['seeds']} seeds of seed {summary['seed']}, other humans than the test experiments', the "
        f"language human speaking {summary.get('phrasings', 'test')} phrasings; metrics on the val split). Mean "
        "cross-entropy over queries 1..Q for each weight decay; the lowest of each method in bold. "
        f"The default for the {summary['reward_model']} reward is {summary['default']:g}.",
        "",
        "| method | " + " | ".join(f"wd {wd:g}" for wd in grid) + " | pick |",
        "|---|" + "---|" * (len(grid) + 1),
    ]
    for name, pick in summary["picks"].items():
        cells = [f"{mean_cross_entropy(results[_prior_key(name, wd)]):.3f}" for wd in grid]
        cells = [f"**{c}**" if wd == pick else c for c, wd in zip(cells, grid)]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {pick:g} |")
    lines += ["", f"![L2 prior strength {summary['env']}]({figure_link(summary['figure'])})"]
    return "\n".join(lines) + "\n"
