"""A kind is read by the answer-model learner from the kind itself (`FeedbackKind.readings`), and joins `--feedback
mixed` by saying so (`FeedbackKind.mixed`): a kind from another package runs under both with no edit in langpref
(issue 43). The kind here is the comparison under another name, query type and cost, so that every path it takes is
the generic one."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from langpref.feedback import KINDS, toy_latent_space
from langpref.feedback.comparison import COMPARISON, ComparisonQuery
from langpref.reward import LearnRewardConfig, learn_reward
from langpref.reward.batch import pair_candidates
from langpref.reward.cost import query_costs
from langpref.reward.mixed import MixedInfoGain
from langpref.reward.readings import NAME, AnswerKind, reading_of
from langpref.reward.selection import ComparisonActive


@dataclass(frozen=True)
class PickQuery(ComparisonQuery):
    """Two trajectories, one picked: a query type of its own, so the loop tells the kinds apart."""


class PickInfoGain(ComparisonActive):
    kind = "pick"


def _infogain(space, pool, reward, candidates, samples):
    return PickInfoGain(space, pool, "infogain", candidates, samples)


def _candidates(learner, v, best, rows, phi):
    return pair_candidates("pick", rows, *learner.comparison_gains(v, rows), phi)


@pytest.fixture
def pick(monkeypatch):
    comparison = reading_of("comparison")
    kind = replace(
        COMPARISON,
        name="pick",
        query=PickQuery,
        seconds=0.5,
        mixed=True,
        strategies={"random": None, "infogain": _infogain},
        readings={NAME: AnswerKind(comparison.record, comparison.log_likelihood, _candidates)},
    )
    monkeypatch.setitem(KINDS, "pick", kind)
    return kind


def _cfg(**kw) -> LearnRewardConfig:
    cfg = LearnRewardConfig(queries=4, humans=1, seeds=1, candidates=8, posterior_samples=16, **kw)
    cfg.answer_model.particles = 128
    return cfg


def test_the_answer_model_reads_a_kind_by_the_reading_it_brings(pick):
    space = toy_latent_space("metaworld", n=30, dim=6, seed=1)
    out = learn_reward(space, _cfg(feedback="pick", learner="answer-model", query_selection="infogain"), progress=False)
    assert out["feedback"] == "pick" and len(out["cross_entropy"]) == 5
    with pytest.raises(Exception, match="takes .*pick.*, not 'rating'"):
        reading_of("rating")


def test_a_kind_that_says_it_mixes_is_asked_in_mixed_with_its_own_cost(pick):
    space = toy_latent_space("metaworld", n=30, dim=6, seed=1)
    assert query_costs() == {"language": pytest.approx(0.887), "comparison": 1.0, "pick": 0.5}
    selector = MixedInfoGain(space, space.split("train"), LearnRewardConfig().reward, query_costs(), candidates=8)
    assert list(selector.selectors) == ["language", "comparison", "pick"]
    scored = selector.score(_learner(space), np.random.default_rng(0))
    assert set(scored.kinds) == {"language", "comparison", "pick"}
    for learner in ("paper", "answer-model"):
        out = learn_reward(space, _cfg(feedback="mixed", learner=learner, query_selection="infogain"), progress=False)
        assert len(out["cross_entropy"]) == 5, learner


def _learner(space):
    from langpref.reward import RewardLearner

    return RewardLearner(space.dim)
