"""Bradley-Terry, written once: every kind of feedback becomes weighted pairs (winner beats loser).

P(winner beats loser) = sigmoid(margin), with margin the difference of their rewards. The synthetic comparison human
answers with it (Eq. 11, margin = rationality * (R_a - R_b)), the reward learner fits r_xi by its negative
log-likelihood over all pairs so far, and the metrics compare the true and the learned reward with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class PairBatch:
    """Bradley-Terry pairs of one answer: winners[j] is preferred to losers[j] with weight weights[j] (embeddings)."""

    winners: np.ndarray
    losers: np.ndarray
    weights: np.ndarray


def probability(margin):
    """P(winner beats loser) = sigmoid(margin), for a number or an array (tanh form: no overflow)."""
    return 0.5 * (1.0 + np.tanh(0.5 * margin))


def log_likelihood(margin: np.ndarray) -> np.ndarray:
    """log P(winner beats loser) = log sigmoid(margin), numerically stable."""
    return -np.logaddexp(0.0, -margin)


def nll(margin):
    """-log sigmoid(margin) on torch tensors: the loss the reward learner minimises (weighted over pairs)."""
    import torch

    return torch.nn.functional.softplus(-margin)
