"""The Laplace posterior of the linear reward: its mean is the fit, its covariance the inverse of the (scaled)
Hessian of the learner's own loss, checked by finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.feedback import HumanConfig, get_kind, random_query, sample_weights, toy_latent_space
from langpref.reward import RewardConfig, RewardLearner
from langpref.reward.posterior import laplace_posterior, pair_arrays

torch.set_num_threads(1)


def _fitted(kind_name: str, queries: int = 6, seed: int = 0, weight_decay: float = 1.0) -> RewardLearner:
    space = toy_latent_space("metaworld", n=40, seed=seed)
    kind = get_kind(kind_name)
    pool = space.split("train")
    rng = np.random.default_rng(seed)
    cfg = RewardConfig(weight_decay=weight_decay, num_negatives=5, max_iter=500)
    human = kind.make_human(sample_weights(len(space.feature_names), seed), space, pool, HumanConfig(), rng)
    learner = RewardLearner(space.dim, cfg)
    for _ in range(queries):
        learner.add(kind.pairs(space, human.answer(random_query(kind, pool, rng)), cfg, rng))
        learner.fit()
    return learner


def _finite_difference_hessian(learner: RewardLearner, eps: float = 1e-4) -> np.ndarray:
    xi0 = learner.params[0].detach().clone()
    dim = len(xi0)

    def grad(x: torch.Tensor) -> np.ndarray:
        with torch.no_grad():
            learner.params[0].copy_(x)
        learner.params[0].grad = None
        learner.loss().backward()
        return learner.params[0].grad.detach().numpy().copy()

    h = np.zeros((dim, dim))
    for k in range(dim):
        step = torch.zeros(dim, dtype=torch.float64)
        step[k] = eps
        h[:, k] = (grad(xi0 + step) - grad(xi0 - step)) / (2 * eps)
    with torch.no_grad():
        learner.params[0].copy_(xi0)
    return 0.5 * (h + h.T)


@pytest.mark.parametrize("kind", ["language", "comparison"])
def test_laplace_mean_is_the_fit_and_covariance_the_inverse_scaled_hessian(kind):
    learner = _fitted(kind)
    post = laplace_posterior(learner)
    xi = learner.params[0].detach().numpy()
    np.testing.assert_array_equal(post.mean, xi)
    # the fit is a minimum of the loss: its gradient vanishes there
    learner.params[0].grad = None
    learner.loss().backward()
    assert np.linalg.norm(learner.params[0].grad.numpy()) < 1e-6
    _, weights = pair_arrays(learner)
    precision = weights.sum() * _finite_difference_hessian(learner)
    np.testing.assert_allclose(post.precision, precision, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(post.covariance, np.linalg.inv(precision), rtol=1e-4, atol=1e-7)
    # the covariance shrinks with answers: the posterior after 6 answers is tighter than the prior
    assert np.trace(post.covariance) < len(xi) / learner.cfg.weight_decay


def test_prior_alone_before_any_answer_and_samples_follow_the_gaussian():
    learner = RewardLearner(4, RewardConfig(weight_decay=2.0))
    post = laplace_posterior(learner)
    np.testing.assert_array_equal(post.mean, np.zeros(4))
    np.testing.assert_allclose(post.covariance, np.eye(4) / 2.0)
    fitted = laplace_posterior(_fitted("comparison", queries=10))
    draws = fitted.sample(40000, np.random.default_rng(0))
    np.testing.assert_allclose(
        draws.mean(axis=0), fitted.mean, atol=0.05 * np.sqrt(np.diag(fitted.covariance)).max() + 1e-3
    )
    np.testing.assert_allclose(np.cov(draws.T), fitted.covariance, atol=0.05 * np.abs(fitted.covariance).max())


def test_posterior_refuses_the_mlp_and_an_improper_prior():
    with pytest.raises(LangprefError, match="linear"):
        laplace_posterior(RewardLearner(4, RewardConfig(model="mlp")))
    with pytest.raises(LangprefError, match="weight_decay"):
        laplace_posterior(RewardLearner(4, RewardConfig(weight_decay=0.0)))
