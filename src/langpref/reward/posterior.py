"""The learner's belief about the linear reward r = xi . phi: a Laplace approximation at its fit, for active queries.

The reward learner (`langpref.reward.RewardLearner`) minimises

    L(xi) = sum_j a_j softplus(-xi . d_j) + (weight_decay / 2) |xi|^2,    a_j = weight_j / W,  W = sum_j weight_j,

over the Bradley-Terry pairs of every answer so far (d_j = winner_j - loser_j). L is a *mean* over pairs; read as a
negative log-posterior it is that of W observations, so the posterior is exp(-W L(xi)): its mode is the fit, and its
Laplace approximation is N(xi_hat, (W H)^-1) with H the Hessian of L at the fit,

    H = sum_j a_j s_j (1 - s_j) d_j d_j^T + weight_decay I,    s_j = sigmoid(xi_hat . d_j).

With no answer yet (W = 0) the belief is the prior alone, N(0, I / weight_decay). W counts a language answer of
L_Explicit + L_Implicit twice and a comparison once, as the fit weighs them. H is exact (not an L-BFGS estimate) and
costs one pass over the pairs: D = 128 and a few hundred pairs take well under a millisecond.

    post = laplace_posterior(learner)          # after learner.fit()
    xi = post.sample(64, rng)                  # (64, D) reward vectors

The mlp reward has no such closed form; active query selection refuses it with one line (`random` works for it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import solve_triangular

from langpref.errors import LangprefError

if TYPE_CHECKING:
    from langpref.reward import RewardLearner


@dataclass(frozen=True)
class LaplacePosterior:
    """N(mean, precision^-1) over xi, with the Cholesky factor of the covariance for sampling."""

    mean: np.ndarray
    """(D,) the fit xi_hat."""
    precision: np.ndarray
    """(D, D) W H."""
    cov_factor: np.ndarray
    """(D, D) a factor L with L L^T = precision^-1 (the transposed inverse of the precision's Cholesky factor)."""

    @property
    def covariance(self) -> np.ndarray:
        return self.cov_factor @ self.cov_factor.T

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, D) draws of xi."""
        return self.mean + rng.standard_normal((int(n), len(self.mean))) @ self.cov_factor.T


def pair_arrays(learner: RewardLearner) -> tuple[np.ndarray, np.ndarray]:
    """(differences d_j = winner - loser (P, D), raw weights (P,)) of every pair the learner has."""
    if not learner.batches:
        return np.zeros((0, learner.params[0].shape[0])), np.zeros(0)
    d = np.concatenate(
        [np.asarray(b.winners, dtype=np.float64) - np.asarray(b.losers, dtype=np.float64) for b in learner.batches]
    )
    return d, np.concatenate([np.asarray(b.weights, dtype=np.float64) for b in learner.batches])


def loss_hessian(xi: np.ndarray, d: np.ndarray, weights: np.ndarray, weight_decay: float) -> np.ndarray:
    """The Hessian H of the learner's loss L (the weighted mean Bradley-Terry loss plus the L2 term) at xi."""
    dim = len(xi)
    h = weight_decay * np.eye(dim)
    if len(d):
        a = weights / weights.sum()
        s = 0.5 * (1.0 + np.tanh(0.5 * (d @ xi)))
        h = h + (d * (a * s * (1.0 - s))[:, None]).T @ d
    return h


def require_linear(model: str, strategy: str = "active") -> None:
    """Active query selection samples the Laplace posterior of the linear r_xi; any other reward model is refused."""
    if strategy != "random" and model != "linear":
        raise LangprefError(
            f"query selection {strategy!r} needs the linear reward model (a Laplace posterior); the {model} "
            "reward only works with --query-selection random"
        )


def laplace_posterior(learner: RewardLearner) -> LaplacePosterior:
    """The Laplace approximation of the linear learner's posterior at its current fit (call `fit` first)."""
    require_linear(learner.cfg.model)
    xi = learner.params[0].detach().numpy().astype(np.float64, copy=True)
    d, weights = pair_arrays(learner)
    total = float(weights.sum()) if len(weights) else 0.0
    wd = float(learner.cfg.weight_decay)
    if total <= 0 and wd <= 0:
        raise LangprefError(
            "with weight_decay 0 and no answer yet the reward's posterior is improper; use a prior "
            "(weight_decay > 0) for active query selection"
        )
    precision = (total * loss_hessian(xi, d, weights, wd)) if total > 0 else wd * np.eye(len(xi))
    precision = 0.5 * (precision + precision.T)
    # the covariance's Cholesky factor from the precision's: P = U U^T, cov = U^-T U^-1
    chol = np.linalg.cholesky(precision + 1e-10 * np.trace(precision) / len(xi) * np.eye(len(xi)))
    inv = solve_triangular(chol, np.eye(len(xi)), lower=True)  # chol^-1, lower triangular
    return LaplacePosterior(xi, precision, inv.T)
