"""Describe a dataset: sizes, splits, feature ranges, correlations, success rate and checksum (`langpref inspect`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from langpref.dataset.checksum import checksum_parts, combine
from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.tasks import get_task


def describe(root: str | Path) -> dict[str, Any]:
    ds = load_dataset(root)
    feats = ds.features
    corr = np.corrcoef(feats.T) if len(feats) > 1 else np.eye(feats.shape[1])
    corr = np.nan_to_num(corr)  # a constant feature has no correlation
    parts = checksum_parts(ds)
    return {
        "path": str(ds.root),
        "env": ds.env,
        "schema_version": ds.meta.schema_version,
        "num_trajectories": len(ds),
        "horizon": ds.meta.horizon,
        "lengths": _lengths(ds.meta.lengths, ds.meta.horizon, len(ds)),
        "obs_dim": ds.meta.obs_dim,
        "action_dim": ds.meta.action_dim,
        "splits": {name: len(idx) for name, idx in ds.meta.splits.items()},
        "frames": ds.meta.frames,
        "success_rate": float(ds.success.mean()),
        "features": {
            name: {"min": float(col.min()), "max": float(col.max()), "mean": float(col.mean()), "std": float(col.std())}
            for name, col in zip(ds.feature_names, feats.T)
        },
        "feature_names": ds.feature_names,
        "feature_correlation": [[round(float(v), 4) for v in row] for row in corr],
        "max_abs_off_diagonal_correlation": (
            float(np.max(np.abs(corr - np.diag(np.diag(corr))))) if len(corr) > 1 else 0.0
        ),
        "env_version": ds.meta.config.get("env_version"),
        "env_version_current": _current_env_version(ds),
        "checksum": combine(parts),
        "checksum_parts": parts,
    }


def _lengths(lengths: list[int] | None, horizon: int, n: int) -> dict[str, float]:
    """The episodes' lengths in steps (min, max, mean): a recording's episodes differ, a generated dataset's are all
    `horizon` long (its meta.json stores no lengths)."""
    steps = np.asarray(lengths if lengths is not None else [horizon] * n, dtype=np.float64)
    return {"min": int(steps.min()), "max": int(steps.max()), "mean": float(steps.mean())}


def _size_line(d: dict[str, Any]) -> str:
    """ "N trajectories x T steps", or with lengths that differ "N trajectories of MIN-MAX steps (mean M)"."""
    ln = d.get("lengths") or {"min": d["horizon"], "max": d["horizon"], "mean": d["horizon"]}
    if ln["min"] == ln["max"]:
        return f"{d['num_trajectories']} trajectories x {ln['max']} steps"
    return f"{d['num_trajectories']} trajectories of {ln['min']}-{ln['max']} steps (mean {ln['mean']:.0f})"


def _current_env_version(ds) -> int | None:
    """This langpref's version of the simulator that made a generated dataset (None for a recorded one)."""
    if "generator" not in ds.meta.config:
        return None
    try:
        simulator = get_task(ds.env).simulator
    except LangprefError:  # a plugin's task that is not installed here
        return None
    return None if simulator is None else simulator.version


def _frames_line(frames: dict[str, Any] | None) -> str:
    if not frames:
        return "none"
    where = {"render": "rendered in the simulator", "image": "decoded from the recorded images"}.get(
        frames["source"], "decoded from the recorded videos"
    )
    return f"{frames['width']}x{frames['height']}, every {frames['stride']} steps, {where}"


def format_description(d: dict[str, Any]) -> str:
    lines = [
        f"{d['path']}: {d['env']} dataset, {_size_line(d)} (obs {d['obs_dim']}, action {d['action_dim']})",
        "splits: " + ", ".join(f"{k} {v}" for k, v in d["splits"].items()),
        f"camera frames: {_frames_line(d.get('frames'))}",
        f"task success: {d['success_rate']:.1%}",
        f"{'feature':<20}{'min':>9}{'max':>9}{'mean':>9}{'std':>9}",
    ]
    for name, s in d["features"].items():
        lines.append(f"{name:<20}{s['min']:>9.3f}{s['max']:>9.3f}{s['mean']:>9.3f}{s['std']:>9.3f}")
    lines.append("feature correlation:")
    names = d["feature_names"]
    for name, row in zip(names, d["feature_correlation"]):
        lines.append(f"  {name:<20}" + "".join(f"{v:>7.2f}" for v in row))
    lines.append(f"largest |off-diagonal correlation|: {d['max_abs_off_diagonal_correlation']:.2f}")
    lines.append(f"checksum (sha256 of the data, see `langpref.dataset.checksum`): {d['checksum']}")
    made, now = d.get("env_version") or 1, d.get("env_version_current")
    if now is not None and made != now:
        lines.append(
            f"made by version {made} of the {d['env']} simulator, this langpref has version {now} "
            "(see CHANGELOG.md): regenerate it to get what this version makes"
        )
    return "\n".join(lines)


def plot_dataset(root: str | Path, out: str | Path) -> Path:
    """`langpref inspect --figure`: each feature's spread over the dataset (a histogram, successes and failures
    stacked) and the features' correlation matrix as a heatmap, into the PNG `out`."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the figure of a dataset's features")
    ds = load_dataset(root)
    names, feats = list(ds.feature_names), ds.features
    corr = np.nan_to_num(np.corrcoef(feats.T)) if len(feats) > 1 else np.eye(len(names))
    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    side = 1.6 + 0.6 * len(names)
    fig = plt.figure(figsize=(2.9 * cols + side + 1.2, max(2.5 * rows, side) + 0.8), layout="constrained")
    grid = fig.add_gridspec(rows, cols + 1, width_ratios=[1.0] * cols + [side / 2.6])
    success = ds.success.astype(bool)
    for k, (name, col) in enumerate(zip(names, feats.T)):
        ax = fig.add_subplot(grid[k // cols, k % cols])
        ax.hist([col[success], col[~success]], bins=20, stacked=True, color=["tab:green", "tab:grey"])
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("feature value", fontsize=8)
        ax.set_ylabel("trajectories", fontsize=8)
        ax.yaxis.get_major_locator().set_params(integer=True)
        if k == 0:
            ax.legend(["task succeeded", "task failed"], fontsize=7)
    heat = fig.add_subplot(grid[:, cols])
    _correlation_heatmap(heat, names, corr)
    heat.set_title("feature correlation (Pearson)", fontsize=10)
    fig.suptitle(
        f"{ds.env} dataset {ds.root.name}: each feature's spread over {len(feats)} trajectories, and how the "
        "features correlate"
    )
    return save_figure(fig, out)


def _correlation_heatmap(ax, names: list[str], corr: np.ndarray) -> None:
    """`corr` as a red (positive) to blue (negative) heatmap over -1..1, each cell's value written in it."""
    image = ax.imshow(corr, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    if len(names) <= 12:
        for i, row in enumerate(corr):
            for j, v in enumerate(row):
                ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=7, color="white" if abs(v) > 0.6 else "k")
    ax.figure.colorbar(image, ax=ax, shrink=0.8, label="correlation")
