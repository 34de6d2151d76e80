"""Reward learning from comparative language feedback (paper Eq. 5-9) and the comparison baseline, with metrics.

r_xi is a function of the frozen trajectory embedding phi. Every answer, of any kind, becomes weighted Bradley-Terry
pairs (winner embedding, loser embedding) by its kind's `pairs` (`langpref.feedback.kind`): language feedback by
L_Explicit and L_Implicit (Eq. 7, 9; `langpref.feedback.language`), a comparison by one pair, preferred beats rejected
(Eq. 11; `langpref.feedback.comparison`). The loop, the fit and the metrics are the same for every kind.

L = sum_pairs weight * BT-loss / sum_pairs weight + (weight_decay / 2) |xi|^2, the weighted mean over every pair so
far plus a Gaussian prior. A language query of L_Explicit + L_Implicit weighs 2 (its explicit pair, and k implicit
pairs of weight 1/k); one of either loss alone, or a comparison, weighs 1. Eq. 9 divides by the number of queries
instead, which for `both` is our loss times 2: the same minimiser without a prior. With one, dividing by the total
weight lets the prior weigh the same against every loss term of every method; divided by the queries, `both` would
meet a prior half as strong as a comparison fit does, and be overconfident after one query.

After every query the model is refit on all feedback so far with full-batch L-BFGS, warm-started from the last fit.
The default r_xi is linear, r = xi . phi, as in the authors' code; then the loss is convex and the L2 term makes its
minimum unique, so the result does not depend on optimiser details; `model="mlp"` gives a small network instead.
With a linear r, r(phi + psi_l) - r(phi) = xi . psi_l: what language teaches does not depend on the shown trajectory.

Queries are drawn uniformly from the query split (the paper's), or chosen by an active strategy from the learner's
Laplace posterior (`query_selection`; `langpref.feedback.selection`, `langpref.feedback.posterior`) from a separate
random stream, so that the human's answers and the negatives draw from the same streams whatever the strategy. With
`feedback="mixed"` one learner asks either kind, each query of the kind and item with the most information per
modelled second of the person's time (`langpref.feedback.mixed`, `langpref.feedback.cost`), and its answers, of both
kinds, enter the same fit. With `query_batch` K > 1, K queries are chosen at once (`langpref.feedback.batch`) and the
learner is refit only after the K-th answer; the metrics are still recorded after every query, so within a batch the
curves stay where the last refit left them.

Metrics (Sec. 5.1), on an evaluation split: `cross_entropy(P_w, P_xi)` averaged over all its unordered pairs, and
`reward_of_best`, the normalised true reward (0 worst, 1 best of the split) of the trajectory r_xi ranks first
(averaged over ties, so a constant r_xi scores the split's mean).

Beyond the dataset (`learn-reward --optimize`, `langpref.propose`): after the last query, r_xi's own optimum is
generated in the simulator (CMA-ES on a surrogate of phi, decided by r_xi of real rollouts embedded by the real
encoder) and `optimized_true_reward` is its true reward on the same scale, so above 1 is better than any trajectory of
the eval split. `--save-reward DIR` writes each run's r_xi for `langpref.rewards.LearnedReward`.
"""

from __future__ import annotations

import sys
import threading
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback import bradley_terry
from langpref.feedback.bradley_terry import PairBatch
from langpref.feedback.cost import query_costs
from langpref.feedback.humans import HumanConfig, normalised_reward, sample_weights, true_reward
from langpref.feedback.kind import KINDS, MIXED, MIXED_KINDS, FeedbackKind, get_kind, kind_of, random_query
from langpref.feedback.space import LatentSpace

LOSSES = ("both", "explicit", "implicit")
NEGATIVES = ("other_meaning", "any")
MODELS = ("linear", "mlp")
DEFAULT_WEIGHT_DECAY = {"linear": 1.0, "mlp": 0.25}


def feedback_choices() -> tuple[str, ...]:
    """Every `feedback` a learner takes: each registered kind, and `mixed` (language and comparisons, chosen per
    query)."""
    return (*KINDS, MIXED)


@dataclass
class RewardConfig:
    """The reward model r_xi and how it is fit."""

    model: str = "linear"
    """`linear` (r = xi . phi, the authors' choice) or `mlp` (one hidden layer of `hidden` ReLU units)."""
    hidden: int = 32
    """Hidden units of the `mlp` model."""
    weight_decay: float | None = None
    """L2 penalty (weight_decay / 2) |xi|^2 added to the weighted mean loss over pairs: a Gaussian prior on xi. It
    fixes the reward's scale, which language feedback alone leaves open (its explicit pairs are separable), and so
    matters for the cross-entropy. None: the model's default in `DEFAULT_WEIGHT_DECAY`. For the linear model, 1.0 is
    what language, comparisons and L_Explicit alone each pick by their own mean cross-entropy on the val split, with
    humans the test experiments never see, in both envs (L_Implicit alone picks 0.5, by 0.002); `langpref experiment
    prior --env ENV` reruns that choice. On the mlp's two layers the same L2 acts as a stronger penalty on the
    function: at 1.0 it stays at the flat reward, hence its weaker default."""
    loss: str = "both"
    """`both` (L_Explicit + L_Implicit, Eq. 9), `explicit` or `implicit` (the ablation)."""
    num_negatives: int = 20
    """k, other utterances per language query for L_Implicit."""
    negatives: str = "other_meaning"
    """`other_meaning`: negatives of other (feature, direction) meanings than the model's reading of l;
    `any`: any pool utterance with another text (the paper's wording)."""
    negative_split: str = "train"
    """Bank split the robot draws implicit negatives from."""
    max_iter: int = 100
    """L-BFGS iterations per refit."""

    def __post_init__(self) -> None:
        if self.weight_decay is None:
            self.weight_decay = DEFAULT_WEIGHT_DECAY.get(self.model, DEFAULT_WEIGHT_DECAY["linear"])

    def validate(self) -> None:
        if self.model not in MODELS:
            raise LangprefError(f"unknown reward model {self.model!r}: choose one of {', '.join(MODELS)}")
        if self.loss not in LOSSES:
            raise LangprefError(f"unknown loss {self.loss!r}: choose one of {', '.join(LOSSES)}")
        if self.negatives not in NEGATIVES:
            raise LangprefError(f"unknown negatives {self.negatives!r}: choose one of {', '.join(NEGATIVES)}")
        if self.num_negatives < 1 and self.loss != "explicit":
            raise LangprefError(f"num_negatives (k) must be >= 1 for L_Implicit, got {self.num_negatives}")
        if self.weight_decay < 0 or self.hidden < 1 or self.max_iter < 1:
            raise LangprefError("weight_decay must be >= 0, hidden and max_iter >= 1")


class RewardLearner:
    """r_xi on phi, refit on all pairs so far after every query (`add` then `fit`)."""

    def __init__(self, dim: int, cfg: RewardConfig | None = None, seed: int = 0):
        import torch

        self.cfg = cfg or RewardConfig()
        self.cfg.validate()
        self._torch = torch
        gen = torch.Generator().manual_seed(int(seed))
        if self.cfg.model == "linear":
            self.params = [torch.zeros(dim, dtype=torch.float64, requires_grad=True)]
        else:
            h = self.cfg.hidden
            self.params = [
                (torch.randn(dim, h, generator=gen, dtype=torch.float64) / dim**0.5).requires_grad_(),
                torch.zeros(h, dtype=torch.float64, requires_grad=True),
                (torch.randn(h, generator=gen, dtype=torch.float64) / h**0.5).requires_grad_(),
            ]
        self.batches: list[PairBatch] = []
        self._data: tuple | None = None

    @property
    def num_queries(self) -> int:
        return len(self.batches)

    def _reward(self, x):
        if self.cfg.model == "linear":
            return x @ self.params[0]
        w1, b1, w2 = self.params
        return self._torch.relu(x @ w1 + b1) @ w2

    def add(self, batch: PairBatch) -> None:
        self.batches.append(batch)
        self._data = None

    def loss(self):
        """The weighted mean Bradley-Terry loss over all pairs plus the L2 term, as a torch scalar."""
        torch = self._torch
        if self._data is None:
            w = np.concatenate([b.weights for b in self.batches])
            w = w / w.sum()
            self._data = tuple(
                torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))
                for a in (
                    np.concatenate([b.winners for b in self.batches]),
                    np.concatenate([b.losers for b in self.batches]),
                    w,
                )
            )
        win, lose, weight = self._data
        margin = self._reward(win) - self._reward(lose)
        reg = sum((p * p).sum() for p in self.params)
        return (weight * bradley_terry.nll(margin)).sum() + 0.5 * self.cfg.weight_decay * reg

    def fit(self) -> None:
        """Refit on all pairs so far. On one thread: the problem is small, and the fit (the mlp's above all, which is
        not convex) then does not depend on how many threads or sweep workers the machine has."""
        if not self.batches:
            return
        torch = self._torch
        opt = torch.optim.LBFGS(
            self.params,
            lr=1.0,
            max_iter=self.cfg.max_iter,
            tolerance_grad=1e-9,
            tolerance_change=1e-12,
            history_size=20,
            line_search_fn="strong_wolfe",
        )

        def closure():
            opt.zero_grad()
            value = self.loss()
            value.backward()
            return value

        with _one_thread(torch):
            opt.step(closure)

    def predict(self, phi: np.ndarray) -> np.ndarray:
        with self._torch.no_grad(), _one_thread(self._torch):
            return self._reward(self._torch.from_numpy(np.asarray(phi, dtype=np.float64))).numpy().copy()


_THREADS = threading.Lock()


@contextmanager
def _one_thread(torch):
    """torch on one thread, one such section at a time: the thread count is process-wide, and concurrent fits (the
    study server answers participants on several threads) must not interleave its save and restore."""
    with _THREADS:
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            yield
        finally:
            torch.set_num_threads(threads)


# ---- metrics ------------------------------------------------------------------------------------------------------


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


@dataclass
class Curves:
    """Metrics after 0, 1, ..., Q queries."""

    cross_entropy: list[float] = field(default_factory=list)
    true_reward_of_best: list[float] = field(default_factory=list)
    optimized_true_reward: float | None = None
    """With generation: the normalised true reward of r_xi's generated optimum after the last query."""
    kinds: list[str] = field(default_factory=list)
    """The kind of feedback asked at queries 1..Q."""
    seconds: list[float] = field(default_factory=list)
    """Modelled seconds of the person's time after 0, 1, ..., Q queries (`langpref.feedback.cost`)."""

    def record(
        self, learner: RewardLearner, space: LatentSpace, eval_rows: np.ndarray, R_eval: np.ndarray, rationality: float
    ) -> None:
        r = learner.predict(space.phi[eval_rows])
        self.cross_entropy.append(cross_entropy(R_eval, r, rationality))
        self.true_reward_of_best.append(reward_of_best(R_eval, r))


# ---- simulated sessions (`langpref learn-reward`) -----------------------------------------------------------------


@dataclass
class LearnRewardConfig:
    """`langpref learn-reward`: synthetic humans x seeds, Q queries each, metrics after every query."""

    feedback: str = "language"
    """The kind of feedback (`langpref.feedback.KINDS`): `language` (one trajectory shown, comparative feedback),
    `comparison` (a pair shown, one choice), any registered kind, or `mixed`: both in one learner, each query of the
    kind and item with the most information per modelled second (`infogain`; the linear reward)."""
    queries: int = 40
    """Q, queries per run."""
    humans: int = 3
    """Synthetic humans (reward weights w), drawn from `seed`."""
    seeds: int = 3
    """Runs per human (query draws, answer noise, negatives)."""
    seed: int = 0
    """Master seed: the same seed gives the same numbers."""
    query_split: str = "train"
    """Trajectories shown in queries; the language human's tau* is the best of this split."""
    eval_split: str = "test"
    """Split of the metrics."""
    human: HumanConfig = field(default_factory=HumanConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    query_selection: str | None = None
    """How each query is chosen (`langpref.feedback.selection`): None or `random` (uniform, the paper's); `infogain`
    (language and comparisons: information about the reward, Laplace posterior); `lal-infogain` (language: the
    authors' follow-up); `volume-removal` (comparisons). Active strategies need the linear reward model."""
    candidates: int | None = None
    """Active strategies score a random subset of this many trajectories of the query split, drawn afresh for
    every query; None: the whole split."""
    posterior_samples: int | None = None
    """Draws of the reward's Laplace posterior per active selection; None: 64."""
    query_batch: int | None = None
    """K, queries chosen at once (greedily, by score with a penalty for pointing the same way in the latent space as
    one already in the batch); the learner is refit only after the batch. None: 1, a refit after every query."""
    language_seconds: float | None = None
    """Modelled time a person takes per language query, in the unit of comparison_seconds. None: 0.887, the paper's
    measurement (Sec. 5.2: language took 11.3% less time per query than comparisons; it gives no seconds). Sets
    what `mixed` asks and the time axis of the curves."""
    comparison_seconds: float | None = None
    """Modelled time a person takes per comparison. None: 1.0 (the unit; the paper reports only the ratio); give
    both in seconds where they were measured."""

    @property
    def selection(self) -> str:
        """The query selection strategy: `random` when unset (`infogain` for `mixed`)."""
        return self.query_selection or ("infogain" if self.feedback == MIXED else "random")

    @property
    def batch(self) -> int:
        """K, queries chosen at once (1 when unset)."""
        return 1 if self.query_batch is None else int(self.query_batch)

    @property
    def costs(self) -> dict[str, float]:
        """Modelled seconds per query by kind (`langpref.feedback.cost.query_costs`)."""
        return query_costs(self.language_seconds, self.comparison_seconds)

    def validate(self) -> None:
        from langpref.feedback.posterior import require_linear
        from langpref.feedback.selection import check_strategy

        if self.feedback not in feedback_choices():
            raise LangprefError(f"unknown feedback {self.feedback!r}: choose one of {', '.join(feedback_choices())}")
        check_strategy(self.selection, self.feedback)
        if self.query_batch is not None and self.query_batch < 1:
            raise LangprefError(f"query_batch must be >= 1, got {self.query_batch}")
        query_costs(self.language_seconds, self.comparison_seconds)
        require_linear(self.reward.model, self.selection)
        if self.candidates is not None and self.candidates < 2:
            raise LangprefError(f"candidates must be >= 2, got {self.candidates}")
        if self.posterior_samples is not None and self.posterior_samples < 2:
            raise LangprefError(f"posterior_samples must be >= 2, got {self.posterior_samples}")
        if self.queries < 1 or self.humans < 1 or self.seeds < 1:
            raise LangprefError("queries, humans and seeds must each be >= 1")
        self.human.validate()
        self.reward.validate()


def human_weights(num_features: int, seed: int, human: int) -> np.ndarray:
    """The reward weights of synthetic human number `human` of experiment seed `seed`."""
    return sample_weights(num_features, np.random.default_rng([seed, 7919, human]))


def run_reward_learning(
    space: LatentSpace,
    w: np.ndarray,
    cfg: LearnRewardConfig,
    run_seed: tuple[int, ...],
    record: list | None = None,
    generation=None,
    learners: list | None = None,
) -> Curves:
    """One run: Q queries of `cfg.feedback` to the synthetic human with weights `w`; metrics after each. Queries
    are drawn uniformly (`random`, from their own stream) or chosen by `cfg.query_selection` (from another stream,
    so the human's answers and the negatives use the same streams whatever the strategy), `cfg.batch` at a time,
    the learner refit after each batch. `mixed` asks a language human and a comparison human with the same `w`,
    each on the answer stream of its kind's single-kind runs, so a mixed run that asks one kind only is that kind's
    `infogain` run, answer for answer. With `record`, appends each query's `langpref.feedback.selection.Selection`
    (score None for random) and answer as a pair. With `generation` (`langpref.propose.Generation`), generates r_xi's
    optimum after the last query and scores it (`Curves.optimized_true_reward`); with `learners`, appends the final
    reward model."""
    cfg.validate()
    pool = space.split(cfg.query_split)
    eval_rows = space.split(cfg.eval_split)
    R_eval = true_reward(w, space.theta[eval_rows])
    rng_query, rng_human, rng_neg = (np.random.default_rng([*run_seed, k]) for k in (1, 2, 3))
    learner = RewardLearner(space.dim, cfg.reward, seed=int(np.random.default_rng([*run_seed, 4]).integers(2**31)))
    selector = _selector(cfg, space, pool)
    rng_select = np.random.default_rng([*run_seed, 5])
    costs = cfg.costs
    curves = Curves(seconds=[0.0])
    curves.record(learner, space, eval_rows, R_eval, cfg.human.rationality)
    if cfg.feedback == MIXED:  # each kind's human on the stream of that kind's own runs (common random numbers)
        humans = {
            name: get_kind(name).make_human(w, space, pool, cfg.human, np.random.default_rng([*run_seed, 2]))
            for name in MIXED_KINDS
        }
    else:
        humans = {cfg.feedback: get_kind(cfg.feedback).make_human(w, space, pool, cfg.human, rng_human)}
    while len(curves.kinds) < cfg.queries:
        size = min(cfg.batch, cfg.queries - len(curves.kinds))
        batch = (
            _random_batch(get_kind(cfg.feedback), pool, rng_query, size)
            if selector is None
            else selector.select_batch(learner, rng_select, size)
        )
        for n, chosen in enumerate(batch, start=1):
            kind = kind_of(chosen.query)
            answer = humans[kind.name].answer(chosen.query)
            if selector is not None:
                selector.observe(space, answer)
            if record is not None:
                record.append((chosen, answer))
            learner.add(kind.pairs(space, answer, cfg.reward, rng_neg))
            if n == len(batch):
                learner.fit()
            curves.kinds.append(kind.name)
            curves.seconds.append(curves.seconds[-1] + costs.get(kind.name, 1.0))
            curves.record(learner, space, eval_rows, R_eval, cfg.human.rationality)
    if generation is not None:
        best = optimize_reward(generation, learner, run_seed).trajectories[0]
        raw = true_reward(w, generation.theta(best)[None])  # the experimenter scores it; the proposer never does
        curves.optimized_true_reward = float(normalised_reward(raw, R_eval)[0])
    if learners is not None:
        learners.append(learner)
    return curves


def _selector(cfg: LearnRewardConfig, space: LatentSpace, pool: np.ndarray):
    """The active strategy of `cfg` (None for random: the loop draws uniformly)."""
    from langpref.feedback.selection import make_selector

    if cfg.feedback == MIXED:  # validate() has checked the strategy (infogain) and the linear reward
        from langpref.feedback.mixed import MixedInfoGain
        from langpref.feedback.selection import DEFAULT_SAMPLES

        samples = DEFAULT_SAMPLES if cfg.posterior_samples is None else cfg.posterior_samples
        return MixedInfoGain(space, pool, cfg.reward, cfg.costs, cfg.candidates, samples)
    kind = get_kind(cfg.feedback)
    return make_selector(cfg.selection, kind, space, pool, cfg.reward, cfg.candidates, cfg.posterior_samples)


def _random_batch(kind: FeedbackKind, pool: np.ndarray, rng: np.random.Generator, size: int) -> list:
    """`size` uniform queries of `kind`, one after another from the query stream (a batch of 1 is the paper's)."""
    from langpref.feedback.selection import Selection

    return [Selection(random_query(kind, pool, rng), None, "random", len(pool)) for _ in range(size)]


def optimize_reward(generation, learner: RewardLearner, run_seed: tuple[int, ...] = (0,)):
    """r_xi's optimum made in the simulator (`langpref.propose.Proposer.optimise`), starting from the dataset
    trajectory r_xi ranks first; the `Proposal` of every rollout, best first by r_xi."""
    start = generation.units[int(np.argmax(learner.predict(generation.phi)))]
    return generation.proposer(key=(*run_seed, 31337)).optimise(learner.predict, start)


def summarise(runs: list[Curves], threshold: float = 0.95) -> dict:
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
    }


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
    it beats the eval split's best trajectory (> 1) and the split's trajectory r_xi ranks first."""
    if not runs or any(c.optimized_true_reward is None for c in runs):
        return {}
    opt = np.array([c.optimized_true_reward for c in runs])
    picked = np.array([c.true_reward_of_best[-1] for c in runs])
    return {
        "optimized_true_reward": opt.tolist(),
        "optimized_true_reward_mean": float(opt.mean()),
        "optimized_beats_best_of_split": float((opt > 1.0).mean()),
        "optimized_beats_true_reward_of_best": float((opt > picked).mean()),
    }


def learn_reward(
    space: LatentSpace,
    cfg: LearnRewardConfig,
    progress: bool = True,
    generation=None,
    save_reward: str | None = None,
    model: str | None = None,
) -> dict:
    """cfg.humans x cfg.seeds runs on `space`; the summary of `summarise` plus the config. With `generation`
    (`langpref.propose.Generation`), each run also generates r_xi's optimum (`optimized_true_reward`, one per run);
    with `save_reward` (a directory), each run's r_xi is written there for `langpref.rewards.LearnedReward`, beside
    a reference to the checkpoint `model` whose trajectory encoder it reads."""
    from tqdm import tqdm

    cfg.validate()
    if save_reward:
        from langpref.rewards import check_saveable

        check_saveable(model)
    runs, saved = [], []
    with tqdm(
        total=cfg.humans * cfg.seeds,
        desc=f"learn-reward {cfg.feedback} {cfg.selection}",
        disable=not progress,
        file=sys.stderr,
    ) as bar:
        for h in range(cfg.humans):
            w = human_weights(len(space.feature_names), cfg.seed, h)
            for s in range(cfg.seeds):
                learners = [] if save_reward else None
                runs.append(
                    run_reward_learning(space, w, cfg, (cfg.seed, h, s), generation=generation, learners=learners)
                )
                if save_reward:
                    from langpref.rewards import save_learned_reward

                    saved.append(
                        str(
                            save_learned_reward(
                                learners[0],
                                save_reward,
                                env=space.env,
                                model=model,
                                name=f"h{h}-s{s}",
                                default=not saved,
                            )
                        )
                    )
                bar.update()
    extra = {"saved_rewards": saved} if saved else {}
    if generation is not None:
        extra["propose"] = asdict(generation.cfg)
    return {
        **summarise(runs),
        "feedback": cfg.feedback,
        "loss": cfg.reward.loss,
        "query_selection": cfg.selection,
        "config": asdict(cfg),
        "space": space.description,
        **extra,
    }
