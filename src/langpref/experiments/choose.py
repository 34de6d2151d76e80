"""`langpref experiment choose --env ENV`: how the answer-model learner's own two settings are chosen: its prior
scale s (language and comparisons, random queries) and the logit c of "that's good, no change" (active language).
Every value of each grid is scored on the val split with other humans than the test experiments' (the val stream of
`--seed`, `langpref.reward.loop.human_stream`) whose language human speaks the bank's val phrasings, and set against
the default value paired by human: a t-interval over the humans, each human's seeds averaged first, so the unit is
the human. Writes choose.json/.md into its output directory (default `results/choose/ENV`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from langpref.experiments.common import Inputs, figure_link, space_experiment
from langpref.experiments.prior import prior_human
from langpref.experiments.reward import paired_difference, run_methods, save_summary

PRIOR_SCALES = (0.25, 0.5, 1.0, 2.0)
NO_CHANGE_LOGITS = (-30.0, 0.0, 1.0, 2.0)
"""-30: "no change" not modelled (its probability e^-30 of the features')."""
GRIDS = {
    "language": ("language", "prior_scale", PRIOR_SCALES, "random"),
    "comparison": ("comparison", "prior_scale", PRIOR_SCALES, "random"),
    "active language": ("language", "no_change_logit", NO_CHANGE_LOGITS, "infogain"),
}
"""Row -> (its feedback, the `AnswerModelConfig` field it varies, its values, the query selection)."""
SYMBOL = {"prior_scale": "s", "no_change_logit": "c"}


def _key(row: str, field: str, value: float) -> str:
    return f"{row} {SYMBOL[field]}={value:g}"


def _methods(base) -> dict[str, Any]:
    """Every (row, value) of `GRIDS` as a `LearnRewardConfig` of the answer-model learner."""
    return {
        _key(row, field, value): replace(
            base,
            feedback=feedback,
            query_selection=selection,
            answer_model=replace(base.answer_model, **{field: value}),
        )
        for row, (feedback, field, values, selection) in GRIDS.items()
        for value in values
    }


def _per_human(result: dict, metric: str) -> np.ndarray:
    """One number per synthetic human (its seeds averaged), in the humans' order."""
    per = result["per_human"]
    return np.array([per[h][metric] for h in sorted(per, key=int)], dtype=np.float64)


def _row(results: dict[str, dict], row: str, field: str, values: tuple[float, ...], default: float) -> dict:
    """Each value's AUC and mean CE over queries 1..Q, its difference to the default's with a 95% t-interval over the
    humans, and the pick: the value of the lowest mean CE."""
    metrics = ("auc_true_reward", "mean_cross_entropy_1_to_q")
    base = {m: _per_human(results[_key(row, field, default)], m) for m in metrics}
    cells = {}
    for value in values:
        own = {m: _per_human(results[_key(row, field, value)], m) for m in metrics}
        cells[f"{value:g}"] = {
            **{m: float(own[m].mean()) for m in metrics},
            **{
                f"{m}_minus_default": {k: v[0] for k, v in paired_difference(own[m][:, None], base[m][:, None]).items()}
                for m in metrics
            },
        }
    pick = min(values, key=lambda v: cells[f"{v:g}"]["mean_cross_entropy_1_to_q"])
    return {"setting": field, "default": default, "values": cells, "lowest_ce": pick}


def plot_choices(rows: dict[str, dict], out: Path, title: str) -> Path:
    """Each row's mean CE against its setting's values, the default marked (dashed): where the pick stands."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the choice figure")
    fig, axes = plt.subplots(1, len(rows), figsize=(3.2 * len(rows), 3.2))
    for ax, (row, r) in zip(np.atleast_1d(axes), rows.items()):
        values = list(r["values"])
        ax.plot(range(len(values)), [c["mean_cross_entropy_1_to_q"] for c in r["values"].values()], marker="o")
        ax.axvline(values.index(f"{r['default']:g}"), color="grey", linestyle="--", linewidth=1)
        ax.set_xticks(range(len(values)), values)
        ax.set_xlabel(SYMBOL[r["setting"]])
        ax.set_title(row, fontsize=9)
    np.atleast_1d(axes)[0].set_ylabel("mean CE, queries 1..Q (val)")
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, out, dpi=120, trim=False)


@space_experiment
def run_choose_experiment(run: Inputs) -> dict[str, Any]:
    """The rows of `GRIDS` under the answer-model learner on the val protocol (module docstring); writes
    choose.json/.md."""
    from langpref.reward import LearnRewardConfig
    from langpref.reward.answer_model import AnswerModelConfig

    given = run.config or LearnRewardConfig()
    base = replace(given, learner="answer-model", query_split="train", eval_split="val", human=prior_human(given.human))
    results, _, space, run = run_methods("choose", run, _methods(base), named_for=given.human)
    defaults = AnswerModelConfig()
    rows = {
        row: _row(results, row, field, values, getattr(defaults, field)) for row, (_, field, values, _) in GRIDS.items()
    }
    figure = plot_choices(rows, run.out / "choose.png", f"The answer model's settings on val, {run.env}")
    fields = {
        "figure": str(figure),
        "seed": base.seed,
        "eval_split": "val",
        "phrasings": base.human.phrase_source,
        "rows": rows,
        "methods": results,
    }
    return save_summary("choose", run, space, base, fields, _markdown)


def _cell(d: dict) -> str:
    return f"{d['mean']:+.3f} ({d['low']:+.3f} to {d['high']:+.3f})"


def _markdown(summary: dict[str, Any]) -> str:
    lines = [
        f"### The answer model's settings, chosen on val, {summary['env']}",
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['humans']} humans x "
        f"{summary['seeds']} seeds of the val stream of seed {summary['seed']}, other humans than the test "
        f"experiments', the language human speaking {summary['phrasings']} phrasings; metrics on the val split). AUC "
        "of the best val trajectory's true reward over query counts 0..Q / mean cross-entropy over queries 1..Q; "
        "below each, the difference to the default value, 95% t-interval over the humans (AUC; CE). The lowest CE "
        "of each row in bold.",
        "",
    ]
    for row, r in summary["rows"].items():
        values = list(r["values"])
        head = [f"{SYMBOL[r['setting']]} = {v}" + (" (default)" if float(v) == r["default"] else "") for v in values]
        lines += [f"| {row} | " + " | ".join(head) + " |", "|---|" + "---|" * len(values)]
        level = []
        for v in values:
            c = r["values"][v]
            text = f"{c['auc_true_reward']:.3f} / {c['mean_cross_entropy_1_to_q']:.3f}"
            level.append(f"**{text}**" if float(v) == r["lowest_ce"] else text)
        diffs = [
            _cell(r["values"][v]["auc_true_reward_minus_default"])
            + "; "
            + _cell(r["values"][v]["mean_cross_entropy_1_to_q_minus_default"])
            if float(v) != r["default"]
            else "-"
            for v in values
        ]
        lines += ["| AUC / CE | " + " | ".join(level) + " |", "| - default | " + " | ".join(diffs) + " |", ""]
    lines += [f"![the answer model's settings on val, {summary['env']}]({figure_link(summary['figure'])})"]
    return "\n".join(lines) + "\n"
