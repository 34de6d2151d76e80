"""Comparisons (paper Eq. 11), the baseline: two trajectories shown, the better one chosen.

Human. Prefers tau_A over tau_B with probability sigmoid(rationality * (R(tau_A) - R(tau_B))) (Bradley-Terry);
rationality 1 is the paper's P_w, a large rationality is a noiseless human (the authors' code).

Likelihood. One Bradley-Terry pair of weight 1: the preferred trajectory's phi beats the other's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback import bradley_terry
from langpref.feedback.bradley_terry import PairBatch
from langpref.feedback.humans import HumanConfig, Seed, rng_of, true_reward
from langpref.feedback.kind import FeedbackKind, StudyPage, register_kind
from langpref.feedback.space import LatentSpace


@dataclass(frozen=True)
class ComparisonQuery:
    """Show two trajectories and ask which one is better."""

    a: int
    b: int

    def __post_init__(self) -> None:
        if self.a == self.b:
            raise LangprefError(f"a comparison needs two different trajectories, got {self.a} twice")


@dataclass(frozen=True)
class ComparisonAnswer:
    """The choice of a comparison: 0 prefers `query.a`, 1 prefers `query.b`."""

    query: ComparisonQuery
    choice: int

    def __post_init__(self) -> None:
        if self.choice not in (0, 1):
            raise LangprefError(f"a comparison choice is 0 or 1, got {self.choice!r}")

    @property
    def preferred(self) -> int:
        return self.query.b if self.choice else self.query.a

    @property
    def rejected(self) -> int:
        return self.query.a if self.choice else self.query.b


class ComparisonHuman:
    """Answers comparison queries with the Bradley-Terry model of Eq. 11."""

    def __init__(self, w: np.ndarray, theta: np.ndarray, rationality: float = 1.0, seed: Seed = 0):
        self.w = np.asarray(w, dtype=np.float64)
        self.reward = true_reward(self.w, theta)
        if not rationality >= 0:
            raise LangprefError(f"the comparison human's rationality must be >= 0, got {rationality}")
        self.rationality = float(rationality)
        self.rng = rng_of(seed)

    def probability(self, a: int, b: int) -> float:
        """P_w(tau_a > tau_b) = sigmoid(rationality * (R_a - R_b))."""
        return float(bradley_terry.probability(self.rationality * (self.reward[a] - self.reward[b])))

    def answer(self, query: ComparisonQuery) -> ComparisonAnswer:
        prefers_a = self.rng.random() < self.probability(query.a, query.b)
        return ComparisonAnswer(query, 0 if prefers_a else 1)


def make_human(
    w: np.ndarray, space: LatentSpace, candidates: Sequence[int], cfg: HumanConfig, rng: np.random.Generator
) -> ComparisonHuman:
    """The Eq. 11 human of rationality `cfg.rationality` (it compares any two trajectories: no candidate set)."""
    return ComparisonHuman(w, space.theta, cfg.rationality, rng)


def comparison_pairs(
    space: LatentSpace, answer: ComparisonAnswer, cfg: Any = None, rng: np.random.Generator | None = None
) -> PairBatch:
    """The one Bradley-Terry pair of a comparison: preferred beats rejected (the learner's settings `cfg` and `rng`
    are not read)."""
    return PairBatch(space.phi[[answer.preferred]], space.phi[[answer.rejected]], np.ones(1))


# ---- over HTTP and in the study database ----------------------------------------------------------------------


def parse(value: Any, query: ComparisonQuery) -> ComparisonAnswer:
    """The body's `choice`: the integer 0 (the first video) or 1 (the second)."""
    if isinstance(value, bool) or not isinstance(value, int) or value not in (0, 1):
        raise LangprefError("'choice' must be 0 (the left/first video) or 1 (the right/second video)")
    return ComparisonAnswer(query, value)


def to_record(answer: ComparisonAnswer) -> dict[str, Any]:
    return {"a": answer.query.a, "b": answer.query.b, "choice": answer.choice, "preferred": answer.preferred}


def from_record(row: Mapping[str, Any]) -> ComparisonAnswer:
    return ComparisonAnswer(ComparisonQuery(int(row["a"]), int(row["b"])), int(row["choice"]))


def to_line(answer: ComparisonAnswer) -> dict[str, Any]:
    """A comparison's fields in an answers file: `shown`, the pair in the order shown, and `choice`."""
    return {"shown": [int(answer.query.a), int(answer.query.b)], "choice": int(answer.choice)}


def from_line(obj: dict[str, Any], where: str, resolve: Callable[[Any, str], int]) -> ComparisonAnswer:
    """A comparison of an answers file: `shown`, the pair shown (index or episode name each), and `choice`."""
    shown = obj.get("shown")
    if not isinstance(shown, list) or len(shown) != 2:
        raise LangprefError(f"{where}: a comparison's 'shown' is the pair shown, [first, second]")
    a, b = resolve(shown[0], where), resolve(shown[1], where)
    if a == b:
        raise LangprefError(f"{where}: a comparison shows two different trajectories, got {a} twice")
    choice = obj.get("choice")
    if isinstance(choice, bool) or choice not in (0, 1):
        raise LangprefError(f"{where}: 'choice' must be 0 (the first shown was preferred) or 1 (the second)")
    return ComparisonAnswer(ComparisonQuery(a, b), int(choice))


COMPARISON = register_kind(
    FeedbackKind(
        name="comparison",
        query=ComparisonQuery,
        answer=ComparisonAnswer,
        shows=2,
        make_human=make_human,
        pairs=comparison_pairs,
        answer_key="choice",
        parse=parse,
        value=lambda answer: answer.choice,
        table="comparisons",
        to_record=to_record,
        from_record=from_record,
        from_line=from_line,
        to_line=to_line,
        mixed=True,
        page=StudyPage(
            widget="choice",
            label="Pair-wise comparison",
            prompt="Which trajectory do you prefer?",
            intro="Each query shows two trajectories. Choose the one you prefer; the robot learns what you prefer "
            "from your choices.",
            option="I prefer trajectory {n}",
        ),
    )
)
