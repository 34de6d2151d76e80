"""`langpref bank check --figure`: the picture of a `BankCheck` (`langpref.language.check`), which meaning is read as
which (the confusion matrix of meanings) and how often each meaning is read as itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from langpref.language.check import BankCheck


def confusion(result: BankCheck) -> tuple[list[str], np.ndarray]:
    """(meanings, counts): counts[i, j] is how many phrasings of meaning i were read as meaning j."""
    names = list(result.meanings)
    counts = np.zeros((len(names), len(names)), dtype=int)
    for i, m in enumerate(result.meanings.values()):
        if m.accuracy is not None:
            counts[i, i] = round(m.accuracy * m.count)
        for other, n in m.confused_with.items():
            counts[i, names.index(other)] += n
    return names, counts


def plot_bank_check(result: BankCheck, out: str | Path) -> Path:
    """Left: the confusion matrix of meanings, each row (a meaning's phrasings) as shares of what they were read as,
    with the counts written in. Right: each meaning's accuracy, weak ones in red, with the weak threshold and the
    chance line (one meaning among all of them)."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the figure of a bank check")
    names, counts = confusion(result)
    size = 2.0 + 0.55 * len(names)
    fig, (left, right) = plt.subplots(
        1, 2, figsize=(2 * size + 3.0, size + 0.6), width_ratios=[size, size * 0.8], layout="constrained"
    )
    _confusion_heatmap(left, names, counts)
    _accuracy_bars(right, result, names)
    fig.suptitle(
        f"bank check of {result.task}: which meaning each phrasing is read as ({result.encoder}, {result.method})",
        fontsize=11,
    )
    return save_figure(fig, out)


def _confusion_heatmap(ax, names: list[str], counts: np.ndarray) -> None:
    rows = counts.sum(axis=1, keepdims=True)
    share = np.divide(counts, rows, out=np.zeros(counts.shape), where=rows > 0)
    image = ax.imshow(share, cmap="Blues", vmin=0.0, vmax=1.0)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_xlabel("read as")
    ax.set_ylabel("meaning of the phrasing")
    for i, j in zip(*np.nonzero(counts)):
        ax.text(
            j, i, str(counts[i, j]), ha="center", va="center", fontsize=7, color="white" if share[i, j] > 0.5 else "k"
        )
    ax.set_title("confusion of meanings (phrasings read as each)", fontsize=10)
    ax.figure.colorbar(image, ax=ax, shrink=0.7, label="share of the meaning's phrasings")


def _accuracy_bars(ax, result: BankCheck, names: list[str]) -> None:
    y = np.arange(len(names))
    acc = [result.meanings[n].accuracy for n in names]
    colors = ["tab:red" if result.meanings[n].weak else "tab:blue" for n in names]
    ax.barh(y, [0.0 if a is None else a for a in acc], color=colors)
    for k, (a, n) in enumerate(zip(acc, names)):
        said = "n/a: under 2 phrasings" if a is None else f"{a:.2f} of {result.meanings[n].count}"
        ax.text(0.01 if a is None else a + 0.01, k, said, va="center", fontsize=7)
    chance = 1.0 / max(len(names), 1)
    ax.axvline(result.threshold, color="tab:red", linestyle="--", linewidth=1, label=f"weak below {result.threshold:g}")
    ax.axvline(chance, color="grey", linestyle=":", linewidth=1, label=f"chance (1 in {len(names)})")
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0.0, 1.15)
    ax.set_xticks(np.linspace(0.0, 1.0, 6))
    ax.set_xlabel("accuracy: share read as its own meaning")
    total = "n/a" if result.accuracy is None else f"{result.accuracy:.0%}"
    ax.set_title(f"per-meaning accuracy (all: {total}; weak in red)", fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
