"""Blindness: no method reads the synthetic human's weights w or the true features theta.

Each test records a synthetic human's answers, then runs the method again on a world whose truth is scrambled after
the fact (theta's rows shuffled among the trajectories and its columns permuted, w permuted and negated: the true
reward of every trajectory changes) while a stand-in human replays the recorded answers. What the method does (the
queries it asks, the reward it learns, the trajectories it moves to) must be the same, bit for bit: anything that
read the truth would change. Only the metrics, which are meant to read the truth, may differ. The study robot's test
is in tests/study/session/test_robot_blindness.py.
"""

from dataclasses import replace

import numpy as np
import pytest

import langpref.improve as improve_module
import langpref.reward as reward_module
from langpref.feedback import KINDS, toy_latent_space
from langpref.feedback.humans import HumanConfig
from langpref.improve import ImproveConfig, run_improvement
from langpref.reward import LearnRewardConfig, human_weights, run_reward_learning
from langpref.reward.answer_model import AnswerModelConfig


class Replay:
    """A stand-in human: gives the recorded answers in order, and checks it is asked the recorded queries."""

    def __init__(self, answers):
        self.answers = list(answers)

    def answer(self, query):
        answer = self.answers.pop(0)
        assert query == answer.query, "the method asked another query than when the real human answered"
        return answer


def scrambled(space, w, seed=0):
    """The same space with the truth scrambled: theta rows shuffled, columns permuted; w permuted and negated."""
    rng = np.random.default_rng(seed)
    rows, cols = rng.permutation(len(space.theta)), rng.permutation(space.theta.shape[1])
    return replace(space, theta=space.theta[rows][:, cols] * 3.0 + 1.0), -w[cols]


@pytest.fixture
def snapshots(monkeypatch):
    """Every reward learner's parameters after every fit, in order (what the learner has learned)."""
    taken = []
    original = reward_module.RewardLearner.fit

    def fit(self):
        original(self)
        taken.append([p.detach().numpy().copy() for p in self.params])

    monkeypatch.setattr(reward_module.RewardLearner, "fit", fit)
    return taken


@pytest.mark.parametrize(
    "feedback, selection",
    [("language", "random"), ("language", "infogain"), ("comparison", "random"), ("comparison", "infogain")],
)
def test_reward_learning_is_blind_to_the_truth(feedback, selection, snapshots, monkeypatch):
    space = toy_latent_space("metaworld", n=30, dim=8, seed=1)
    cfg = LearnRewardConfig(
        feedback=feedback,
        queries=6,
        query_selection=selection,
        candidates=8,
        posterior_samples=16,
        human=HumanConfig(phrasing_split="test"),
    )
    w = human_weights(len(space.feature_names), 0, 0)
    record = []
    run_reward_learning(space, w, cfg, (0, 0, 0), record=record)
    first, answers = [s.copy() for s in map(list, snapshots)], [a for _, a in record]
    snapshots.clear()

    other, w_other = scrambled(space, w)
    assert not np.allclose(other.theta @ w_other, space.theta @ w)  # the truth did change
    kind = KINDS[feedback]
    monkeypatch.setitem(KINDS, feedback, replace(kind, make_human=lambda *a, **k: Replay(answers)))
    again = []
    run_reward_learning(other, w_other, cfg, (0, 0, 0), record=again)
    assert [s.query for s, _ in again] == [s.query for s, _ in record]
    assert len(snapshots) == len(first) == cfg.queries
    for a, b in zip(first, snapshots):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("feedback, selection", [("language", "infogain"), ("mixed", "infogain")])
def test_the_answer_model_learner_is_blind_to_the_truth(feedback, selection, monkeypatch):
    """What it asks and learns is the same, bit for bit, when the truth is scrambled and the answers replayed."""
    space = toy_latent_space("metaworld", n=30, dim=8, seed=1)
    cfg = LearnRewardConfig(
        feedback=feedback,
        queries=6,
        query_selection=selection,
        candidates=8,
        posterior_samples=16,
        learner="answer-model",
        answer_model=AnswerModelConfig(particles=256),
    )
    w = human_weights(len(space.feature_names), 0, 0)
    record, learners = [], []
    run_reward_learning(space, w, cfg, (0, 0, 0), record=record, learners=learners)
    other, w_other = scrambled(space, w)
    answers = [a for _, a in record]
    for name in ("language", "comparison"):
        mine = [a for a in answers if type(a.query) is KINDS[name].query]
        monkeypatch.setitem(KINDS, name, replace(KINDS[name], make_human=lambda *a, _m=mine, **k: Replay(_m)))
    again, learners_again = [], []
    run_reward_learning(other, w_other, cfg, (0, 0, 0), record=again, learners=learners_again)
    assert [s.query for s, _ in again] == [s.query for s, _ in record]
    np.testing.assert_array_equal(learners[0].v, learners_again[0].v)


@pytest.mark.parametrize("strategy", ["paper", "history"])
def test_improvement_is_blind_to_the_truth(strategy, monkeypatch):
    space = toy_latent_space("metaworld", n=30, dim=8, seed=2)
    cfg = ImproveConfig(iterations=6, seeds=1, strategy=strategy)
    w = human_weights(len(space.feature_names), 0, 0)
    heard = []
    real = improve_module.LanguageHuman

    def recording(*args, **kwargs):
        human = real(*args, **kwargs)
        answer = human.answer

        def keep(query):
            heard.append(answer(query))
            return heard[-1]

        human.answer = keep
        return human

    monkeypatch.setattr(improve_module, "LanguageHuman", recording)
    first = run_improvement(space, w, cfg, (0, 0))
    other, w_other = scrambled(space, w)
    monkeypatch.setattr(improve_module, "LanguageHuman", lambda *a, **k: Replay(heard))
    again = run_improvement(other, w_other, cfg, (0, 0))
    assert again.shown == first.shown and again.feedback == first.feedback
    assert len(set(first.shown)) > 1  # it did move
