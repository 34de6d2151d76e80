"""The study's PNG figures from its summary (`stats.analyse`): one function per figure, `figures` makes them all.

study1_attributes  Study 1's attribute scores            study1_iterations  iterations to satisfaction
study2_attributes  Study 2's attribute scores by method  study2_ratings     rating curves by method (Fig. 9)
study2_time        seconds per query, per participant and on average (Appendix E)
study2_rewards     what each participant's learned reward wants, per method (only where the rewards were written)

`CAPTIONS` says in a sentence what each shows; the report puts it under the figure.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from langpref.study.protocol.config import METHODS
from langpref.study.protocol.surveys import METHOD_LABELS

COLORS = {"language": "#1f77b4", "comparison": "#ff7f0e"}
STUDY1_COLOR = "#2ca02c"


def figures(summary: dict[str, Any], out: Path) -> dict[str, str]:
    """Every figure of `FIGURES` as `out/NAME.png`; returns name -> file name."""
    from langpref.extras import pyplot

    plt = pyplot("the study's figures")
    made = {}
    for name, draw in DRAW.items():
        fig = draw(plt, summary)
        path = out / f"{name}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        made[name] = path.name
    return made


def _bar_err(ax, x, stats_list, label=None, width=0.8, offset=0.0, color=None) -> None:
    """Bars of the means with the standard deviations as error bars (a missing one drawn as 0)."""
    mean = [s["mean"] if s["mean"] is not None else 0.0 for s in stats_list]
    err = [s["std"] if s["std"] is not None else 0.0 for s in stats_list]
    ax.bar(np.asarray(x) + offset, mean, width, yerr=err, capsize=3, label=label, color=color)


def _labelled(fig, ax, title: str, ylabel: str, xlabel: str | None = None, ylim=None, legend: bool = False):
    """`fig` once its single axes `ax` has its title, axis labels, y range and legend (where given)."""
    if xlabel is not None:
        ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if ylim is not None:
        ax.set_ylim(*ylim)
    if legend:
        ax.legend(fontsize=8)
    ax.set_title(title)
    return fig


def study1_attributes(plt, summary: dict[str, Any]):
    """Study 1's attribute scores (mean and std, 1-5)."""
    a1 = summary["study1_attributes"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    _bar_err(ax, range(len(a1)), list(a1.values()), color=STUDY1_COLOR)
    ax.set_xticks(range(len(a1)), ["Satisfaction", "Adaptation speed", "Experience"][: len(a1)])
    return _labelled(fig, ax, "Study 1: attribute scores", "score (1-5)", ylim=(0, 5.5))


def study1_iterations(plt, summary: dict[str, Any]):
    """How many participants were satisfied after each round, and how many never were."""
    it = summary["study1_iterations_to_satisfaction"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    keys = list(it["histogram"]) + ["never"]
    ax.bar(range(len(keys)), list(it["histogram"].values()) + [it["not_satisfied"]], color=STUDY1_COLOR)
    ax.set_xticks(range(len(keys)), keys)
    return _labelled(fig, ax, "Study 1: iterations to satisfaction", "participants", "iterations to satisfaction")


def study2_attributes(plt, summary: dict[str, Any]):
    """Study 2's attribute scores, the two methods side by side."""
    a2 = summary["study2_attributes"]
    fig, ax = plt.subplots(figsize=(6, 3.4))
    x = np.arange(len(a2))
    for k, m in enumerate(METHODS):
        _bar_err(
            ax, x, [a2[s][m] for s in a2], label=METHOD_LABELS[m], width=0.38, offset=(k - 0.5) * 0.4, color=COLORS[m]
        )
    ax.set_xticks(x, ["Adaptation speed", "Experience", "Noticed learning", "Trust"][: len(a2)])
    return _labelled(fig, ax, "Study 2: attribute scores", "score (1-5)", ylim=(0, 5.5), legend=True)


def study2_ratings(plt, summary: dict[str, Any]):
    """Rating of the best trajectory after each rating point, mean +- std per method (Fig. 9)."""
    r = summary["study2_ratings"]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    for m in METHODS:
        pts = [int(q) for q in r["points"]]
        stats_m = [r[m]["per_point"][str(q)] for q in pts]
        mean = np.array([s["mean"] if s["mean"] is not None else np.nan for s in stats_m])
        std = np.array([s["std"] if s["std"] is not None else 0.0 for s in stats_m])
        ax.plot(pts, mean, "o-", color=COLORS[m], label=METHOD_LABELS[m])
        ax.fill_between(pts, mean - std, mean + std, color=COLORS[m], alpha=0.2)
    return _labelled(
        fig, ax, "Study 2: ratings", "rating of the best trajectory (1-5)", "queries", ylim=(0.5, 5.5), legend=True
    )


def study2_time(plt, summary: dict[str, Any]):
    """Seconds per query: per participant and method, and the mean per method (Appendix E)."""
    t = summary["study2_time_per_query_s"]
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), gridspec_kw={"width_ratios": [3, 1]})
    pids = sorted(set(t["language"]["per_participant_s"]) | set(t["comparison"]["per_participant_s"]))
    x = np.arange(len(pids))
    for k, m in enumerate(METHODS):
        axes[0].bar(
            x + (k - 0.5) * 0.4,
            [t[m]["per_participant_s"].get(p, 0.0) for p in pids],
            0.38,
            color=COLORS[m],
            label=METHOD_LABELS[m],
        )
    top = max([t[m]["per_participant_s"].get(p, 0.0) for m in METHODS for p in pids] or [1.0])
    axes[0].set_ylim(0, 1.35 * top if top > 0 else 1.0)  # room for the legend
    axes[0].set_xticks(x, [str(i + 1) for i in range(len(pids))])
    axes[0].set_xlabel("participant")
    axes[0].set_ylabel("seconds per query")
    axes[0].legend(fontsize=8, ncol=2, loc="upper left")
    _bar_err(axes[1], range(2), [t[m] for m in METHODS], color=[COLORS[m] for m in METHODS])
    axes[1].set_xticks(range(2), ["Language", "Comparison"])
    axes[1].set_title("mean")
    fig.suptitle("Study 2: time per query")
    return fig


DRAW: dict[str, Callable[[Any, dict[str, Any]], Any]] = {
    "study1_attributes": study1_attributes,
    "study1_iterations": study1_iterations,
    "study2_attributes": study2_attributes,
    "study2_ratings": study2_ratings,
    "study2_time": study2_time,
}
"""Each figure's drawing function: (pyplot, summary) -> figure."""
FIGURES = tuple(DRAW)

CAPTIONS = {
    "study1_attributes": "Study 1: mean score (1-5) of each attribute, the error bar one standard deviation.",
    "study1_iterations": "Study 1: how many participants were satisfied after each round of improvement, and how "
    "many never were.",
    "study2_attributes": "Study 2: mean score (1-5) of each attribute, language beside comparison.",
    "study2_ratings": "Study 2 (the paper's Fig. 9): the rating (1-5) of the trajectory each method's learned reward "
    "ranks best, after each number of queries; the band is one standard deviation over participants. A curve that "
    "rises sooner learned what people wanted from fewer answers.",
    "study2_time": "Study 2 (Appendix E): seconds per query for each participant and method, and the mean.",
    "study2_rewards": "What each participant's learned reward wants: its weight on each feature (per standard "
    "deviation of the feature, red up, blue down) for each method, and in brackets the share of the reward the "
    "features explain. Rows that agree across a method mean its participants asked for the same thing.",
}
"""Each figure's caption in the report: what it shows and how to read it."""


def rewards_figure(rewards: list[dict[str, Any]], out: Path) -> str | None:
    """`study2_rewards.png` into `out`: per Study-2 method a heatmap of each participant's learned reward's weight
    on each feature (`wants` of each entry, with `method` and `participant`); its file name, or None without any."""
    rows = [r for r in rewards if r.get("wants")]
    if not rows:
        return None
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the study's figures")
    methods = [m for m in METHODS if any(r["method"] == m for r in rows)] or sorted({r["method"] for r in rows})
    features = list(rows[0]["wants"]["features"])
    height = max(len([r for r in rows if r["method"] == m]) for m in methods)
    fig, axes = plt.subplots(
        1,
        len(methods),
        figsize=(1.8 + 1.3 * len(features) * len(methods), 1.6 + 0.35 * height),
        squeeze=False,
        layout="constrained",
    )
    for ax, method in zip(axes[0], methods):
        mine = [r for r in rows if r["method"] == method]
        weights = np.array([[r["wants"]["features"][f]["weight"] for f in features] for r in mine])
        top = max(float(np.abs(weights).max()), 1e-9)
        ax.imshow(weights, cmap="RdBu_r", vmin=-top, vmax=top, aspect="auto")
        ax.set_xticks(range(len(features)), features, rotation=30, ha="right", fontsize=8)
        ax.set_yticks(range(len(mine)), [f"{r['participant']} ({r['wants']['explained']:.0%})" for r in mine])
        for i, row in enumerate(weights):
            for j, v in enumerate(row):
                ax.text(
                    j, i, f"{v:+.2f}", ha="center", va="center", fontsize=7, color="w" if abs(v) > 0.6 * top else "k"
                )
        ax.set_title(METHOD_LABELS.get(method, method), fontsize=10)
    fig.suptitle("Study 2: what each participant's learned reward wants (weight per feature sd)", fontsize=10)
    return save_figure(fig, out / "study2_rewards.png").name
