"""Synthetic humans (paper Sec. 5.1): a reward R(tau) = w . theta(tau) on normalised features, and how they answer.

Weights. `sample_weights(F, seed)` draws w uniformly on the unit sphere of R^F (a standard normal vector scaled to
norm 1): every feature matters with a random sign and size, and R differences between trajectories are O(1) because
`theta` is in units of each feature's train-split standard deviation.

Language human (Eq. 10). Shown tau^0, with tau* the best trajectory of its candidate set under w, it samples a feature
f from softmax(w (.) (theta*_f - theta0_f) / temperature), says the direction that raises its reward (`increase` when
w_f >= 0), and picks a phrasing of that feature and direction uniformly from one split of the bank (default `test`,
phrasings the model never trained on). The paper's Eq. 10 has no temperature (temperature 1).

Comparison human (Eq. 11). Prefers tau_A over tau_B with probability sigmoid(rationality * (R(tau_A) - R(tau_B)));
rationality 1 is the paper's P_w, a large rationality is a noiseless human (the authors' code).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.space import PhraseTable, file_table_name
from langpref.feedback.types import ComparisonAnswer, ComparisonQuery, LanguageAnswer, LanguageQuery
from langpref.language.bank import DIRECTIONS

Seed = int | np.random.Generator


def _rng(seed: Seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def sample_weights(num_features: int, seed: Seed) -> np.ndarray:
    """A human's reward weights: uniform on the unit sphere of R^num_features (normalised standard normal)."""
    if num_features < 1:
        raise LangprefError(f"a reward needs at least one feature, got {num_features}")
    rng = _rng(seed)
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


def softmax(logits: np.ndarray) -> np.ndarray:
    z = np.asarray(logits, dtype=np.float64)
    z = np.exp(z - z.max())
    return z / z.sum()


@dataclass(frozen=True)
class HumanConfig:
    """How the synthetic humans answer."""

    temperature: float = 1.0
    """Of the language human's softmax over features (Eq. 10 is temperature 1); small = always the best feature."""
    phrasing_split: str = "test"
    """Bank split the language human draws its phrasings from (test: unseen by the model; `all`: every split, as the
    paper's human, which speaks "all language utterances of that feature")."""
    phrasings: str | None = None
    """An utterance file (DESIGN.md schema) the language human draws from instead of the bank, e.g.
    heldout/utterances.json, phrasings written by people who never saw the bank."""
    rationality: float = 1.0
    """Of the comparison human, beta in sigmoid(beta (R_A - R_B)); 1 is Eq. 11, large is noiseless."""

    @property
    def phrase_source(self) -> str:
        """The name of the space's phrase table the language human draws from."""
        return file_table_name(self.phrasings) if self.phrasings else self.phrasing_split

    def validate(self) -> None:
        if not self.temperature > 0:
            raise LangprefError(f"the language human's temperature must be > 0, got {self.temperature}")
        if not self.rationality >= 0:
            raise LangprefError(f"the comparison human's rationality must be >= 0, got {self.rationality}")


class LanguageHuman:
    """Answers language queries about trajectories with Eq. 10, relative to the best of its candidate set."""

    def __init__(self, w: np.ndarray, theta: np.ndarray, phrases: PhraseTable, candidates: Sequence[int],
                 feature_names: Sequence[str], temperature: float = 1.0, seed: Seed = 0):
        self.w = np.asarray(w, dtype=np.float64)
        self.theta = np.asarray(theta, dtype=np.float64)
        if self.theta.shape[1] != len(self.w):
            raise LangprefError(f"{len(self.w)} weights for {self.theta.shape[1]} features")
        if not temperature > 0:
            raise LangprefError(f"the language human's temperature must be > 0, got {temperature}")
        self.phrases = phrases
        self.feature_names = tuple(feature_names)
        self.temperature = float(temperature)
        cands = np.asarray(candidates, dtype=np.int64)
        self.best = int(cands[np.argmax(true_reward(self.w, self.theta[cands]))])
        """tau*, the best trajectory of the candidate set under w."""
        self.rng = _rng(seed)

    def feature_probabilities(self, shown: int) -> np.ndarray:
        """softmax(w (.) (theta* - theta0) / temperature) over the features (Eq. 10)."""
        return softmax(self.w * (self.theta[self.best] - self.theta[shown]) / self.temperature)

    def direction(self, feature: int) -> int:
        """The direction (0 increase, 1 decrease) of `feature` that raises the reward."""
        return 0 if self.w[feature] >= 0 else 1

    def answer(self, query: LanguageQuery) -> LanguageAnswer:
        feature = int(self.rng.choice(len(self.w), p=self.feature_probabilities(query.shown)))
        direction = self.direction(feature)
        rows = self.phrases.rows(feature, direction)
        if len(rows) == 0:
            raise LangprefError(f"the phrasings this human speaks from have none of {self.feature_names[feature]}/"
                                f"{DIRECTIONS[direction]}")
        row = int(rows[self.rng.integers(len(rows))])
        return LanguageAnswer(query, self.phrases.texts[row], self.feature_names[feature], DIRECTIONS[direction])


class ComparisonHuman:
    """Answers comparison queries with the Bradley-Terry model of Eq. 11."""

    def __init__(self, w: np.ndarray, theta: np.ndarray, rationality: float = 1.0, seed: Seed = 0):
        self.w = np.asarray(w, dtype=np.float64)
        self.reward = true_reward(self.w, theta)
        if not rationality >= 0:
            raise LangprefError(f"the comparison human's rationality must be >= 0, got {rationality}")
        self.rationality = float(rationality)
        self.rng = _rng(seed)

    def probability(self, a: int, b: int) -> float:
        """P_w(tau_a > tau_b) = sigmoid(rationality * (R_a - R_b))."""
        z = self.rationality * (self.reward[a] - self.reward[b])
        return float(0.5 * (1.0 + np.tanh(0.5 * z)))

    def answer(self, query: ComparisonQuery) -> ComparisonAnswer:
        prefers_a = self.rng.random() < self.probability(query.a, query.b)
        return ComparisonAnswer(query, 0 if prefers_a else 1)
