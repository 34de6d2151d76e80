"""The learning-curve figure of reward learning (the paper's Fig. 5/6 analogue), drawn from the summaries of
`summarise_curves`: `langpref learn-reward --figure`, the reward experiments (`langpref.experiments.reward`) and the
demo each draw it, so it lives beside the curves it plots, not in one experiment the others borrow it from."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_reward_curves(results: dict[str, dict], out: str | Path, title: str = "") -> Path:
    """Fig. 5/6 analogue: (a) cross-entropy and (b) normalised true reward of the best test trajectory per query,
    one line (mean, with a +-std band) per entry of `results` (name -> a `summarise_curves` summary)."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the reward-learning figure")

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, key, label in (
        (axes[0], "cross_entropy", "(a) cross-entropy CE(P_w, P_xi)"),
        (axes[1], "true_reward_of_best", "(b) true reward of the best test trajectory"),
    ):
        for name, res in results.items():
            mean, std = np.array(res[key]), np.array(res[f"{key}_std"])
            x = np.arange(len(mean))
            ax.plot(x, mean, label=name)
            ax.fill_between(x, mean - std, mean + std, alpha=0.2)
        ax.set_xlabel("queries")
        ax.set_title(label, fontsize=10)
        ax.legend(fontsize=8)
    axes[1].set_ylim(-0.05, 1.05)
    fig.suptitle(title)
    return save_figure(fig, out, dpi=120, trim=False)
