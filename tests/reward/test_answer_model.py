"""The answer-model learner: it reads what was shown, its belief contracts, it asks under its own model, and the
paper's learner is untouched by it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from langpref.errors import LangprefError
from langpref.feedback import KINDS, toy_latent_space
from langpref.feedback.comparison import ComparisonAnswer, ComparisonQuery
from langpref.feedback.humans import HumanConfig
from langpref.feedback.language import LanguageAnswer, LanguageQuery
from langpref.language.bank import NO_CHANGE_FEEDBACK
from langpref.reward import LearnRewardConfig, learn_reward
from langpref.reward.answer_model import AnswerModelConfig, AnswerModelInfoGain, AnswerModelLearner
from langpref.reward.cost import query_costs


@pytest.fixture(scope="module")
def space():
    return toy_latent_space("metaworld", n=40, dim=8, seed=3)


def learner_of(space, seed=0, **cfg):
    return AnswerModelLearner(space, space.split("train"), AnswerModelConfig(**cfg), seed=seed)


def speed_up(space):
    return space.table("train").texts[int(space.table("train").rows(1, 0)[0])]  # a `speed/increase` phrasing


def test_the_same_sentence_about_two_trajectories_teaches_two_things(space):
    """'Faster' said about the slowest trajectory is strong evidence that speed matters; said about the fastest, where
    the person could not have meant "toward the best along speed", it is weak (Eq. 10's human rarely says it)."""
    pool = space.split("train")
    speed = space.theta[pool, 1]
    fast, slow = int(pool[np.argmax(speed)]), int(pool[np.argmin(speed)])
    text = speed_up(space)
    means = []
    for shown in (fast, slow):
        learner = learner_of(space)
        learner.observe("language", LanguageAnswer(LanguageQuery(shown), text))
        learner.fit()
        means.append(learner.mean())
    assert not np.allclose(means[0], means[1], atol=1e-2)
    scale = AnswerModelConfig().prior_scale  # the belief's weights are in units of the prior's spread
    assert means[1][1] > means[0][1] + 0.3 * scale and means[1][1] > 0.5 * scale


def test_no_change_says_the_shown_trajectory_is_nearly_the_best(space):
    """ "That's good, no change" about a trajectory moves the belief toward rewards under which it is the best, and
    the paper's learner, which compares imagined improvements, learns nothing from it (no pairs, no failure)."""
    pool = space.split("train")
    learner = learner_of(space)
    position = int(np.argmin(learner.predict(space.phi[pool])))  # the worst under the prior's mean
    good = LanguageAnswer(LanguageQuery(int(pool[position])), NO_CHANGE_FEEDBACK)
    learner.observe("language", good)
    learner.fit()
    after = learner.predict(space.phi[pool])
    assert np.mean(after < after[position]) > 0.8  # it now beats most of the pool
    paper = KINDS["language"].pairs(space, good, LearnRewardConfig().reward, np.random.default_rng(0))
    assert len(paper.weights) == 0


def test_a_human_who_says_no_change_is_learned_from_by_both_learners(space):
    cfg = LearnRewardConfig(
        feedback="language",
        queries=12,
        humans=2,
        seeds=1,
        human=HumanConfig(phrasing_split="train", no_change_logit=2.0),
    )
    for learner in ("paper", "answer-model"):
        out = learn_reward(space, replace(cfg, learner=learner))
        assert np.isfinite(out["cross_entropy"]).all() and 0 < out["no_change_share"] < 1
        assert out["true_reward_of_best"][-1] > out["true_reward_of_best"][0]
    assert out["config"]["human"]["no_change_logit"] == 2.0
    assert "no_change_share" not in learn_reward(space, replace(cfg, human=HumanConfig(phrasing_split="train")))


def test_the_belief_contracts_as_answers_arrive(space):
    pool = space.split("train")
    w = np.array([0.3, 0.9, -0.3])
    w /= np.linalg.norm(w)
    learner = learner_of(space, seed=1)
    human = KINDS["language"].make_human(w, space, pool, HumanConfig(phrasing_split="train"), np.random.default_rng(0))
    rng = np.random.default_rng(2)

    def spread():
        u = learner.v / np.linalg.norm(learner.v, axis=1, keepdims=True)
        return float(np.trace(np.cov(u.T, aweights=learner.weights())))

    spreads = [spread()]
    for _ in range(30):
        learner.observe("language", human.answer(LanguageQuery(int(rng.choice(pool)))))
        learner.fit()
        spreads.append(spread())
    assert spreads[10] < 0.6 * spreads[0] and spreads[30] < spreads[10]
    assert np.dot(learner.mean() / np.linalg.norm(learner.mean()), w) > 0.8


def test_comparisons_enter_the_same_belief(space):
    pool = space.split("train")
    learner = learner_of(space)
    before = learner.mean().copy()
    r = space.theta[pool] @ np.array([1.0, 0.0, 0.0])
    for k in range(10):
        a, b = int(pool[k]), int(pool[k + 10])
        choice = 0 if r[k] > r[k + 10] else 1
        learner.observe("comparison", ComparisonAnswer(ComparisonQuery(a, b), choice))
    learner.fit()
    assert learner.mean()[0] > before[0] + 0.3
    with pytest.raises(LangprefError, match="takes language and comparison feedback, not 'rating'"):
        learner.observe("rating", object())


def test_mixed_scores_both_kinds_in_the_same_unit(space):
    """A mixed selection's language and comparison scores are each kind's own scores on the same draws (nats),
    divided only by the kind's modelled seconds."""
    pool = space.split("train")
    learner = learner_of(space)
    learner.observe("language", LanguageAnswer(LanguageQuery(int(pool[0])), speed_up(space)))
    learner.fit()
    costs = query_costs()
    scored = {}
    for kinds in (("language",), ("comparison",), ("language", "comparison")):
        selector = AnswerModelInfoGain(space, pool, kinds, costs, candidates=12, samples=32)
        scored[kinds] = selector.score(learner, np.random.default_rng(5))
    both = scored[("language", "comparison")]
    lang = both.kind == both.kinds.index("language")
    np.testing.assert_allclose(both.gains[lang], scored[("language",)].gains)
    np.testing.assert_allclose(both.gains[~lang], scored[("comparison",)].gains)
    np.testing.assert_allclose(both.rates[lang], both.gains[lang] / costs["language"])
    assert (both.gains >= 0).all() and both.gains.max() > 0


def test_queries_inform_less_once_the_belief_is_sure(space):
    """The information a query is expected to give falls as the belief contracts (nothing is worth asking twice
    once its answer is predictable)."""
    pool = space.split("train")
    w = np.array([0.0, 1.0, 0.0])
    learner = learner_of(space, seed=4)
    human = KINDS["language"].make_human(w, space, pool, HumanConfig(phrasing_split="train"), np.random.default_rng(1))
    selector = AnswerModelInfoGain(space, pool, ("language",), samples=64)
    before = selector.score(learner, np.random.default_rng(0)).gains
    for shown in pool[:25]:
        learner.observe("language", human.answer(LanguageQuery(int(shown))))
    learner.fit()
    after = selector.score(learner, np.random.default_rng(0)).gains
    assert after.mean() < 0.5 * before.mean()


def test_the_paper_learner_output_has_no_answer_model_fields(space):
    """`--learner paper` writes the config as before the answer-model learner existed (its numbers are pinned by
    the golden file of test_loop.py); the answer-model learner records its own settings."""
    cfg = LearnRewardConfig(feedback="language", queries=3, humans=1, seeds=1)
    paper = learn_reward(space, cfg, progress=False)
    assert "learner" not in paper["config"] and "answer_model" not in paper["config"]
    assert paper == learn_reward(space, replace(cfg, learner="paper"), progress=False)
    ours = learn_reward(space, replace(cfg, learner="answer-model"), progress=False)
    assert ours["config"]["learner"] == "answer-model" and ours["config"]["answer_model"]["particles"] == 2048
    json.dumps(ours)


def test_bad_answer_model_settings_are_one_line_errors():
    for cfg, says in (
        (LearnRewardConfig(learner="bayes"), "unknown learner 'bayes'"),
        (
            LearnRewardConfig(learner="answer-model", query_selection="lal-infogain"),
            "asks with random or infogain queries, not 'lal-infogain'",
        ),
        (LearnRewardConfig(learner="answer-model", answer_model=AnswerModelConfig(lapse=1.5)), r"lapse in \[0, 1\)"),
    ):
        with pytest.raises(LangprefError, match=says) as err:
            cfg.validate()
        assert "\n" not in str(err.value)


ADDED_SINCE_GOLDEN = {"kendall_tau", "kendall_tau_std", "epic_distance", "epic_distance_std"}
"""Keys the learn-reward JSON gained after the golden file was written (the standard reward metrics)."""


def test_the_paper_learner_reproduces_its_output_byte_for_byte():
    """The JSON of four paper-learner runs, written by the code before the reward/ package and the answer-model
    learner existed (tests/fixtures/learn_reward_paper_golden.json), is what the learner writes today: every key
    of the golden file byte for byte, beside only the keys added since (`ADDED_SINCE_GOLDEN`). Its language runs
    were written again on 2026-12-03, when two held-out phrasings left Meta-World's train bank (the human and the
    implicit negatives draw from it); the comparison run, which reads no bank, was unchanged byte for byte."""
    from pathlib import Path

    golden = json.loads((Path(__file__).parents[1] / "fixtures" / "learn_reward_paper_golden.json").read_text())
    space = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    for fb, sel in (("language", None), ("language", "infogain"), ("comparison", "infogain"), ("mixed", None)):
        cfg = LearnRewardConfig(
            feedback=fb, query_selection=sel, queries=5, humans=2, seeds=1, candidates=10, posterior_samples=16
        )
        out = learn_reward(space, cfg, progress=False)
        before = json.loads(golden[f"{fb}-{sel}"])
        assert json.dumps({k: out[k] for k in before if k in out}, sort_keys=True) == golden[f"{fb}-{sel}"]
        assert set(out) - set(before) == ADDED_SINCE_GOLDEN
