"""The standard reward metrics: Kendall's tau, EPIC distance, value-order correlation, on hand-computed cases and as the
learn-reward loop records them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats  # a core dependency: never skipped

from langpref.errors import LangprefError
from langpref.feedback import toy_latent_space
from langpref.feedback.humans import true_reward
from langpref.reward import LearnRewardConfig, human_weights, learn_reward, run_reward_learning
from langpref.reward.metrics import epic_distance, kendall_tau, ranks, spearman, value_order_correlation
from langpref.reward.steps import SuccessEpisodes


def test_kendall_tau_on_hand_computed_cases_with_ties():
    # every pair concordant except one tied in the learned reward: tau-b = 5 / sqrt(6 * 5)
    assert kendall_tau([1, 2, 3, 4], [1, 1, 2, 3]) == pytest.approx(5 / np.sqrt(30))
    # (0,1) and (0,2) discordant, (1,2) concordant
    assert kendall_tau([1, 2, 3], [3, 1, 2]) == pytest.approx(-1 / 3)
    # ties on both sides: one concordant pair of the two untied on each side
    assert kendall_tau([1, 1, 2], [1, 2, 2]) == pytest.approx(0.5)
    assert kendall_tau([1, 2, 3], [30, 20, 10]) == pytest.approx(-1.0)
    assert kendall_tau([1, 2, 3], [5, 5, 5]) == 0.0  # a constant reward ranks nothing


def test_kendall_tau_is_scipys_tau_b():
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 6, 40).astype(float), rng.integers(0, 6, 40).astype(float)  # many ties
    assert kendall_tau(a, b) == pytest.approx(stats.kendalltau(a, b).statistic)


def test_epic_distance_on_hand_computed_cases():
    R = np.array([0.0, 1.0, 2.0, 5.0, -1.0])
    assert epic_distance(R, 3.0 * R + 7.0) == pytest.approx(0.0, abs=1e-7)  # a positive affine map: the same reward
    assert epic_distance(R, -R) == pytest.approx(1.0)
    assert epic_distance(R, -0.5 * R + 2.0) == pytest.approx(1.0)
    # centred (-1, 0, 1) and (-1, 1, 0): rho = 1 / 2, distance sqrt((1 - 1/2) / 2) = 1/2
    assert epic_distance([0, 1, 2], [0, 2, 1]) == pytest.approx(0.5)
    assert epic_distance(R, np.full(5, 2.0)) == pytest.approx(np.sqrt(0.5))  # constant: uncorrelated
    with pytest.raises(LangprefError):
        epic_distance([1.0, 2.0], [1.0, 2.0, 3.0])


def test_value_order_correlation_on_hand_computed_cases():
    assert value_order_correlation([np.array([1.0, 2.0, 3.0])]) == pytest.approx(1.0)
    assert value_order_correlation([np.array([3.0, 2.0, 1.0])]) == pytest.approx(-1.0)
    # d = (0, 1, -1, 0): 1 - 6 * 2 / (4 * 15) = 0.8; averaged with a rising episode
    assert value_order_correlation([np.array([1.0, 2.0, 3.0]), np.array([1.0, 3.0, 2.0, 4.0])]) == pytest.approx(0.9)
    # ties take their mean rank: ranks (1.5, 1.5, 3) against (1, 2, 3) give 1.5 / sqrt(1.5 * 2)
    assert value_order_correlation([np.array([1.0, 1.0, 2.0])]) == pytest.approx(1.5 / np.sqrt(3.0))
    assert np.isnan(value_order_correlation([np.array([1.0])]))
    np.testing.assert_array_equal(ranks([10, 30, 20, 20]), [1, 4, 2.5, 2.5])


def test_spearman_is_scipys():
    rng = np.random.default_rng(1)
    a, b = rng.integers(0, 5, 30), rng.normal(size=30)
    assert spearman(a, b) == pytest.approx(stats.spearmanr(a, b).statistic)


@pytest.fixture(scope="module")
def space():
    return toy_latent_space("metaworld", n=40, dim=8, seed=3)


def test_the_loop_records_the_metrics_of_the_learned_reward(space):
    """After every query the curves hold Kendall's tau on the eval split and EPIC over the whole dataset; the last
    values are those of the final learner computed directly."""
    cfg = LearnRewardConfig(feedback="language", queries=6, humans=1, seeds=1)
    w = human_weights(len(space.feature_names), cfg.seed, 0)
    learners: list = []
    curves = run_reward_learning(space, w, cfg, (0, 0, 0), learners=learners)
    assert len(curves.kendall_tau) == len(curves.epic_distance) == cfg.queries + 1
    assert curves.kendall_tau[0] == 0.0 and curves.epic_distance[0] == pytest.approx(np.sqrt(0.5))  # r_xi = 0
    rows = space.split(cfg.eval_split)
    learned = learners[0].predict(space.phi)
    assert curves.kendall_tau[-1] == pytest.approx(kendall_tau(true_reward(w, space.theta[rows]), learned[rows]))
    assert curves.epic_distance[-1] == pytest.approx(epic_distance(true_reward(w, space.theta), learned))
    assert curves.kendall_tau[-1] > 0.3 and curves.epic_distance[-1] < 0.5  # language taught it something
    assert curves.value_order is None


def test_value_order_is_scored_on_given_successful_episodes(space):
    """An episode whose prefix embedding walks from the learned reward's worst trajectory to its best rises all the
    way (value-order 1); walked backwards it falls (-1)."""
    cfg = LearnRewardConfig(feedback="comparison", queries=5, humans=1, seeds=1)
    w = human_weights(len(space.feature_names), cfg.seed, 0)
    learners: list = []
    run_reward_learning(space, w, cfg, (0, 0, 1), learners=learners)
    r = learners[0].predict(space.phi)
    walk = np.linspace(space.phi[np.argmin(r)], space.phi[np.argmax(r)], 12)
    rising = np.linspace(-w, w, 12)  # theta_t moving along w: the true reward rises
    again = run_reward_learning(space, w, cfg, (0, 0, 1), episodes=SuccessEpisodes([walk], [rising]))
    assert again.value_order == pytest.approx(1.0) and again.value_order_true == pytest.approx(1.0)
    both = SuccessEpisodes([walk, walk[::-1]], [rising, rising])
    again = run_reward_learning(space, w, cfg, (0, 0, 1), episodes=both)
    assert again.value_order == pytest.approx(0.0, abs=1e-12) and again.value_order_true == pytest.approx(1.0)


def test_learn_reward_json_carries_the_metrics(space):
    cfg = LearnRewardConfig(feedback="language", queries=3, humans=2, seeds=1)
    episodes = SuccessEpisodes([space.phi[:5]], [space.theta[:5]])
    out = learn_reward(space, cfg, progress=False, episodes=episodes)
    for name in ("kendall_tau", "epic_distance"):
        assert len(out[name]) == len(out[f"{name}_std"]) == cfg.queries + 1
    assert len(out["value_order_correlation_runs"]) == 2
    assert out["value_order_correlation"] == pytest.approx(np.mean(out["value_order_correlation_runs"]))
    # the true reward's value order through the episode, for each run's human (humans 0 and 1, one seed each)
    truth = [
        value_order_correlation([true_reward(human_weights(len(space.feature_names), cfg.seed, h), space.theta[:5])])
        for h in range(2)
    ]
    assert truth[0] != truth[1]  # the two humans' orders differ, so a mix-up would show
    assert out["value_order_correlation_true_reward"] == pytest.approx(np.mean(truth))
