"""What a learned reward wants, in the task's own terms: which feature it pushes up, which down, and how much.

A reward is learned on phi, which no one reads; its preferences show in how it ranks the dataset's trajectories.
`what_it_wants` regresses r_xi of every trajectory on the task's features, each standardised over the dataset, by
least squares: a feature's weight is the change of the reward, in standard deviations of the reward over the
dataset, per standard deviation of that feature with the others held fixed. Beside each weight, the plain
correlation of the feature with the reward (which the weight can disagree with where features move together), and
how much of the reward the features explain (R^2: low means it rewards something the features do not measure). The
trajectories it ranks best and worst are named by dataset index.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

TOP = 3
"""Best and worst trajectories listed."""


def what_it_wants(reward: np.ndarray, theta: np.ndarray, feature_names: Sequence[str]) -> dict[str, Any]:
    """{features: {name: {weight, correlation}}, explained (R^2), best, worst} of a reward's values `reward` (N,) of
    a dataset's trajectories, whose features are `theta` (N, F) (module docstring)."""
    r = np.asarray(reward, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    r_sd = float(r.std())
    x_sd = theta.std(axis=0)
    live = x_sd > 1e-12
    x = np.zeros_like(theta)
    x[:, live] = (theta[:, live] - theta[:, live].mean(axis=0)) / x_sd[live]
    y = (r - r.mean()) / r_sd if r_sd > 1e-12 else np.zeros_like(r)
    coef = np.linalg.lstsq(x, y, rcond=None)[0] if len(r) > 1 else np.zeros(theta.shape[1])
    fitted = x @ coef
    explained = float(1.0 - np.sum((y - fitted) ** 2) / np.sum(y**2)) if r_sd > 1e-12 else 0.0
    corr = x.T @ y / max(len(y), 1)
    order = np.argsort(-r, kind="stable")
    return {
        "features": {
            name: {"weight": round(float(coef[i]), 4), "correlation": round(float(corr[i]), 4)}
            for i, name in enumerate(feature_names)
        },
        "explained": round(explained, 4),
        "best": [int(i) for i in order[:TOP]],
        "worst": [int(i) for i in order[::-1][:TOP]],
    }


def describe(wants: dict[str, Any]) -> str:
    """One line in words, strongest first: "wants speed up (+0.81), height down (-0.32), ...; the features explain
    94% of it"."""
    items = sorted(wants["features"].items(), key=lambda kv: -abs(kv[1]["weight"]))
    parts = [
        f"{name} {'up' if w['weight'] > 0 else 'down'} ({w['weight']:+.2f})" for name, w in items if w["weight"] != 0
    ]
    return f"wants {', '.join(parts) or 'nothing yet'}; the features explain {wants['explained']:.0%} of it"


def plot_wants(rewards: list[dict[str, Any]], out: str | Path, title: str = "") -> Path:
    """One panel per reward (`name` and `wants` of each): its weight on each feature as a bar, up or down, with the
    plain correlation as a tick beside it, and the share the features explain in the panel's title."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the figure of what a reward wants")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    n = max(len(rewards), 1)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n + 0.8, 3.2), sharey=True, squeeze=False)
    for ax, entry in zip(axes[0], rewards):
        features = entry["wants"]["features"]
        names = list(features)
        weights = [features[f]["weight"] for f in names]
        ax.barh(names, weights, color=["tab:blue" if w >= 0 else "tab:red" for w in weights])
        ax.scatter([features[f]["correlation"] for f in names], names, marker="|", s=200, color="black", zorder=3)
        ax.axvline(0.0, color="grey", linewidth=0.8)
        ax.set_title(f"{entry['name']} (explains {entry['wants']['explained']:.0%})", fontsize=9)
        ax.set_xlabel("weight (bar), correlation (tick)", fontsize=8)
    fig.suptitle(title or "what each learned reward wants, per standard deviation of a feature")
    fig.tight_layout()
    return save_figure(fig, out)
