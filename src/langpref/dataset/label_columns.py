"""The columns `langpref label` adds to a recording, computed per episode from a saved reward, and what the writers
of both formats (`label_plain`, `label_lerobot`) share: the size check, linking videos, the progress bar."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from langpref.errors import LangprefError

SHARE = "langpref.reward_share"
PROGRESS = "langpref.reward_progress"
EPISODE = "langpref.episode_reward"
COLUMNS = {
    SHARE: "r_t, this frame's share of the episode's learned reward; an episode's frames sum to its r_xi(tau)",
    PROGRESS: "v_t, the learned reward r_xi of the episode up to and including this frame; the last is r_xi(tau)",
    EPISODE: "r_xi(tau), the learned reward of the whole episode, on each of its frames",
}
"""The columns `label` adds, each float32 with one value per frame, and what each holds."""


def episode_columns(reward: Any, observations: np.ndarray, actions: np.ndarray) -> dict[str, np.ndarray]:
    """The label columns of one episode (T,) each, float32, from the saved `reward`."""
    share = reward.compute_reward(observations, actions)
    so_far = reward.progress(observations, actions)
    total = np.full(len(share), float(so_far[-1]))
    return {SHARE: share.astype(np.float32), PROGRESS: so_far.astype(np.float32), EPISODE: total.astype(np.float32)}


def check_sizes(reward: Any, obs_dim: int, action_dim: int, where: str) -> None:
    """A one-line error when the dataset's observations or actions are not the size the reward was learned on."""
    if (obs_dim, action_dim) != (reward.obs_dim, reward.action_dim):
        raise LangprefError(
            f"the reward {reward.path} was learned on task {reward.task!r} with observations of {reward.obs_dim} "
            f"and actions of {reward.action_dim} numbers; {where} has {obs_dim} and {action_dim}: label with a "
            "reward learned on this robot's data"
        )


def link_or_copy(src: Path, dst: Path) -> None:
    """`dst` as a hard link to `src` (no bytes copied), or a copy where the file system cannot link."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def bar(items: Iterable, desc: str, total: int, progress: bool) -> Iterable:
    """A progress bar on stderr over `items` (one per episode)."""
    return tqdm(items, desc=desc, total=total, unit="episode", disable=not progress, dynamic_ncols=True)
