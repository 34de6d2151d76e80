"""Batches of active queries (`--query-batch K`): K distinct queries that do not all ask the same thing, a batch of 1
is the single-query strategy, and the learner is refit only after each batch."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from langpref.feedback import toy_latent_space
from langpref.reward import LearnRewardConfig, RewardConfig, RewardLearner, human_weights, run_reward_learning
from langpref.reward.batch import join, pair_candidates, pick, shown_candidates, similarity_to
from langpref.reward.selection import ComparisonActive, LanguageInfoGain

torch.set_num_threads(1)


def test_a_batch_skips_a_near_duplicate_of_what_it_already_asks():
    # four trajectories in 2-D; phi* at the origin. 0 and 1 lie the same way from it (parallel gaps), 2 at a right
    # angle, 3 the opposite way from 0 (the same question, sign aside)
    phi = np.array([[1.0, 0.0], [2.0, 0.01], [0.0, 1.0], [-1.5, 0.0]])
    gains = np.array([1.0, 0.99, 0.6, 0.95])
    scored = shown_candidates("language", np.array([10, 11, 12, 13]), gains, phi, np.zeros(2))
    assert pick(scored, 1) == [0]
    assert pick(scored, 2) == [0, 2]  # not 1 nor 3: they point along 0's direction
    assert sorted(pick(scored, 4)) == [0, 1, 2, 3]  # K distinct items, as many as there are
    assert pick(scored, 9) == pick(scored, 4)
    np.testing.assert_allclose(similarity_to(scored, 0)[[1, 3]], 1.0, atol=1e-3)
    assert similarity_to(scored, 0)[2] == pytest.approx(0.0)
    # comparisons: (a, b) and (b, a) are one question, a pair along another axis is a new one
    cmp = pair_candidates(
        "comparison", np.arange(4), np.array([0, 1, 0]), np.array([1, 0, 2]), np.array([0.5, 0.49, 0.3]), np.eye(4)
    )
    assert pick(cmp, 2) == [0, 2]


def test_a_direction_of_length_zero_is_like_nothing_and_ties_go_to_the_least_alike():
    phi = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.1], [0.0, 1.0]])
    # every answer certain: all score 0
    scored = shown_candidates("language", np.arange(4), np.zeros(4), phi, np.zeros(2))
    assert similarity_to(scored, 0).tolist() == [0.0, 0.0, 0.0, 0.0]
    assert pick(scored, 3) == [0, 1, 3]  # after 1, the tie among 2 and 3 goes to 3, at a right angle to 1


def test_costs_rank_by_gain_per_second():
    phi = np.eye(3)
    lang = shown_candidates("language", np.arange(3), np.array([0.5, 0.4, 0.1]), phi, np.zeros(3))
    cmp = pair_candidates("comparison", np.arange(3), np.array([0]), np.array([1]), np.array([0.5]), phi)
    both = join([lang, cmp], {"language": 0.887, "comparison": 1.0})
    assert both.kinds == ("language", "comparison") and both.costs.tolist() == [0.887] * 3 + [1.0]
    assert both.query(pick(both, 1)[0]).__class__.__name__ == "LanguageQuery"
    both = join([lang, cmp], {"language": 1.2, "comparison": 1.0})
    assert both.query(pick(both, 1)[0]).__class__.__name__ == "ComparisonQuery"


def _learner(space, n: int = 5) -> RewardLearner:
    """A linear learner fit on a few comparisons of the toy space."""
    from langpref.feedback.bradley_terry import PairBatch

    learner = RewardLearner(space.dim, RewardConfig(max_iter=200))
    rng = np.random.default_rng(0)
    for _ in range(n):
        a, b = rng.choice(space.split("train"), 2, replace=False)
        learner.add(PairBatch(space.phi[[a]], space.phi[[b]], np.ones(1)))
    learner.fit()
    return learner


def _alike(scored, chosen) -> float:
    """The mean similarity of the directions of the candidates `chosen`, over their pairs."""
    return float(np.mean([similarity_to(scored, c)[d] for c in chosen for d in chosen if c < d]))


@pytest.mark.parametrize("strategy", ["infogain", "volume-removal"])
def test_selector_batches_are_distinct_diverse_and_k1_is_select(strategy):
    space = toy_latent_space("metaworld", n=40, seed=3)
    learner = _learner(space)
    pool = space.split("train")
    selectors = [ComparisonActive(space, pool, strategy, candidates=15)]
    if strategy == "infogain":
        selectors.append(LanguageInfoGain(space, pool, RewardConfig(), candidates=15))
    for selector in selectors:
        one = selector.select(learner, np.random.default_rng(7))
        assert selector.select_batch(learner, np.random.default_rng(7), 1) == [one]
        batch = selector.select_batch(learner, np.random.default_rng(7), 4)
        assert len(batch) == 4 and len({s.query for s in batch}) == 4 and batch[0] == one
        # diverse: the batch's directions are less alike than those of the 4 best by score alone
        scored = selector.score(learner, np.random.default_rng(7))
        chosen = pick(scored, 4)
        top = list(np.argsort(-scored.gains, kind="stable")[:4])

        assert _alike(scored, chosen) <= _alike(scored, top) + 1e-12


@pytest.mark.parametrize("feedback,strategy", [("language", "infogain"), ("comparison", None), ("mixed", None)])
def test_batch_of_one_is_the_run_of_before_and_a_batch_refits_only_at_its_end(feedback, strategy):
    space = toy_latent_space("metaworld", n=30, seed=1)
    w = human_weights(len(space.feature_names), 0, 0)
    base = LearnRewardConfig(
        feedback=feedback,
        queries=5,
        query_selection=strategy,
        candidates=10,
        reward=RewardConfig(num_negatives=4, max_iter=50),
    )
    runs = {}
    for k in (None, 1, 3):
        record: list = []
        curves = run_reward_learning(space, w, replace(base, query_batch=k), (0, 1, 2), record)
        runs[k] = ([chosen.query for chosen, _ in record], curves)
    assert runs[None][0] == runs[1][0] and runs[None][1] == runs[1][1]
    ce = runs[3][1].cross_entropy
    assert len(ce) == 6 and len(runs[3][0]) == 5
    assert ce[0] == ce[1] == ce[2] != ce[3]  # refit after the 3rd answer, not before
    assert ce[4] == ce[3] != ce[5]  # the last batch holds the remaining 2
    if strategy is None and feedback != "mixed":  # random: the same uniform draws, only the refits differ
        assert runs[3][0] == runs[1][0]
