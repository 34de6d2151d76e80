"""Synthetic humans (paper Sec. 5.1): a reward R(tau) = w . theta(tau), whatever they answer.

Weights. `sample_weights(F, seed)` draws w uniformly on the unit sphere of R^F (a standard normal vector scaled to
norm 1): every feature matters with a random sign and size.

Feature scale (`HumanConfig.feature_scale`). What theta(tau) is sets how noisy both humans are, since Eq. 10 and
Eq. 11 are softmaxes of reward differences. `standardised` (the default): each feature's per-step mean over the
trajectory, standardised by the train split's mean and std, so every feature weighs by its spread and R differences
between trajectories are O(1). `paper`: the paper's theta(tau), the sum over the trajectory's steps of the raw
per-step features (Sec. 5.1), not standardised: R differences are then tens of units on T = 500 steps, the
comparison human is almost noiseless and the language human almost always names the feature of largest
w_f (theta*_f - theta0_f). The space a command runs in holds the humans' theta (`LatentSpace.theta`, see
`langpref.feedback.space.load_space`); the methods never see it.

How a human of each kind answers is in that kind's module: `langpref.feedback.language` (Eq. 10) and
`langpref.feedback.comparison` (Eq. 11); `HumanConfig` holds the knobs of both.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.space import FEATURE_SCALES, FeatureScaleName, PhrasingSplit, file_table_name

Seed = int | np.random.Generator


def rng_of(seed: Seed) -> np.random.Generator:
    """A generator from a seed, or the generator itself (so humans and callers can share one stream)."""
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def sample_weights(num_features: int, seed: Seed) -> np.ndarray:
    """A human's reward weights: uniform on the unit sphere of R^num_features (normalised standard normal)."""
    if num_features < 1:
        raise LangprefError(f"a reward needs at least one feature, got {num_features}")
    rng = rng_of(seed)
    while True:
        w = rng.standard_normal(num_features)
        norm = float(np.linalg.norm(w))
        if norm > 1e-9:
            return w / norm


def true_reward(w: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """R(tau) = w . theta(tau) for each row of `theta` (normalised features)."""
    return np.asarray(theta, dtype=np.float64) @ np.asarray(w, dtype=np.float64)


def normalised_reward(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Rescale true rewards so the worst of `reference` is 0 and its best is 1."""
    lo, hi = float(np.min(reference)), float(np.max(reference))
    return (np.asarray(values, dtype=np.float64) - lo) / max(hi - lo, 1e-12)


DirectionRule = Literal["reward", "toward-best"]
"""How the language human picks the direction of the feature it names (see `HumanConfig.direction`)."""
FeatureRule = Literal["eq10", "largest-change"]
"""How the language human picks the feature it names (see `HumanConfig.feature_rule`)."""
DIRECTION_RULES: tuple[str, ...] = get_args(DirectionRule)
FEATURE_RULES: tuple[str, ...] = get_args(FeatureRule)


def softmax(logits: np.ndarray) -> np.ndarray:
    z = np.asarray(logits, dtype=np.float64)
    z = np.exp(z - z.max())
    return z / z.sum()


@dataclass(frozen=True)
class HumanConfig:
    """How the synthetic humans answer."""

    temperature: float = 1.0
    """Of the language human's softmax over features (Eq. 10 is temperature 1); small = always the best feature."""
    phrasing_split: PhrasingSplit = "test"
    """Bank split the language human draws its phrasings from (test: unseen by the model; `all`: every split, as the
    paper's human, which speaks "all language utterances of that feature")."""
    phrasings: str | None = None
    """An utterance file (docs/design.md#utterance-files) the language human draws from instead of the bank, e.g.
    heldout/utterances.json, phrasings written by people who never saw the bank."""
    rationality: float = 1.0
    """Of the comparison human, beta in sigmoid(beta (R_A - R_B)); 1 is Eq. 11, large is noiseless."""
    feature_scale: FeatureScaleName = "standardised"
    """theta(tau) of both humans' reward w . theta: `standardised` (per-step mean, standardised by the train split;
    reward differences O(1)) or `paper` (Sec. 5.1: raw per-step features summed over the trajectory's steps; reward
    differences of tens of units, so both humans are nearly noiseless)."""
    direction: DirectionRule = "reward"
    """The direction the language human says for the feature it picked (Eq. 10 does not say): `reward`, the one
    that raises its reward (sign of w_f), or `toward-best`, the one that moves tau^0 toward tau* (sign of theta*_f -
    theta0_f, the difference Eq. 10's softmax weighs; the sign of w_f when they are equal)."""
    feature_rule: FeatureRule = "eq10"
    """How the language human picks the feature it names: `eq10` (the paper's softmax of w_f (theta*_f - theta0_f))
    or `largest-change`, a human no learner models: the feature whose raw value differs most between tau^0 and tau*
    (|theta*_f - theta0_f|, whatever its weight), said in the direction toward tau*."""
    vague: float = 0.0
    """Probability that the language human says something vague that names no feature ("Not quite.")."""
    no_change_logit: float | None = None
    """The logit of "that's good, no change" beside Eq. 10's feature logits w_f (theta*_f - theta0_f) / temperature,
    so it is likely only near the human's best trajectory (at tau* itself it has e^c / (e^c + F)); None: the human
    always names a feature (the paper's). With `largest-change`, the human says it when shown tau* itself."""
    no_change_margin: float | None = None
    """A "no change" rule no learner models: the human says "that's good, no change" whenever the shown
    trajectory's true reward is within this margin of the best it knows (tau*, the best of the query split), on the
    scale where the query split's worst is 0 and tau* is 1 (0.05: within 5% of the range), and otherwise names a
    feature as `feature_rule` says. A threshold, not the answer model's softmax of a logit beside the features'.
    None: off (the paper's human). Not with `no_change_logit`."""

    @property
    def phrase_source(self) -> str:
        """The name of the space's phrase table the language human draws from."""
        return file_table_name(self.phrasings) if self.phrasings else self.phrasing_split

    def validate(self) -> None:
        if not self.temperature > 0:
            raise LangprefError(f"the language human's temperature must be > 0, got {self.temperature}")
        if not self.rationality >= 0:
            raise LangprefError(f"the comparison human's rationality must be >= 0, got {self.rationality}")
        if self.feature_scale not in FEATURE_SCALES:
            raise LangprefError(
                f"unknown feature scale {self.feature_scale!r}: choose one of {', '.join(FEATURE_SCALES)}"
            )
        if self.feature_rule not in FEATURE_RULES:
            raise LangprefError(f"unknown feature rule {self.feature_rule!r}: choose one of {', '.join(FEATURE_RULES)}")
        if not 0.0 <= self.vague <= 1.0:
            raise LangprefError(f"the share of vague answers must be in [0, 1], got {self.vague}")
        if self.no_change_margin is not None and not (
            0.0 <= self.no_change_margin <= 1.0 and self.no_change_logit is None
        ):
            raise LangprefError("the no-change margin takes a value in [0, 1], and not with a no-change logit")
        if self.direction not in DIRECTION_RULES:
            raise LangprefError(
                f"unknown direction rule {self.direction!r}: choose one of {', '.join(DIRECTION_RULES)}"
            )

    def variant(self) -> list[str]:
        """What sets these humans apart from the default ones, for an output's name (none for the defaults)."""
        return (
            ([] if self.feature_scale == "standardised" else [f"{self.feature_scale}-scale"])
            + ([] if self.direction == "reward" else [self.direction])
            + ([] if self.feature_rule == "eq10" else [self.feature_rule])
            + ([] if self.vague == 0 else [f"vague{self.vague:g}"])
            + ([] if self.no_change_logit is None else [f"nochange{self.no_change_logit:g}"])
            + ([] if self.no_change_margin is None else [f"nochange-margin{self.no_change_margin:g}"])
        )
