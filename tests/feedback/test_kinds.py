"""The feedback-kind protocol: the two kinds of the paper through it, and a third kind that is one definition here."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.feedback import (
    KINDS,
    FeedbackKind,
    HumanConfig,
    LanguageAnswer,
    PairBatch,
    get_kind,
    random_query,
    register_kind,
    sample_weights,
    softmax,
    toy_latent_space,
    true_reward,
)
from langpref.reward import LearnRewardConfig, RewardConfig, human_weights, run_reward_learning

torch.set_num_threads(1)


# ---- a third kind: show three trajectories, the human picks the best (Luce's choice rule) ----------------------


@dataclass(frozen=True)
class TripleQuery:
    a: int
    b: int
    c: int

    def __post_init__(self) -> None:
        if len({self.a, self.b, self.c}) < 3:
            raise LangprefError("a best-of-three query needs three different trajectories")


@dataclass(frozen=True)
class TripleAnswer:
    query: TripleQuery
    best: int
    """0, 1 or 2: the position of the chosen trajectory."""

    @property
    def shown(self) -> tuple[int, int, int]:
        return self.query.a, self.query.b, self.query.c


class TripleHuman:
    """Picks trajectory i of the three with probability softmax(rationality * R)_i (Bradley-Terry for three)."""

    def __init__(self, w: np.ndarray, theta: np.ndarray, rationality: float, rng: np.random.Generator):
        self.reward = true_reward(w, theta)
        self.rationality = rationality
        self.rng = rng

    def answer(self, query: TripleQuery) -> TripleAnswer:
        shown = [query.a, query.b, query.c]
        return TripleAnswer(query, int(self.rng.choice(3, p=softmax(self.rationality * self.reward[shown]))))


def triple_pairs(space, answer: TripleAnswer, cfg: RewardConfig, rng: np.random.Generator) -> PairBatch:
    """The chosen one beats each of the other two; the answer weighs 1 in all."""
    others = [i for k, i in enumerate(answer.shown) if k != answer.best]
    winner = space.phi[answer.shown[answer.best]]
    return PairBatch(np.stack([winner, winner]), space.phi[others], np.full(2, 0.5))


def triple_parse(value: Any, query: TripleQuery) -> TripleAnswer:
    if isinstance(value, bool) or value not in (0, 1, 2):
        raise LangprefError("'best' must be 0, 1 or 2")
    return TripleAnswer(query, int(value))


def triple_human(
    w: np.ndarray, space, candidates: Sequence[int], cfg: HumanConfig, rng: np.random.Generator
) -> TripleHuman:
    return TripleHuman(w, space.theta, cfg.rationality, rng)


def triple_from_record(row: Mapping[str, Any]) -> TripleAnswer:
    return TripleAnswer(TripleQuery(row["a"], row["b"], row["c"]), row["best"])


TRIPLE = FeedbackKind(
    name="best_of_three",
    query=TripleQuery,
    answer=TripleAnswer,
    shows=3,
    make_human=triple_human,
    pairs=triple_pairs,
    answer_key="best",
    parse=triple_parse,
    value=lambda answer: answer.best,
    table="triples",
    to_record=lambda ans: {"a": ans.query.a, "b": ans.query.b, "c": ans.query.c, "best": ans.best},
    from_record=triple_from_record,
)


@pytest.fixture
def triple():
    register_kind(TRIPLE)
    yield TRIPLE
    KINDS.pop(TRIPLE.name)


@pytest.fixture(scope="module")
def space():
    return toy_latent_space(n=90, dim=10, seed=3)


def test_a_third_kind_learns_a_reward_through_the_same_loop(triple, space):
    """Registered by name, the new kind runs in the reward loop end to end, and its answers teach: the
    cross-entropy to the human's true preferences falls well below the flat reward's, and the learned reward's best
    trajectory is near the best. Swapping winners and losers in its pairs would make both worse."""
    assert get_kind("best_of_three") is triple
    cfg = LearnRewardConfig(feedback="best_of_three", queries=15, human=HumanConfig(rationality=3.0))
    first, last, best = [], [], []
    for h in range(3):
        curves = run_reward_learning(space, human_weights(len(space.feature_names), 0, h), cfg, (0, h, 0))
        assert len(curves.cross_entropy) == cfg.queries + 1
        first.append(curves.cross_entropy[0])
        last.append(curves.cross_entropy[-1])
        best.append(curves.true_reward_of_best[-1])
    assert np.allclose(first, np.log(2))  # zero queries: the flat reward
    assert np.mean(last) < np.log(2) - 0.1
    assert max(last) < np.log(2)
    assert np.mean(best) > 0.85


def test_random_queries_show_distinct_trajectories_of_the_pool(triple, space):
    pool = np.asarray(space.split("train"))
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = random_query(triple, pool, rng)
        assert isinstance(q, TripleQuery) and {q.a, q.b, q.c} <= set(pool.tolist())
    assert isinstance(random_query(get_kind("language"), pool, rng).shown, int)


def test_registry_names_the_known_kinds_and_refuses_a_second_kind_of_a_taken_name(triple):
    assert {"language", "comparison", "best_of_three"} <= set(KINDS)
    with pytest.raises(
        LangprefError,
        match="unknown feedback 'ranking': choose one of .*language.*comparison|"
        "unknown feedback 'ranking': choose one of .*comparison.*language",
    ):
        get_kind("ranking")
    register_kind(TRIPLE)  # the same kind again: nothing changes
    with pytest.raises(LangprefError, match="already registered"):
        register_kind(FeedbackKind(**{**TRIPLE.__dict__, "shows": 2}))
    with pytest.raises(LangprefError, match="unknown feedback"):
        LearnRewardConfig(feedback="ranking").validate()


@pytest.mark.parametrize("name", ["language", "comparison", "best_of_three"])
def test_every_kind_answers_stores_and_parses_its_own_answers(triple, space, name):
    """One path for any kind: a human's answer survives the HTTP value and the stored record, and gives pairs of
    embeddings whose weights sum to what one answer weighs."""
    kind = get_kind(name)
    pool = np.asarray(space.split("train"))
    rng = np.random.default_rng(1)
    w = sample_weights(len(space.feature_names), 2)
    human = kind.make_human(w, space, pool, HumanConfig(), rng)
    for _ in range(5):
        query = random_query(kind, pool, rng)
        answer = human.answer(query)
        assert isinstance(answer, kind.answer) and answer.query == query
        bare = LanguageAnswer(query, answer.text) if name == "language" else answer  # a participant's: no labels
        assert kind.parse(kind.value(answer), query) == bare
        assert kind.from_record(kind.to_record(answer)) == bare
        batch = kind.pairs(space, answer, RewardConfig(num_negatives=4), rng)
        assert batch.winners.shape == batch.losers.shape == (len(batch.weights), space.dim)
        assert np.isclose(batch.weights.sum(), 2.0 if name == "language" else 1.0)


@pytest.mark.parametrize(
    "name, bad",
    [
        ("language", 5),
        ("language", "  "),
        ("language", "x" * 501),
        ("comparison", 2),
        ("comparison", True),
        ("comparison", "1"),
        ("comparison", 1.0),
        ("best_of_three", 3),
    ],
)
def test_bad_http_values_are_one_line_errors(triple, name, bad):
    kind = get_kind(name)
    query = kind.query(*range(kind.shows))
    with pytest.raises(LangprefError) as info:
        kind.parse(bad, query)
    assert "\n" not in str(info.value) and str(info.value)
