"""A learner of another package's (`langpref.reward.learners.register_learner`, or the entry-point group
`langpref.learners`) runs through `learn-reward`, recorded answers and a saved reward with no edit inside langpref."""

from __future__ import annotations

import numpy as np
import pytest

from langpref.errors import LangprefError
from langpref.feedback.space import toy_latent_space
from langpref.reward import LearnRewardConfig, learn_reward
from langpref.reward.learners import LearnerType, get_learner, learner_names, register_learner


class MeanDirection:
    """r = xi . phi with xi the mean direction the answers point: psi of each sentence, winner minus loser of each
    comparison. Crude, and enough to show a learner needs nothing but these four members."""

    def __init__(self, space, seed: int):
        self.space, self.dirs = space, []

    @property
    def num_queries(self) -> int:
        return len(self.dirs)

    def fit(self) -> None:
        pass

    def predict(self, phi: np.ndarray) -> np.ndarray:
        xi = np.mean(self.dirs, axis=0) if self.dirs else np.zeros(self.space.dim)
        return np.asarray(phi) @ xi


def _teach(learner, space, kind, answer, settings, rng, meaning=None):
    if kind.name == "language":
        learner.dirs.append(space.psi_of(answer.text))
    else:
        q = answer.query
        loser = q.a if answer.preferred == q.b else q.b
        learner.dirs.append(space.phi[answer.preferred] - space.phi[loser])


PLUGIN = LearnerType(
    "mean-direction",
    MeanDirection,
    lambda space, pool, settings, seed: MeanDirection(space, seed),
    _teach,
    lambda learner: ("linear", {"xi": learner.predict(np.eye(learner.space.dim)).tolist()}, {"learner": "mean"}),
)


@pytest.fixture(autouse=True, scope="module")
def registered():
    from langpref.reward.learners import REGISTRY

    register_learner(PLUGIN)
    yield
    REGISTRY.items.pop(PLUGIN.name)  # the other tests' `--learner` choices are the built-in ones


def test_a_registered_learner_runs_through_learn_reward():
    assert "mean-direction" in learner_names() and get_learner("mean-direction") is PLUGIN
    space = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    for feedback in ("language", "comparison"):
        cfg = LearnRewardConfig(feedback=feedback, learner="mean-direction", queries=12, humans=2, seeds=1)
        out = learn_reward(space, cfg, progress=False)
        assert out["true_reward_of_best"][-1] > out["true_reward_of_best"][0], feedback
    with pytest.raises(LangprefError, match="the mean-direction learner asks with random queries, not 'infogain'"):
        LearnRewardConfig(feedback="mixed", learner="mean-direction").validate()  # mixed chooses by information


def test_its_name_is_taken_once_and_unknown_names_are_one_line():
    with pytest.raises(LangprefError, match="already registered"):
        register_learner(LearnerType("mean-direction", object, None, None, None))
    with pytest.raises(LangprefError, match="unknown learner 'bayes': choose one of paper, answer-model"):
        LearnRewardConfig(learner="bayes").validate()
