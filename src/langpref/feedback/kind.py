"""A kind of feedback as one value: its query and answer types, its synthetic human, its likelihood as Bradley-Terry
pairs, how an answer arrives over HTTP and how it is stored. APReL's taxonomy is the model (one query type with one
user model's `loglikelihood` each); here the likelihood is a list of weighted Bradley-Terry pairs, which the reward
learner (`langpref.reward`) fits whatever the kind.

    from langpref.feedback import get_kind
    kind = get_kind("comparison")
    human = kind.make_human(w, space, space.split("train"), HumanConfig(), rng)
    answer = human.answer(random_query(kind, space.split("train"), rng))
    batch = kind.pairs(space, answer, RewardConfig(), rng)

The two kinds of the paper are `langpref.feedback.language` and `langpref.feedback.comparison`; the package imports
both, so they are in `KINDS` whenever `langpref.feedback` is imported. A new kind is one module that builds a
`FeedbackKind` and passes it to `register_kind`; `langpref learn-reward` and the reward loop then take it by name.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from langpref.errors import LangprefError

if TYPE_CHECKING:
    from langpref.feedback.bradley_terry import PairBatch
    from langpref.feedback.humans import HumanConfig
    from langpref.feedback.space import LatentSpace
    from langpref.reward import RewardConfig


class Human(Protocol):
    """A synthetic human of one kind: answers that kind's queries."""

    def answer(self, query: Any) -> Any: ...


@dataclass(frozen=True)
class FeedbackKind:
    """Everything the library needs to know about one kind of feedback."""

    name: str
    """`--feedback NAME`; in the study, the kind of step and the method of Study 2."""
    query: type
    """The frozen query type; `query(*indices)` is the query showing those dataset trajectories."""
    answer: type
    """The frozen answer type; every answer holds its `query`."""
    shows: int
    """How many trajectories a query shows (videos of a study step)."""
    make_human: Callable[[np.ndarray, LatentSpace, Sequence[int], HumanConfig, np.random.Generator], Human]
    """(w, space, candidates, config, rng) -> the synthetic human with true reward w . theta."""
    pairs: Callable[[LatentSpace, Any, RewardConfig, np.random.Generator], PairBatch]
    """(space, answer, reward config, rng) -> the answer's likelihood as weighted Bradley-Terry pairs of embeddings.
    The pairs read only phi and psi, never the synthetic human's ground truth."""
    answer_key: str
    """The field of an HTTP answer body that holds this kind's answer (DESIGN.md's study contract)."""
    parse: Callable[[Any, Any], Any]
    """(the body's value at `answer_key`, the query shown) -> the answer; a one-line LangprefError for bad input."""
    value: Callable[[Any], Any]
    """answer -> what a client sends at `answer_key` (the inverse of `parse`)."""
    table: str
    """The study database table that stores this kind's answers."""
    to_record: Callable[[Any], dict[str, Any]]
    """answer -> its columns of `table` (the study adds the query number and times)."""
    from_record: Callable[[Mapping[str, Any]], Any]
    """A stored row of `table` -> the answer again (the study replays them to rebuild a learner)."""


KINDS: dict[str, FeedbackKind] = {}
"""The registered kinds by name."""
MIXED = "mixed"
"""The `feedback` of a learner that asks either kind, chosen per query (`langpref.reward.mixed`); not a kind."""
MIXED_KINDS = ("language", "comparison")
"""The kinds a mixed learner chooses between, in this order."""


def register_kind(kind: FeedbackKind) -> FeedbackKind:
    """Add `kind` to `KINDS`; a second, different kind under a taken name is an error."""
    known = KINDS.get(kind.name)
    if known is not None and known != kind:
        raise LangprefError(f"a feedback kind named {kind.name!r} is already registered")
    KINDS[kind.name] = kind
    return kind


def get_kind(name: str) -> FeedbackKind:
    """The registered kind called `name`."""
    try:
        return KINDS[name]
    except (KeyError, TypeError):
        raise LangprefError(f"unknown feedback {name!r}: choose one of {', '.join(KINDS)}") from None


def random_query(kind: FeedbackKind, pool: np.ndarray, rng: np.random.Generator) -> Any:
    """A query of `kind` showing trajectories drawn uniformly from `pool` (distinct ones when it shows several)."""
    if kind.shows == 1:
        return kind.query(int(rng.choice(pool)))
    return kind.query(*(int(i) for i in rng.choice(pool, size=kind.shows, replace=False)))


def kind_of(query: Any) -> FeedbackKind:
    """The registered kind whose query type `query` is (a mixed learner asks queries of several kinds)."""
    for kind in KINDS.values():
        if type(query) is kind.query:
            return kind
    raise LangprefError(f"no registered feedback kind asks a {type(query).__name__}")
