"""Active query selection: it asks about what the learner is unsure of, a certain answer is worth nothing, the same
seed gives the same queries, `random` is the old uniform stream, and `lal-infogain` scores as the follow-up's code."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.feedback import LatentSpace, get_kind, phrase_table, random_query, toy_latent_space
from langpref.feedback.bradley_terry import PairBatch
from langpref.feedback.space import perfect_encoder
from langpref.language.bank import load_bank
from langpref.reward import LearnRewardConfig, RewardConfig, RewardLearner, human_weights, run_reward_learning
from langpref.reward.selection import (
    ComparisonActive,
    LalInfoGain,
    LanguageInfoGain,
    binary_mutual_information,
    make_selector,
    mutual_information,
)

torch.set_num_threads(1)


def _hand_built_space() -> LatentSpace:
    """Meta-World's 3 features, phi = (theta, 3), psi = (+-e_f, 0). Trajectory 0 is the best for a reward that
    favours all three features; 1, 2, 3 fall short of it along feature 0, 1, 2 only."""
    bank = load_bank("metaworld")
    names = tuple(bank.features)
    base = perfect_encoder(names, bank)

    def encode(texts):
        return np.concatenate([base(texts), np.zeros((len(texts), 1))], axis=1)

    theta = np.array([[1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, -1.0]])
    phi = np.concatenate([theta, np.full((4, 1), 3.0)], axis=1)
    tables = {s: phrase_table(bank, s, names, encode) for s in ("train", "test")}
    return LatentSpace(
        "metaworld", names, theta, phi, {"train": (0, 1, 2, 3), "test": (0, 1, 2, 3)}, tables, encode=encode
    )


def _sure_of_features_0_and_1() -> RewardLearner:
    """A learner that has seen many comparisons along features 0 and 1 (xi_0, xi_1 large and certain) and none
    along feature 2 (xi_2 at its prior, 0, with the prior's spread: a weak prior, so that it is wide)."""
    learner = RewardLearner(4, RewardConfig(max_iter=500, weight_decay=0.02))
    e = np.eye(4)
    for f, size in ((0, 1.0), (1, 0.3)):
        learner.add(PairBatch(np.tile(size * e[f], (30, 1)), np.zeros((30, 4)), np.ones(30)))
    learner.fit()
    return learner


def test_language_infogain_asks_about_the_uncertain_feature():
    space = _hand_built_space()
    learner = _sure_of_features_0_and_1()
    xi = learner.params[0].detach().numpy()
    assert xi[0] > 1 and xi[1] > 1 and abs(xi[2]) < 1e-6
    selector = LanguageInfoGain(space, space.split("train"), RewardConfig())
    chosen = selector.select(learner, np.random.default_rng(0))
    # 0 and 3 differ along feature 2 only (which is best depends on the sign of xi_2); 1 and 2 fall short of them
    # along a feature the learner is sure of
    assert chosen.query.shown in (0, 3)
    draws = np.random.default_rng(1).standard_normal((256, 4)) * np.array([0.05, 0.05, 1.0, 0.0]) + xi
    scores = selector.scores(draws, np.arange(4))
    assert min(scores[0], scores[3]) > 3 * max(scores[1], scores[2])
    # and the person is expected to talk about feature 2 there
    predictive = selector.answer_probabilities(draws, np.array([chosen.query.shown])).mean(axis=0)[0]
    assert predictive[4:6].sum() > 0.5


def test_comparison_infogain_asks_about_the_uncertain_feature_and_volume_removal_is_its_formula():
    space = _hand_built_space()
    learner = _sure_of_features_0_and_1()
    chosen = ComparisonActive(space, space.split("train"), "infogain").select(learner, np.random.default_rng(0))
    d = space.theta[chosen.query.a] - space.theta[chosen.query.b]
    assert d[0] == 0 and d[1] == 0 and d[2] != 0  # the pair that differs along feature 2 only
    # volume removal: 1 - P(a)^2 - P(b)^2 with P the mean choice probability over the draws (its known weakness:
    # any pair whose mean P is near 1/2 scores high, however little the draws disagree)
    draws = np.random.default_rng(0).standard_normal((8, 4))
    i, j, score = ComparisonActive(space, space.split("train"), "volume-removal").scores(draws, np.arange(4))
    p = (1 / (1 + np.exp(-(space.phi[i] - space.phi[j]) @ draws.T))).mean(axis=1)
    np.testing.assert_allclose(score, 1 - p**2 - (1 - p) ** 2, rtol=1e-5)


def test_information_gain_is_zero_for_a_certain_answer():
    space = _hand_built_space()
    learner = _sure_of_features_0_and_1()
    xi = learner.params[0].detach().numpy()
    # every draw agrees: nothing to learn, whatever is shown
    same = np.tile(xi, (16, 1))
    np.testing.assert_allclose(
        LanguageInfoGain(space, space.split("train"), RewardConfig()).scores(same, np.arange(4)), 0.0, atol=1e-12
    )
    # the draws differ only along feature 2, and the shown trajectory is far short of the best along feature 0
    # alone, with a large xi_0: the person says "increase feature 0" whatever xi_2 is
    far = replace(space, theta=space.theta.copy(), phi=space.phi.copy())
    far.phi[1, 0] = -40.0
    draws = np.tile(xi, (64, 1))
    draws[:, 2] = np.random.default_rng(0).uniform(0.1, 0.3, 64)
    assert LanguageInfoGain(far, far.split("train"), RewardConfig()).scores(draws, np.array([1]))[0] < 1e-9
    # a comparison whose choice is certain under every draw
    assert binary_mutual_information(np.full((1, 64), 1.0 - 1e-9))[0] < 1e-5
    assert mutual_information(np.tile([[[0.2, 0.8]]], (8, 1, 1)))[0] == pytest.approx(0.0, abs=1e-15)
    # and an answer that depends on the draw carries information (log 2 nats at most for two answers)
    assert mutual_information(np.array([[[1.0, 0.0]], [[0.0, 1.0]]]))[0] == pytest.approx(np.log(2))


@pytest.mark.parametrize(
    "feedback,strategy",
    [
        ("language", "infogain"),
        ("language", "lal-infogain"),
        ("comparison", "infogain"),
        ("comparison", "volume-removal"),
    ],
)
def test_same_seed_same_queries(feedback, strategy):
    space = toy_latent_space("metaworld", n=40, seed=2)
    cfg = LearnRewardConfig(
        feedback=feedback,
        queries=5,
        query_selection=strategy,
        candidates=12,
        reward=RewardConfig(num_negatives=5, max_iter=50),
    )
    w = human_weights(len(space.feature_names), 0, 0)
    runs = []
    for seed in ((0, 0, 0), (0, 0, 0), (0, 0, 1)):
        record: list = []
        curves = run_reward_learning(space, w, cfg, seed, record)
        runs.append(([chosen.query for chosen, _ in record], [chosen.score for chosen, _ in record], curves))
    assert runs[0][0] == runs[1][0] and runs[0][1] == runs[1][1]
    assert runs[0][2].cross_entropy == runs[1][2].cross_entropy
    assert runs[0][0] != runs[2][0]
    assert all(s is not None and np.isfinite(s) for s in runs[0][1])


@pytest.mark.parametrize("feedback", ["language", "comparison"])
def test_random_is_the_uniform_stream_of_before(feedback):
    """`random` (and unset) must keep every earlier number: the queries are random_query's on stream 1."""
    space = toy_latent_space("metaworld", n=30, seed=1)
    kind = get_kind(feedback)
    w = human_weights(len(space.feature_names), 0, 1)
    expected_rng = np.random.default_rng([3, 1, 2, 1])
    expected = [random_query(kind, space.split("train"), expected_rng) for _ in range(4)]
    for selection in (None, "random"):
        record: list = []
        cfg = LearnRewardConfig(
            feedback=feedback, queries=4, query_selection=selection, reward=RewardConfig(num_negatives=3, max_iter=20)
        )
        run_reward_learning(space, w, cfg, (3, 1, 2), record)
        assert [chosen.query for chosen, _ in record] == expected
        assert all(chosen.score is None for chosen, _ in record)


def test_lal_infogain_scores_as_the_follow_up_info_function():
    """Our log-domain scores equal the follow-up's `info` (lal/active_learning/info.py) computed as it does."""
    space = toy_latent_space("metaworld", n=30, dim=8, seed=0)
    sel = LalInfoGain(space, space.split("train"))
    rng = np.random.default_rng(0)
    w, l_samples = sel.samples(rng)
    rows = space.split("train")
    ours = sel.scores(w, l_samples, rows)
    m, mk = len(w), len(l_samples)
    traj = space.phi[rows]
    embed_diff = (w[:, None, :] - traj[None, :, :]).reshape(m * len(rows), -1)
    probs = np.exp(embed_diff @ l_samples.T).reshape(m, len(rows), -1).transpose(1, 0, 2)
    probs /= probs.sum(axis=-1, keepdims=True)
    tmp = m * probs / probs.sum(axis=1, keepdims=True)
    theirs = np.log2(tmp).sum(axis=2).sum(axis=1) / mk
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-9)


def test_lal_infogain_never_shows_a_trajectory_twice_while_fresh_ones_remain():
    space = toy_latent_space("metaworld", n=40, seed=3)
    cfg = LearnRewardConfig(
        queries=8, query_selection="lal-infogain", reward=RewardConfig(num_negatives=3, max_iter=20)
    )
    record: list = []
    run_reward_learning(space, human_weights(3, 0, 0), cfg, (0, 0, 0), record)
    shown = [chosen.query.shown for chosen, _ in record]
    assert len(set(shown)) == len(shown)


def test_strategies_are_checked_against_the_kind_and_the_reward_model():
    space = toy_latent_space("metaworld", n=20)
    with pytest.raises(LangprefError, match="volume-removal"):
        LearnRewardConfig(feedback="language", query_selection="volume-removal").validate()
    with pytest.raises(LangprefError, match="lal-infogain"):
        LearnRewardConfig(feedback="comparison", query_selection="lal-infogain").validate()
    with pytest.raises(LangprefError, match="unknown query selection"):
        LearnRewardConfig(query_selection="bald").validate()
    with pytest.raises(LangprefError, match="linear"):
        LearnRewardConfig(query_selection="infogain", reward=RewardConfig(model="mlp")).validate()
    with pytest.raises(LangprefError, match="candidates"):
        LearnRewardConfig(query_selection="infogain", candidates=1).validate()
    assert make_selector("random", get_kind("language"), space, space.split("train"), RewardConfig()) is None
