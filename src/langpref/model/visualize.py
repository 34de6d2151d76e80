"""Figures of a model: `langpref visualize` (the latent space at a glance) and the training curve.

The trajectories' phi projected onto their first two principal components, one panel per feature, each point
coloured by that feature's value; in every panel two arrows, the mean psi of the feature's `increase` and
`decrease` meanings (the model's prototypes) projected onto the same two components, drawn from the centre of the
cloud with a length proportional to the share of psi that lies in that plane. In an aligned space the `increase`
arrow points from the low-valued points toward the high-valued ones.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError


def pca_2d(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(projected (N, 2), components (2, D), explained variance ratio (2,)) of the rows of x."""
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    comps = vt[:2]
    if comps.shape[0] < 2:
        comps = np.vstack([comps, np.zeros((2 - comps.shape[0], x.shape[1]))])
    var = s**2
    ratio = var[:2] / var.sum() if var.sum() > 0 else np.zeros(2)
    return (x - mean) @ comps.T, comps, np.pad(ratio, (0, 2 - len(ratio)))


def visualize(model, dataset, out: str | Path, split: str | None = None) -> dict:
    """Draw the picture into `out` (.png, .pdf or .svg); returns a small summary."""
    from langpref.extras import pyplot

    plt = pyplot("langpref visualize")

    out = Path(out)
    if out.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise LangprefError(f"--out {out} must end in .png, .pdf or .svg")
    model.check_dataset(dataset)
    idx = list(range(len(dataset))) if split is None else dataset.split(split)
    if len(idx) < 3:
        raise LangprefError(f"need at least 3 trajectories to draw, {split or 'the dataset'} has {len(idx)}")
    phi = model.encode_dataset(dataset, split).double().cpu().numpy()
    proto = model.prototypes.double().cpu().numpy()
    pts, comps, ratio = pca_2d(phi)
    arrows = proto @ comps.T  # directions only: the PCA mean is a translation
    names = model.feature_names
    feats = dataset.features[idx]
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 4.0), squeeze=False)
    span = np.ptp(pts, axis=0).max() or 1.0
    centre = pts.mean(axis=0)
    tips = [
        centre + 1.15 * arrows[g] / np.linalg.norm(proto[g]) * 0.45 * span
        for g in range(len(proto))
        if np.linalg.norm(proto[g]) > 0
    ]
    box = np.vstack([pts, *tips]) if tips else pts
    lo, hi = box.min(axis=0), box.max(axis=0)
    pad = 0.06 * (hi - lo + 1e-9)
    for f, (ax, name) in enumerate(zip(axes[0], names)):
        ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
        ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
        sc = ax.scatter(pts[:, 0], pts[:, 1], c=feats[:, f], cmap="viridis", s=14, alpha=0.85)
        fig.colorbar(sc, ax=ax, fraction=0.046, pad=0.04, label=name)
        for d, (direction, colour) in enumerate((("increase", "tab:red"), ("decrease", "tab:blue"))):
            v = arrows[2 * f + d]
            full = np.linalg.norm(proto[2 * f + d])
            if np.linalg.norm(v) == 0 or full == 0:
                continue
            v = v / full * 0.45 * span  # length: the share of psi that lies in the PCA plane
            ax.annotate("", xy=centre + v, xytext=centre, arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 2.2})
            ax.text(*(centre + 1.08 * v), direction, color=colour, fontsize=8, ha="center", va="center")
        ax.set_title(f"{name}", fontsize=10)
        ax.set_xlabel(f"PC1 ({ratio[0]:.0%})")
        ax.set_ylabel(f"PC2 ({ratio[1]:.0%})")
    fig.suptitle(
        f"{model.info.env}: trajectory embeddings phi (PCA) and language directions psi "
        f"({len(idx)} trajectories{', ' + split if split else ''})",
        fontsize=10,
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return {"out": str(out), "num_trajectories": len(idx), "explained_variance": [float(r) for r in ratio]}


def plot_history(history: list[dict[str, Any]], path: Path, title: str = "") -> Path:
    """Training curve: loss and accuracy (train, validation) per epoch, stage 2 after the dashed line."""
    from langpref.extras import pyplot

    plt = pyplot("the training curve")

    x = np.arange(1, len(history) + 1)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax1.plot(x, [h["loss"] for h in history], label="loss")
    ax1.plot(x, [h["align"] for h in history], label="L_align", alpha=0.7)
    ax1.set_xlabel("epoch")
    ax1.set_ylabel("train loss")
    ax2.plot(x, [h["train_acc"] for h in history], label="train (sampled phrasings)")
    ax2.plot(x, [h["val_acc"] for h in history], label="validation")
    ax2.set_xlabel("epoch")
    ax2.set_ylabel("alignment accuracy")
    n1 = sum(1 for h in history if h["stage"] == 1)
    for ax in (ax1, ax2):
        if 0 < n1 < len(history):
            ax.axvline(n1 + 0.5, color="grey", linestyle="--", linewidth=1)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(title or "latent-space training (stage 2 right of the dashed line)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
