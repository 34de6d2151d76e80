"""How good a learned reward is.

The paper's two (Sec. 5.1), on an evaluation split: the cross-entropy between the person's and the learner's pairwise
preferences, and the true reward of the trajectory the learner ranks first. And the ones reward models are compared by
elsewhere: Kendall's tau between the true and the learned ranking (`kendall_tau`), the EPIC distance between the two
rewards (`epic_distance`), and, on successful episodes of a recording, the value-order correlation of the reward
through each episode (`value_order_correlation`). All are computed directly from their definitions; the tests
check them on hand-computed cases."""

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


# ---- the metrics reward models are compared by elsewhere ------------------------------------------------------------


def _pair(true_values: np.ndarray, learned_values: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    R = np.asarray(true_values, dtype=np.float64)
    r = np.asarray(learned_values, dtype=np.float64)
    if R.shape != r.shape or R.ndim != 1 or len(R) < 2:
        raise LangprefError(f"{what} needs two equal vectors of >= 2 rewards, got {R.shape} and {r.shape}")
    return R, r


def kendall_tau(true_values: np.ndarray, learned_values: np.ndarray) -> float:
    """Kendall's tau-b between the rankings of the true and the learned reward: over all unordered pairs (i < j),
    (concordant - discordant) / sqrt((pairs - ties in true) (pairs - ties in learned)); a pair tied in either counts
    as neither. 1: the same order, -1: reversed. A reward constant over the set ranks nothing and scores 0 (tau-b is
    undefined there; 0 is what a ranking carrying no information earns). Computed over the pairs directly."""
    R, r = _pair(true_values, learned_values, "Kendall tau")
    i, j = np.triu_indices(len(R), k=1)
    a, b = np.sign(R[i] - R[j]), np.sign(r[i] - r[j])
    untied_true, untied_learned = np.count_nonzero(a), np.count_nonzero(b)
    if untied_true == 0 or untied_learned == 0:
        return 0.0
    return float(np.sum(a * b) / np.sqrt(float(untied_true) * float(untied_learned)))


def pearson(x: np.ndarray, y: np.ndarray) -> float:
    """Pearson's correlation of two vectors; 0 when either is constant (it carries no order to correlate)."""
    x = np.asarray(x, dtype=np.float64) - np.mean(x)
    y = np.asarray(y, dtype=np.float64) - np.mean(y)
    scale = float(np.sqrt(np.dot(x, x) * np.dot(y, y)))
    if scale <= 1e-12 * max(1.0, float(np.abs(x).max() * np.abs(y).max())):
        return 0.0
    return float(np.clip(np.dot(x, y) / scale, -1.0, 1.0))


def epic_distance(true_values: np.ndarray, learned_values: np.ndarray) -> float:
    """EPIC distance (Gleave et al., 2021, "Quantifying differences in reward functions") between the true and the
    learned trajectory reward over a coverage set of trajectories (the dataset, each trajectory equally likely).

    EPIC canonicalises a reward R(s, a, s') under coverage distributions D_S, D_A,
        C(R)(s, a, s') = R(s, a, s') + E[gamma R(s', A, S') - R(s, A, S') - gamma R(S, A, S')],
    then takes the Pearson distance sqrt((1 - rho) / 2) of the canonicalised rewards over the coverage distribution.
    Our rewards are of whole trajectories, r(tau) = r_xi(phi(tau)) and R(tau) = w . theta(tau): each trajectory is
    one transition from a common start to an absorbing end, with gamma = 1 and no transition from one trajectory to
    another. The expectation is then the same for every trajectory, so canonicalisation only subtracts a constant
    (E_D[R]), and Pearson's rho ignores constants: EPIC here IS the Pearson distance of the two rewards over the
    coverage set, and that is what is computed, directly. 0: equal up to a positive affine map (the only freedom a
    reward learned from comparisons has); 1: one is the other negated; 1/sqrt(2) for uncorrelated rewards, and for a
    reward constant over the set (rho is undefined there; `pearson` gives 0)."""
    R, r = _pair(true_values, learned_values, "EPIC distance")
    return float(np.sqrt(max(0.0, (1.0 - pearson(R - R.mean(), r - r.mean())) / 2.0)))


def ranks(values: np.ndarray) -> np.ndarray:
    """Ranks 1..n of `values`, ties sharing their mean rank (as Spearman's rho needs)."""
    v = np.asarray(values, dtype=np.float64)
    order = np.argsort(v, kind="mergesort")
    sorted_v = v[order]
    starts = np.flatnonzero(np.r_[True, sorted_v[1:] != sorted_v[:-1]])
    ends = np.r_[starts[1:], len(v)]
    out = np.empty(len(v))
    for s, e in zip(starts, ends):
        out[order[s:e]] = (s + e + 1) / 2.0  # the mean of ranks s+1..e
    return out


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rho: Pearson's correlation of the ranks (ties at their mean rank); 0 when either is constant."""
    return pearson(ranks(x), ranks(y))


def value_order_correlation(progress: list[np.ndarray]) -> float:
    """Value-order correlation (as in GVL, Ma et al. 2024, and LeRobot's reward models): per successful episode,
    Spearman's rho between the reward's value of the episode so far at each step and the time index, averaged over
    the episodes. A reward that reads progress rises through a successful episode and scores near 1.

    Each item of `progress` is one episode's values v_1..v_T; for a learned r_xi, v_t = r_xi(phi_t), the reward of
    the trajectory up to step t (phi_t the running mean of the per-step embeddings; `langpref.reward.api.Reward.
    progress`). That is the value of the prefix, invariant to the constant a reward learned from comparisons is only
    known up to; the running sum of per-step rewards, t r_xi(phi_t), would grow or fall with that constant alone.
    Episodes of fewer than 2 steps are skipped; NaN when none is left."""
    rhos = [spearman(v, np.arange(len(v))) for v in progress if len(v) >= 2]
    return float(np.mean(rhos)) if rhos else float("nan")
