"""How good a learned reward is (paper Sec. 5.1), on an evaluation split: the cross-entropy between the person's
and the learner's pairwise preferences, and the true reward of the trajectory the learner ranks first."""

from __future__ import annotations

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback import bradley_terry


def cross_entropy(true_values: np.ndarray, learned_values: np.ndarray, rationality: float = 1.0) -> float:
    """CE(P_w, P_xi) averaged over all unordered pairs (i < j): P_w = sigmoid(rationality (R_i - R_j)) and
    P_xi = sigmoid(r_i - r_j)."""
    R = np.asarray(true_values, dtype=np.float64)
    r = np.asarray(learned_values, dtype=np.float64)
    if R.shape != r.shape or R.ndim != 1 or len(R) < 2:
        raise LangprefError(f"cross-entropy needs two equal vectors of >= 2 rewards, got {R.shape} and {r.shape}")
    i, j = np.triu_indices(len(R), k=1)
    p = bradley_terry.probability(rationality * (R[i] - R[j]))
    d = r[i] - r[j]
    return float(np.mean(-(p * bradley_terry.log_likelihood(d) + (1.0 - p) * bradley_terry.log_likelihood(-d))))


def reward_of_best(true_values: np.ndarray, learned_values: np.ndarray) -> float:
    """Normalised true reward (0 worst, 1 best of the set) of the trajectory ranked first by the learned reward;
    ties share the rank, so the mean over the tied trajectories."""
    R = np.asarray(true_values, dtype=np.float64)
    r = np.asarray(learned_values, dtype=np.float64)
    top = r >= r.max() - 1e-9 * max(1.0, abs(float(r.max())))
    return float(((R[top] - R.min()) / max(float(R.max() - R.min()), 1e-12)).mean())
