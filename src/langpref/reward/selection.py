"""Active queries: which trajectory (language) or pair (comparisons) to show next, from the learner's belief.

Strategies (`query_selection`), over a candidate pool (the query split, or a random subset of `candidates` of it
drawn afresh for every query):

- `random`: uniform, the paper's (`langpref.feedback.kind.random_query`; the reward loop calls it as before).
- `infogain`, language: the mutual information between xi and the person's answer, under the *answer model* below,
  with xi drawn from the Laplace posterior (`langpref.reward.posterior`). Comparisons: the mutual information
  between xi and the Bradley-Terry choice over every pair of candidates (APReL's `mutual_information`).
- `volume-removal`, comparisons: the expected removed volume 1 - sum_answers P(answer)^2 (Sadigh et al. 2017; APReL's
  `volume_removal` returns the remaining sum, which it minimises).
- `lal-infogain`, language: the follow-up's selection (Hirota, Yang et al., USC-Lira/language_active_learning,
  `lal/active_learning/{laplace,info,next_traj}.py`, the `--active=1 --reward=3 --lang=3` setting of its scripts).
- `infogain` with both kinds in one learner (`--feedback mixed`, `langpref.reward.mixed`): the language and the
  comparison scores above, from the same posterior draws, per modelled second of the person's time.

Every strategy scores all its candidates at once (`langpref.reward.batch.Scored`); `select` asks the best, and
`select_batch` K at once, greedily with a diversity penalty (`langpref.reward.batch.pick`).

The answer model of `infogain` for language. With a linear r_xi the likelihood the learner fits (Eq. 5-9) does not
depend on the shown trajectory (r(phi + psi_l) - r(phi) = xi . psi_l), so its information cannot rank trajectories.
What the shown trajectory changes is *which* feedback the person gives. We model that with the paper's own human
(Eq. 10) in the latent space, the learner's belief xi in place of w: the person names the feature along which the
shown trajectory is farthest, in reward, from the best trajectory they can imagine,

    P(feature f | xi, tau) = softmax_f( (xi . v_f) (v_f . (phi*_xi - phi_tau)) / T ),   phi*_xi = argmax_pool xi . phi,

in the direction that raises r_xi (`increase` when xi . v_f >= 0). v_f is feature f's axis in the latent space, the
unit vector of (mean psi of f's `increase` phrasings - mean psi of its `decrease` ones) over the robot's own bank
split (`negative_split`, whose meanings the robot knows); with the perfect latent space v_f = e_f and this is Eq. 10
exactly (xi = w). T = 1, Eq. 10's. The score is I(xi; answer | tau) = H[E_xi P] - E_xi H[P] over the 2F meanings, in
nats, from `samples` posterior draws. A query whose answer is certain scores 0.

What `lal-infogain` does (and where we depart). The follow-up models an answer l to trajectory tau as
P(l | w, tau) proportional to exp(l . (w - phi_tau)): w is a point of the latent space the feedback points toward. Its
"Laplace" belief over w maximises sum_i l_i . (w - phi_i) on the unit ball (mode: the unit vector along sum_i l_i, or
0 before any answer) with covariance 0.05 I; over l it maximises sum_{m,i} l . (w_m - phi_i) on the unit ball (mode:
the unit vector along that sum; before any answer, 0.95 times a uniform random direction of the positive orthant)
with covariance 0.05 I. It draws M = 10 w and M K = 100 l, and scores each trajectory not shown before by
mean_{m,k} log2(M P(l_k | w_m, tau) / sum_m' P(l_k | w_m', tau)), P normalised over the 100 l samples; the argmax is
shown. Departures: (1) the modes in closed form (the exact optimum of a linear objective on the unit ball, which its
SLSQP call approaches); (2) the covariance 0.05 I: its code scales by 0.05 the inverse Hessian of one L-BFGS-B step
on a linear objective with a -100 cliff at |x| = 1, which is the identity up to that step's finite-difference
curvature pair (an artefact of the cliff, not of the likelihood); (3) scores in the log domain (its exp overflows to
nan, which it maps to 0); (4) our own seeded generator; (5) the reward learned from the answers is ours (the same Eq. 9
fit as every strategy), so the strategies differ only in what they show. Its mean of w samples is not used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from langpref.errors import LangprefError
from langpref.reward.batch import Scored, pair_candidates, pick, shown_candidates
from langpref.reward.posterior import laplace_posterior, require_linear

if TYPE_CHECKING:
    from langpref.feedback.kind import FeedbackKind, SelectorFactory
    from langpref.feedback.space import LatentSpace
    from langpref.reward import RewardConfig, RewardLearner

STRATEGIES = ("random", "infogain", "lal-infogain", "volume-removal")
"""The `query_selection`s of the paper's two kinds; each kind lists its own (`FeedbackKind.strategies`)."""
MIXED_STRATEGIES = ("infogain",)
"""`mixed` (both kinds in one learner, `langpref.reward.mixed`) chooses by information per second: only `infogain`."""
DEFAULT_SAMPLES = 64
"""Posterior draws of xi per selection."""
ANSWER_TEMPERATURE = 1.0
"""T of the language answer model (Eq. 10's)."""
LAL_W, LAL_L_PER_W, LAL_COV = 10, 10, 0.05
"""The follow-up's M, K and covariance scale."""


@dataclass(frozen=True)
class Selection:
    """What a strategy chose and why."""

    query: Any
    score: float | None
    """The chosen query's score: nats of information (`infogain`), expected removed volume (`volume-removal`), the
    follow-up's bit score (`lal-infogain`)."""
    strategy: str
    candidates: int
    """How many trajectories (language) or pairs (comparisons) were scored; both together for a mixed learner."""


_FACTORIES: dict[str, dict[str, SelectorFactory]] = {}
"""kind name -> strategy -> its selector's factory, registered from the reward side (`register_strategy`)."""


def register_strategy(kind: str, strategy: str, factory: SelectorFactory) -> None:
    """Make `strategy` a query selection of feedback `kind` (the paper's are registered below; another package's kind
    may register its own here, or list them in `FeedbackKind.strategies`)."""
    _FACTORIES.setdefault(kind, {})[strategy] = factory


def selector_factories(kind: FeedbackKind) -> dict[str, SelectorFactory | None]:
    """strategy -> factory of `kind`, in the order errors list them: `random` (None: drawn uniformly), the kind's own
    list (`FeedbackKind.strategies`), then those registered here."""
    from langpref.feedback.kind import RANDOM

    return {RANDOM: None, **kind.strategies, **_FACTORIES.get(kind.name, {})}


def strategies_of(feedback: str) -> tuple[str, ...]:
    """The query selections of `feedback`: a registered kind's (`selector_factories`), `MIXED_STRATEGIES` for
    `mixed`."""
    from langpref.feedback.kind import KINDS, MIXED, RANDOM

    if feedback == MIXED:
        return MIXED_STRATEGIES
    kind = KINDS.get(feedback)
    return tuple(selector_factories(kind)) if kind is not None else (RANDOM,)


def known_strategies() -> tuple[str, ...]:
    """Every query selection of some registered kind, the paper's first."""
    from langpref.feedback.kind import kind_names

    return tuple(dict.fromkeys([*STRATEGIES, *(s for name in kind_names() for s in strategies_of(name))]))


def check_strategy(strategy: str, kind: str) -> None:
    """One line naming the choices when `strategy` is unknown or not defined for feedback `kind`."""
    if strategy not in known_strategies():
        raise LangprefError(f"unknown query selection {strategy!r}: choose one of {', '.join(known_strategies())}")
    allowed = strategies_of(kind)
    if strategy not in allowed:
        raise LangprefError(
            f"query selection {strategy!r} is not defined for {kind} feedback: choose one of {', '.join(allowed)}"
        )


def candidate_rows(pool: np.ndarray, candidates: int | None, rng: np.random.Generator) -> np.ndarray:
    """The pool, or a sorted uniform subset of `candidates` of it."""
    pool = np.asarray(pool, dtype=np.int64)
    if candidates is None or candidates >= len(pool):
        return pool
    return np.sort(rng.choice(pool, size=int(candidates), replace=False))


def _entropy(p: np.ndarray, axis: int = -1) -> np.ndarray:
    """Entropy in nats along `axis` (0 log 0 = 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return -np.sum(np.where(p > 0, p * np.log(p), 0.0), axis=axis)


def mutual_information(probs: np.ndarray) -> np.ndarray:
    """I(xi; answer) from answer distributions per posterior draw: probs (S, C, K) -> (C,) nats,
    H[mean_s probs] - mean_s H[probs]; clipped at 0 (rounding)."""
    return np.maximum(_entropy(probs.mean(axis=0)) - _entropy(probs).mean(axis=0), 0.0)


def binary_mutual_information(p: np.ndarray) -> np.ndarray:
    """I(xi; choice) for a two-way answer: p (..., S) the probability of the first answer per draw -> (...,) nats."""

    def h(q):
        q = np.clip(q, 1e-6, 1 - 1e-6)  # float32-safe
        return -(q * np.log(q) + (1 - q) * np.log(1 - q))

    return np.maximum(h(p.mean(axis=-1)) - h(p).mean(axis=-1), 0.0)


class Selector:
    """A strategy with its state: `select` the next query (or `select_batch` the next K) from the learner's current
    fit, then `observe` each answer. A strategy is its `score`: every candidate, scored once."""

    name = "random"
    reads_learner = True
    """Whether `score_rows` reads the learner's fit; False (the follow-up's strategy, which reads only the answers it
    observed): a caller may pass None and spare the fit."""
    observes = False
    """Whether the selector keeps a record of the answers (`observe`); a caller that chooses for many people (the
    study) builds one per choice and shows it that person's answers."""

    def score(self, learner: RewardLearner, rng: np.random.Generator) -> Scored:
        raise NotImplementedError

    def score_rows(self, learner: RewardLearner | None, rows: np.ndarray, rng: np.random.Generator) -> Scored:
        """The queries over exactly `rows` (dataset indices, drawn by the caller) scored from the learner's fit:
        `score` without its own draw of candidates. The study chooses its active queries with it
        (`langpref.study.protocol.queries`), so a kind's strategy runs there with no edit in the study."""
        raise NotImplementedError(f"the {self.name!r} selector cannot score rows it is given (Selector.score_rows)")

    def select_batch(self, learner: RewardLearner, rng: np.random.Generator, k: int) -> list[Selection]:
        """The next min(k, candidates) queries, chosen at once from one scoring (`langpref.reward.batch.pick`);
        k = 1 is `select`."""
        scored = self.score(learner, rng)
        n = len(scored.gains)
        return [Selection(scored.query(c), float(scored.gains[c]), self.name, n) for c in pick(scored, k)]

    def select(self, learner: RewardLearner, rng: np.random.Generator) -> Selection:
        return self.select_batch(learner, rng, 1)[0]

    def observe(self, space: LatentSpace, answer: Any) -> None:
        """Called with every answer (the follow-up's strategy keeps its own record of them)."""


# ---- language -------------------------------------------------------------------------------------------------


def feature_axes(space: LatentSpace, split: str = "train") -> tuple[np.ndarray, np.ndarray]:
    """(feature indices (F',), unit axes v_f (F', D)) of the features with phrasings in bank split `split`:
    the direction from the mean psi of f's `decrease` phrasings to that of its `increase` ones (or either alone)."""
    table = space.table(split)
    feats, axes = [], []
    for f in range(len(space.feature_names)):
        inc, dec = table.rows(f, 0), table.rows(f, 1)
        if len(inc) == 0 and len(dec) == 0:
            continue
        v = (table.psi[inc].mean(axis=0) if len(inc) else 0.0) - (table.psi[dec].mean(axis=0) if len(dec) else 0.0)
        norm = float(np.linalg.norm(v))
        if norm > 1e-12:
            feats.append(f)
            axes.append(v / norm)
    if not feats:
        raise LangprefError(f"bank split {split!r} gives no feature axis for the language answer model")
    return np.array(feats, dtype=np.int64), np.stack(axes)


class LanguageInfoGain(Selector):
    """`infogain` for language: I(xi; answer | tau) under the latent Eq. 10 answer model (module docstring)."""

    name = "infogain"
    kind = "language"
    """The feedback kind of the queries it scores (registered for it below)."""

    def __init__(
        self,
        space: LatentSpace,
        pool: Sequence[int],
        reward: RewardConfig,
        candidates: int | None = None,
        samples: int = DEFAULT_SAMPLES,
        temperature: float = ANSWER_TEMPERATURE,
    ):
        self.space = space
        self.pool = np.asarray(pool, dtype=np.int64)
        self.features, self.axes = feature_axes(space, reward.negative_split)
        self.candidates = candidates
        self.samples = int(samples)
        self.temperature = float(temperature)
        self._pool_proj = space.phi[self.pool] @ self.axes.T  # (N, F)
        self._pool_phi = space.phi[self.pool]

    def best(self, xi: np.ndarray) -> np.ndarray:
        """(S,) position in the pool of phi*_xi, the best trajectory under each draw."""
        return np.argmax(xi @ self._pool_phi.T, axis=1)

    def answer_probabilities(self, xi: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """(S, C, 2F) P(meaning | xi_s, tau_c); meaning 2k + d for feature self.features[k], d = 0 increase."""
        a = xi @ self.axes.T  # (S, F): xi . v_f
        best = self.best(xi)  # (S,) phi*_xi in the pool
        gap = self._pool_proj[best][:, None, :] - (self.space.phi[rows] @ self.axes.T)[None, :, :]  # (S, C, F)
        logits = a[:, None, :] * gap / self.temperature
        logits -= logits.max(axis=2, keepdims=True)
        p = np.exp(logits)
        p /= p.sum(axis=2, keepdims=True)
        up = (a >= 0)[:, None, :]
        out = np.empty(p.shape[:2] + (2 * p.shape[2],))
        out[:, :, 0::2] = np.where(up, p, 0.0)
        out[:, :, 1::2] = np.where(up, 0.0, p)
        return out

    def scores(self, xi: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """I(xi; answer | tau) in nats for each of `rows`, from the draws `xi` (S, D)."""
        return mutual_information(self.answer_probabilities(xi, rows))

    def scored(self, xi: np.ndarray, rows: np.ndarray) -> Scored:
        """`rows` scored from the draws `xi`, each pointing to the mean over draws of phi*_xi."""
        star = self._pool_phi[self.best(xi)].mean(axis=0)
        return shown_candidates(self.kind, rows, self.scores(xi, rows), self.space.phi[rows], star)

    def score(self, learner: RewardLearner, rng: np.random.Generator) -> Scored:
        return self.score_rows(learner, candidate_rows(self.pool, self.candidates, rng), rng)

    def score_rows(self, learner: RewardLearner | None, rows: np.ndarray, rng: np.random.Generator) -> Scored:
        return self.scored(laplace_posterior(learner).sample(self.samples, rng), rows)


class LalInfoGain(Selector):
    """`lal-infogain`: the follow-up's information gain over trajectories not shown before (module docstring)."""

    name = "lal-infogain"
    kind = "language"
    reads_learner = False
    observes = True

    def __init__(self, space: LatentSpace, pool: Sequence[int], candidates: int | None = None):
        self.space = space
        self.pool = np.asarray(pool, dtype=np.int64)
        self.candidates = candidates
        self.shown: list[int] = []
        self.phi: list[np.ndarray] = []
        self.psi: list[np.ndarray] = []

    def observe(self, space: LatentSpace, answer: Any) -> None:
        if answer.no_change:  # the follow-up's model has sentences only
            return
        self.shown.append(int(answer.query.shown))
        self.phi.append(space.phi[answer.query.shown])
        self.psi.append(space.psi_of(answer.text))

    def samples(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(w (M, D), l (M K, D)) drawn from the follow-up's two Gaussians."""
        dim = self.space.dim
        if self.psi:
            total = np.sum(self.psi, axis=0)
            norm = float(np.linalg.norm(total))
            w_mode = total / norm if norm > 0 else np.zeros(dim)
        else:
            w_mode = np.zeros(dim)
        w = w_mode + np.sqrt(LAL_COV) * rng.standard_normal((LAL_W, dim))
        if self.phi:
            total = (w[:, None, :] - np.array(self.phi)[None, :, :]).sum(axis=(0, 1))
            norm = float(np.linalg.norm(total))
            l_mode = total / norm if norm > 0 else np.zeros(dim)
        else:
            guess = rng.random(dim)
            l_mode = 0.95 * guess / np.linalg.norm(guess)
        l_samples = l_mode + np.sqrt(LAL_COV) * rng.standard_normal((LAL_W * LAL_L_PER_W, dim))
        return w, l_samples

    def scores(self, w: np.ndarray, l_samples: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """mean_{m,k} log2(M P(l_k | w_m, tau) / sum_m' P(l_k | w_m', tau)) per row (the follow-up's `info`)."""
        m = len(w)
        logits = (w[:, None, :] - self.space.phi[rows][None, :, :]) @ l_samples.T  # (M, C, MK)
        logp = logits - np.logaddexp.reduce(logits, axis=2, keepdims=True)
        log_tmp = np.log(m) + logp - np.logaddexp.reduce(logp, axis=0, keepdims=True)
        return (log_tmp / np.log(2.0)).sum(axis=(0, 2)) / l_samples.shape[0]

    def score(self, learner: RewardLearner, rng: np.random.Generator) -> Scored:
        """Trajectories not shown before (all when every one was), each pointing away from the pool's mean phi (the
        follow-up has no guess of the best trajectory; only batches use the directions)."""
        rows = candidate_rows(self.pool, self.candidates, rng)
        fresh = rows[~np.isin(rows, self.shown)]
        return self.score_rows(learner, fresh if len(fresh) else rows, rng)

    def score_rows(self, learner: RewardLearner | None, rows: np.ndarray, rng: np.random.Generator) -> Scored:
        w, l_samples = self.samples(rng)
        star = self.space.phi[self.pool].mean(axis=0)
        return shown_candidates(self.kind, rows, self.scores(w, l_samples, rows), self.space.phi[rows], star)


# ---- comparisons ----------------------------------------------------------------------------------------------


class ComparisonActive(Selector):
    """`infogain` (mutual information) or `volume-removal` over every pair of candidates."""

    kind = "comparison"

    def __init__(
        self,
        space: LatentSpace,
        pool: Sequence[int],
        strategy: str,
        candidates: int | None = None,
        samples: int = DEFAULT_SAMPLES,
    ):
        self.space = space
        self.pool = np.asarray(pool, dtype=np.int64)
        self.name = strategy
        self.candidates = candidates
        self.samples = int(samples)

    def scores(self, xi: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, score) over the pairs i < j of `rows` (positions in rows)."""
        r = (self.space.phi[rows] @ xi.T).astype(np.float32)  # (C, S)
        i, j = np.triu_indices(len(rows), k=1)
        p = 0.5 * (1.0 + np.tanh(0.5 * (r[i] - r[j])))  # (P, S) P(tau_i preferred | xi_s)
        if self.name == "infogain":
            s = binary_mutual_information(p)
        else:
            mean = p.mean(axis=1)
            s = 1.0 - mean**2 - (1.0 - mean) ** 2
        return i, j, s

    def scored(self, xi: np.ndarray, rows: np.ndarray) -> Scored:
        """Every pair of `rows` scored from the draws `xi`."""
        i, j, s = self.scores(xi, rows)
        return pair_candidates(self.kind, rows, i, j, s, self.space.phi[rows])

    def score(self, learner: RewardLearner, rng: np.random.Generator) -> Scored:
        return self.score_rows(learner, candidate_rows(self.pool, self.candidates, rng), rng)

    def score_rows(self, learner: RewardLearner | None, rows: np.ndarray, rng: np.random.Generator) -> Scored:
        return self.scored(laplace_posterior(learner).sample(self.samples, rng), rows)


def make_selector(
    strategy: str,
    kind: FeedbackKind,
    space: LatentSpace,
    pool: Sequence[int],
    reward: RewardConfig,
    candidates: int | None = None,
    samples: int | None = None,
) -> Selector | None:
    """The selector of `strategy` for feedback `kind` (built by its factory, `selector_factories`); None for
    `random` (the caller draws uniformly)."""
    check_strategy(strategy, kind.name)
    require_linear(reward.model, strategy)
    factory = selector_factories(kind)[strategy]
    if factory is None:
        return None
    return factory(space, pool, reward, candidates, DEFAULT_SAMPLES if samples is None else int(samples))


# ---- the paper's kinds' strategies ---------------------------------------------------------------------------------


def _language_infogain(space, pool, reward, candidates, samples) -> Selector:
    """`infogain`: the information about xi in the person's answer, under the answer model (Eq. 10 with xi)."""
    return LanguageInfoGain(space, pool, reward, candidates, samples)


def _lal_infogain(space, pool, reward, candidates, samples) -> Selector:
    """`lal-infogain`: the authors' follow-up's selection."""
    return LalInfoGain(space, pool, candidates)


def _comparison(strategy: str) -> SelectorFactory:
    """`infogain` (the mutual information between xi and the choice) or `volume-removal` (the expected removed
    volume, Sadigh et al. 2017), over every pair of candidates."""

    def make(space, pool, reward, candidates, samples) -> Selector:
        return ComparisonActive(space, pool, strategy, candidates, samples)

    return make


register_strategy("language", "infogain", _language_infogain)
register_strategy("language", "lal-infogain", _lal_infogain)
register_strategy("comparison", "infogain", _comparison("infogain"))
register_strategy("comparison", "volume-removal", _comparison("volume-removal"))
