"""What a reward-learning run records (`Curves`: the metrics after every query) and how runs are summarised
(`summarise_curves`: mean and std per query count, and what the queries cost) into `langpref learn-reward --json` and
the reward experiments' results."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from langpref.feedback.kind import get_kind
from langpref.feedback.space import LatentSpace
from langpref.reward.learner import RewardLearner
from langpref.reward.metrics import cross_entropy, epic_distance, kendall_tau, reward_of_best


@dataclass
class Curves:
    """Metrics after 0, 1, ..., Q queries."""

    cross_entropy: list[float] = field(default_factory=list)
    true_reward_of_best: list[float] = field(default_factory=list)
    optimized_true_reward: float | None = None
    """With generation: the normalised true reward of r_xi's generated optimum after the last query."""
    recorded_true_reward: float | None = None
    """With generation: the same of the recorded trajectory r_xi ranks first over every split of the dataset."""
    kinds: list[str] = field(default_factory=list)
    """The kind of feedback asked at queries 1..Q."""
    seconds: list[float] = field(default_factory=list)
    """Modelled seconds of the person's time after 0, 1, ..., Q queries (`langpref.reward.cost`)."""
    credible: bool | None = None
    """Answer-model learner: whether the true weights' direction lies in the belief's 90% credible region of
    directions after the last query (a calibration check; read by the metrics only)."""
    confirmed: list[int] = field(default_factory=list)
    """With `confirm_margin`, per answer of a kind that can be confirmed: -1 not asked, -2 "none of these", else the
    meaning clicked (2 x its dataset feature index + its direction)."""
    no_change: list[int] = field(default_factory=list)
    """The queries (1..Q) the person answered "that's good, no change"."""
    kendall_tau: list[float] = field(default_factory=list)
    """Kendall's tau-b between the true and the learned ranking of the evaluation split, after 0..Q queries."""
    epic_distance: list[float] = field(default_factory=list)
    """EPIC distance between the true and the learned reward over every trajectory of the dataset, after 0..Q
    queries."""
    value_order: float | None = None
    """With successful episodes step by step: the value-order correlation of r_xi through them after the last
    query."""
    value_order_true: float | None = None
    """The same of the synthetic human's true reward: what a reward that matched it exactly would score (a reward
    of preferences need not rise through a successful episode, as a reward of task progress does)."""

    def record(
        self,
        learner: RewardLearner,
        space: LatentSpace,
        eval_rows: np.ndarray,
        R_eval: np.ndarray,
        rationality: float,
        R_all: np.ndarray,
    ) -> None:
        r = learner.predict(space.phi[eval_rows])
        self.cross_entropy.append(cross_entropy(R_eval, r, rationality))
        self.true_reward_of_best.append(reward_of_best(R_eval, r))
        self.kendall_tau.append(kendall_tau(R_eval, r))
        self.epic_distance.append(epic_distance(R_all, learner.predict(space.phi)))


def summarise_curves(runs: list[Curves], threshold: float = 0.95) -> dict:
    """Mean and std per query count over runs, the area under the mean true-reward curve (its mean over query
    counts 0..Q), the first query count whose mean true reward reaches `threshold` (None if never), and what the
    queries cost (`kinds_summary`)."""
    ce = np.array([c.cross_entropy for c in runs])
    best = np.array([c.true_reward_of_best for c in runs])
    mean_best = best.mean(axis=0)
    reached = np.flatnonzero(mean_best >= threshold)
    return {
        "cross_entropy": ce.mean(axis=0).tolist(),
        "cross_entropy_std": ce.std(axis=0).tolist(),
        "true_reward_of_best": mean_best.tolist(),
        "true_reward_of_best_std": best.std(axis=0).tolist(),
        "auc_true_reward": float(mean_best.mean()),
        "auc_cross_entropy": float(ce.mean(axis=0).mean()),
        f"queries_to_{threshold:g}": int(reached[0]) if len(reached) else None,
        "num_runs": len(runs),
        **kinds_summary(runs),
        **optimized_summary(runs),
        **confirm_summary(runs),
        **standard_summary(runs),
    }


def standard_summary(runs: list[Curves]) -> dict:
    """Mean and std over runs, per query count, of `kendall_tau` and `epic_distance`, and of runs scored on
    successful episodes the mean `value_order` correlation (with its std, the per-run values, and the mean of the
    true reward's, `value_order_correlation_true_reward`). Empty for runs
    recorded before these were kept (an older experiment cache)."""
    out: dict = {}
    for name in ("kendall_tau", "epic_distance"):
        curves = [getattr(c, name) for c in runs]
        if runs and all(curves) and len({len(c) for c in curves}) == 1:
            values = np.array(curves)
            out[name] = values.mean(axis=0).tolist()
            out[f"{name}_std"] = values.std(axis=0).tolist()
    orders = [c.value_order for c in runs]
    if runs and all(v is not None for v in orders):
        out["value_order_correlation"] = float(np.mean(orders))
        out["value_order_correlation_std"] = float(np.std(orders))
        out["value_order_correlation_runs"] = [float(v) for v in orders]
        truth = [c.value_order_true for c in runs]
        if all(v is not None for v in truth):
            out["value_order_correlation_true_reward"] = float(np.mean(truth))
    return out


def confirm_summary(runs: list[Curves]) -> dict:
    """Of answer-model runs, `credible_90`: the share whose true direction lies in the belief's 90% credible region
    (calibrated: about 0.9). Of runs that asked people to confirm their sentences: the share of language answers
    confirmed, and of those the share answered "none of these". Of runs whose person said "that's good, no change",
    the share of the answers that could have been it (`FeedbackKind.says_no_change`: language) that were
    (`no_change_share`). Empty for the paper's learner and human."""
    out = {}
    credible = [c.credible for c in runs if c.credible is not None]
    if credible:
        out["credible_90"] = float(np.mean(credible))
    said = sum(len(c.no_change) for c in runs)
    if said:
        could = sum(get_kind(k).says_no_change for c in runs for k in c.kinds)  # answers that could have said it
        out["no_change_share"] = said / max(could, 1)
    marks = np.array([m for c in runs for m in c.confirmed])
    if len(marks):
        asked = marks != -1
        out["confirm_asked"] = float(asked.mean())
        out["confirm_none"] = float((marks == -2).sum() / max(int(asked.sum()), 1))
    return out


def kinds_summary(runs: list[Curves]) -> dict:
    """Which kind was asked and the person's modelled time: `kinds_asked` (per run, the kind of queries 1..Q),
    `kind_share` ({kind: share of runs asking it at each query 1..Q}) and `modelled_seconds` (mean over runs after
    0..Q queries, with `modelled_seconds_std`). Empty for runs recorded before these were kept."""
    if not runs or any(not c.kinds or len(c.seconds) != len(c.kinds) + 1 for c in runs):
        return {}
    asked = np.array([c.kinds for c in runs])
    seconds = np.array([c.seconds for c in runs])
    return {
        "kinds_asked": asked.tolist(),
        "kind_share": {k: (asked == k).mean(axis=0).tolist() for k in sorted(set(asked.ravel()))},
        "modelled_seconds": seconds.mean(axis=0).tolist(),
        "modelled_seconds_std": seconds.std(axis=0).tolist(),
    }


def optimized_summary(runs: list[Curves]) -> dict:
    """Of runs with a generated optimum: `optimized_true_reward` (one per run), its mean, and the shares of runs where
    it beats the eval split's best trajectory (> 1) and the split's trajectory r_xi ranks first; and the recorded
    trajectory r_xi ranks first over every split (`recorded_true_reward`), with the share the optimum beats it."""
    if not runs or any(c.optimized_true_reward is None for c in runs):
        return {}
    opt = np.array([c.optimized_true_reward for c in runs])
    picked = np.array([c.true_reward_of_best[-1] for c in runs])
    out = {
        "optimized_true_reward": opt.tolist(),
        "optimized_true_reward_mean": float(opt.mean()),
        "optimized_beats_best_of_split": float((opt > 1.0).mean()),
        "optimized_beats_true_reward_of_best": float((opt > picked).mean()),
    }
    if all(c.recorded_true_reward is not None for c in runs):
        recorded = np.array([c.recorded_true_reward for c in runs])
        out.update(
            recorded_true_reward=recorded.tolist(),
            recorded_true_reward_mean=float(recorded.mean()),
            optimized_beats_recorded=float((opt > recorded).mean()),
        )
    return out
