"""`langpref label DATASET --reward R --out OUT`: a copy of a recording with per-frame columns of a learned reward.

Robot-learning code reads rewards where it reads the robot's data: a LeRobotDataset (v3) or a plain recording
folder (NAME.npz episodes). This writes a copy of either with three float32 columns per frame, computed by the saved
reward (`langpref.reward.load`) from each episode's observations and actions:

    langpref.reward_share     r_t, the frame's share of the episode's learned reward (`Reward.compute_reward`):
                              the episode's frames sum to r_xi(tau), up to float32 rounding
    langpref.reward_progress  v_t = r_xi of the episode up to and including this frame (`Reward.progress`): the
                              last frame's is r_xi(tau); a per-frame progress, as reward-weighted imitation reads one
    langpref.episode_reward   r_xi(tau) of the whole episode, on each of its frames (`Reward.trajectory_reward`)

Nothing of the original changes: every original column (or npz array) keeps its bytes, the videos are hard-linked
(copied where the file system cannot link), and everything else is copied. The copy is written beside OUT and moved
into place only when complete, so a failure leaves neither a half-written OUT nor a lost one. What was labelled with
which reward is written to `meta/langpref_label.json` (LeRobotDataset) or `langpref_label.json` (plain folder).

The columns and what both formats' writers share are `langpref.dataset.label_columns`; the writers are
`langpref.dataset.label_plain` and `langpref.dataset.label_lerobot`; this module has the command and its figure.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.dataset.label_columns import COLUMNS
from langpref.dataset.label_plain import label_plain
from langpref.dataset.recording import is_lerobot
from langpref.errors import LangprefError
from langpref.extras import needs

RECORD = "langpref_label.json"
"""What was labelled with which reward: at the top of a plain folder, in meta/ of a LeRobotDataset."""


@dataclass
class LabelConfig:
    """What `langpref label` reads and writes."""

    dataset: Path
    """A LeRobotDataset (v3, with meta/info.json) or a plain recording folder (NAME.npz episodes)."""
    reward: Path
    """A saved reward: a `--save-reward` directory (its reward.json) or a reward-NAME.json file."""
    out: Path
    """The labelled copy to create (a new folder)."""
    task: str | None = None
    """Refuse the reward unless it was learned on this task (its name, as `langpref tasks` lists it)."""
    state_key: str = "observation.state"
    """LeRobotDataset: the feature the reward reads as observations."""
    action_key: str = "action"
    """LeRobotDataset: the feature the reward reads as actions."""
    force: bool = False
    """Replace an existing OUT."""


def label_dataset(
    cfg: LabelConfig, reward: Any, progress: bool = True, figure: str | Path | None = None
) -> dict[str, Any]:
    """Write the labelled copy of `cfg.dataset` to `cfg.out` with `reward` (the saved reward at `cfg.reward`, as
    `langpref.reward.load` opened it: the reward side is opened by the caller, so that datasets need nothing of it)
    and return its summary: `episodes`, `frames`, `seconds` (wall time), `out`, `format` (`lerobot` or `plain`),
    `columns` and the episodes' learned rewards (`episode_reward`: mean, min, max). With `figure`, also draw the
    episodes' v_t curves into that PNG (`plot_progress`) and name it in the summary's `figure`."""
    start = time.perf_counter()
    src, out = Path(cfg.dataset), Path(cfg.out)
    _check_paths(src, out, cfg.force)
    if cfg.task is not None and reward.task != cfg.task:
        raise LangprefError(f"the reward {reward.path} was learned on task {reward.task!r}, not {cfg.task!r}")
    tmp = out.parent / f".{out.name}.labelling-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    try:
        if is_lerobot(src):
            with needs("lerobot", "labelling a LeRobotDataset"):
                from langpref.dataset.label_lerobot import label_lerobot
            kind, totals = "lerobot", label_lerobot(src, tmp, reward, cfg.state_key, cfg.action_key, progress)
        else:
            kind, totals = "plain", label_plain(src, tmp, reward, progress)
        _write_record(tmp / (Path("meta") if kind == "lerobot" else Path()) / RECORD, src, reward, kind)
        if out.is_dir() and not out.is_symlink():
            shutil.rmtree(out)
        elif out.exists() or out.is_symlink():
            out.unlink()
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    rewards = totals["episode_rewards"]
    summary = {
        "episodes": len(rewards),
        "frames": totals["frames"],
        "seconds": round(time.perf_counter() - start, 3),
        "out": str(out),
        "format": kind,
        "columns": list(COLUMNS),
        "episode_reward": {"mean": float(np.mean(rewards)), "min": float(min(rewards)), "max": float(max(rewards))},
    }
    if figure is not None:
        summary["figure"] = str(plot_progress(totals["curves"], figure, reward.task))
    return summary


def _check_paths(src: Path, out: Path, force: bool) -> None:
    """One-line errors before any work: no dataset, OUT taken (without --force), OUT and the dataset overlapping."""
    if not src.exists():
        raise LangprefError(f"dataset {src} not found (a LeRobotDataset v3 or a folder of NAME.npz episodes)")
    if not src.is_dir():
        raise LangprefError(f"dataset {src} is not a folder (a LeRobotDataset v3 or a folder of NAME.npz episodes)")
    if out.exists() and not force:
        raise LangprefError(f"{out} already exists; pass --force to replace it or choose another --out")
    s, o = src.resolve(), out.resolve()
    if o == s or s in o.parents or o in s.parents:
        raise LangprefError(f"--out {out} and the dataset {src} overlap; choose a folder outside the dataset")


MOST_CURVES = 200
"""`plot_progress` draws at most this many episodes' curves in grey (spread over the range of their rewards)."""


def plot_progress(curves: dict[str, np.ndarray], out: str | Path, task: str = "") -> Path:
    """`langpref label --figure`: left, each episode's v_t (the learned reward so far) along its frames, the best and
    the worst episode (by r_xi(tau), the last v_t) highlighted; right, how the episodes' learned rewards spread."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the figure of the learned reward along each episode")
    names = sorted(curves, key=lambda n: float(curves[n][-1]))
    totals = np.array([float(curves[n][-1]) for n in names])
    fig, (left, right) = plt.subplots(1, 2, figsize=(12.0, 4.4), width_ratios=[2.0, 1.0], layout="constrained")
    shown = [names[int(k)] for k in np.unique(np.linspace(0, len(names) - 1, min(len(names), MOST_CURVES)).round())]
    for name in shown:
        left.plot(curves[name], color="grey", alpha=0.35, linewidth=0.8)
    for name, color, which in ((names[-1], "tab:green", "best"), (names[0], "tab:red", "worst")):
        left.plot(curves[name], color=color, linewidth=2.2, label=f"{which}: {name} ({float(curves[name][-1]):.3g})")
    left.set_xlabel("frame")
    left.set_ylabel("v_t: learned reward of the episode so far")
    some = f"{len(shown)} of {len(names)}" if len(shown) < len(names) else f"all {len(names)}"
    left.set_title(f"the learned reward along each episode ({some} episodes, grey)", fontsize=10)
    left.legend(fontsize=8)
    right.hist(totals, bins=min(30, max(5, len(totals) // 3)), color="tab:blue", edgecolor="white")
    right.axvline(totals[-1], color="tab:green", linewidth=2, label="best")
    right.axvline(totals[0], color="tab:red", linewidth=2, label="worst")
    right.set_xlabel("r_xi(tau): the episode's learned reward")
    right.set_ylabel("episodes")
    right.yaxis.get_major_locator().set_params(integer=True)
    right.set_title("the episodes' learned rewards", fontsize=10)
    right.legend(fontsize=8)
    fig.suptitle(f"langpref label: the learned reward{f' of task {task}' if task else ''} on {len(names)} episodes")
    return save_figure(fig, out)


def _write_record(path: Path, src: Path, reward: Any, kind: str) -> None:
    """What was labelled with which reward, and what each column holds, as JSON at `path`."""
    from langpref import __version__

    doc = {
        "written_by": f"langpref {__version__}",
        "source": str(src.resolve()),
        "format": kind,
        "reward": {
            "path": str(Path(reward.path).resolve()),
            "task": reward.task,
            "kind": reward.kind,
            "format_version": reward.doc.get("format_version", 1),
            "model": reward.doc.get("model", {}),
        },
        "columns": {name: {"dtype": "float32", "shape": [1], "meaning": text} for name, text in COLUMNS.items()},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
