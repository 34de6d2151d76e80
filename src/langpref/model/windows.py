"""Windows of recorded episodes as extra training trajectories (`TrainConfig.windows`).

A task's feature of a trajectory is the time mean of its per-step features, theta(tau) = mean_t theta(s_t, a_t), so
any contiguous window of an episode is itself a trajectory whose features are known exactly: the mean of the
window's own per-step features. On a small recording (tens of episodes) the train split holds few ordered pairs;
windows multiply them, and each window shows the trajectory encoder a different stretch of an episode with its own
feature values. Only train episodes are cut: validation and evaluation see whole val/test episodes, as always.

A `Segments` table lists what one epoch trains on: every whole train episode first (start 0, its full length), then
the epoch's windows, each a row of the split (`row`), a first step (`start`) and a number of steps (`length`).
Pairs are then built over the segments' features exactly as over episodes' (`langpref.language.pairs.build_pairs`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from langpref.errors import LangprefError


@dataclass(frozen=True)
class Segments:
    """Contiguous pieces of a split's episodes: episode `row[i]` (a row of the split), steps start[i] ..
    start[i] + length[i] - 1, and their features (the time mean of those steps' per-step features)."""

    row: np.ndarray
    start: np.ndarray
    length: np.ndarray
    features: np.ndarray

    def __len__(self) -> int:
        return len(self.row)

    def __add__(self, other: Segments) -> Segments:
        return Segments(
            np.concatenate([self.row, other.row]),
            np.concatenate([self.start, other.start]),
            np.concatenate([self.length, other.length]),
            np.concatenate([self.features, other.features]),
        )


def whole_episodes(lengths: Sequence[int], features: np.ndarray) -> Segments:
    """Every episode whole: row i, start 0, its full length, its features as stored (the mean over all its steps)."""
    n = len(lengths)
    return Segments(
        np.arange(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        np.asarray(lengths, dtype=np.int64),
        np.asarray(features, dtype=np.float64),
    )


def window_features(step_features: np.ndarray, start: int, length: int) -> np.ndarray:
    """The features of steps start .. start + length - 1 of one episode: the time mean of their per-step features."""
    return np.asarray(step_features[start : start + length], dtype=np.float64).mean(axis=0)


def sample_windows(
    step_features: Sequence[np.ndarray], per_episode: int, min_fraction: float, rng: np.random.Generator
) -> Segments:
    """`per_episode` random windows of every episode: a length drawn uniformly between `min_fraction` of the
    episode's length (at least 2 steps) and its whole length, then a start drawn uniformly where that length fits.
    Each window's features are the time mean of its per-step features (by cumulative sums, exact to rounding)."""
    if per_episode < 0 or not 0 < min_fraction <= 1:
        raise LangprefError(
            f"windows must be >= 0 and window_min_fraction in (0, 1], got {per_episode} and {min_fraction}"
        )
    rows, starts, lengths, feats = [], [], [], []
    for i, steps in enumerate(step_features):
        total = len(steps)
        shortest = min(total, max(2, int(np.ceil(min_fraction * total))))
        length = rng.integers(shortest, total + 1, size=per_episode)
        start = np.floor(rng.random(per_episode) * (total - length + 1)).astype(np.int64)
        cum = np.concatenate([np.zeros((1, steps.shape[1])), np.cumsum(np.asarray(steps, dtype=np.float64), axis=0)])
        rows.append(np.full(per_episode, i, dtype=np.int64))
        starts.append(start)
        lengths.append(length.astype(np.int64))
        feats.append((cum[start + length] - cum[start]) / length[:, None])
    if not rows or per_episode == 0:
        width = step_features[0].shape[1] if len(step_features) else 0
        empty = np.zeros(0, dtype=np.int64)
        return Segments(empty, empty, empty, np.zeros((0, width)))
    return Segments(*(np.concatenate(x) for x in (rows, starts, lengths, feats)))


def segment_steps(segments: Segments, items: np.ndarray, time_index: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """(rows, steps, lengths) that pick segments `items` out of their split's (N, T, d) step array.

    `time_index` (n, k) holds steps within each segment (0 .. length - 1, as a stratified draw gives them): the
    result then indexes those k steps of each, and lengths is None (all k are real). Without it every step of each
    segment is taken, padded to the longest by repeating its last step, with the real lengths for the encoder's
    masked mean."""
    rows, start, length = segments.row[items], segments.start[items], segments.length[items]
    if time_index is not None:
        return rows, start[:, None] + time_index, None
    offset = np.minimum(np.arange(int(length.max(initial=1)))[None, :], length[:, None] - 1)
    return rows, start[:, None] + offset, length
