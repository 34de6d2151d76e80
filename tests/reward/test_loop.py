"""Reward learning from language (Eq. 5-9) and comparisons: metrics, recovery of w, seeds, CLI, experiments."""

from __future__ import annotations

import json
from dataclasses import asdict, replace

import numpy as np
import pytest
import torch
from scipy.stats import spearmanr

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.feedback import (
    ComparisonAnswer,
    ComparisonQuery,
    HumanConfig,
    LanguageAnswer,
    LanguageHuman,
    LanguageQuery,
    sample_weights,
    toy_latent_space,
)
from langpref.feedback.comparison import comparison_pairs
from langpref.feedback.language import language_pairs, read_meaning
from langpref.reward import (
    LearnRewardConfig,
    RewardConfig,
    RewardLearner,
    cross_entropy,
    learn_reward,
    reward_of_best,
    run_reward_learning,
)
from tests.factories import write_dataset

torch.set_num_threads(1)


def test_cross_entropy_on_hand_built_numbers():
    assert np.isclose(cross_entropy(np.array([0.0, 1.0]), np.zeros(2)), np.log(2))
    # P_w(0 > 1) = sigmoid(-ln 3) = 1/4; with r = R, CE is the entropy H(1/4)
    R = np.array([0.0, np.log(3.0)])
    assert np.isclose(cross_entropy(R, R), -(0.25 * np.log(0.25) + 0.75 * np.log(0.75)))
    # three trajectories: the mean over the 3 unordered pairs
    R3, r3 = np.array([0.0, 1.0, 3.0]), np.array([1.0, 0.0, 0.0])
    sig = lambda z: 1 / (1 + np.exp(-z))  # noqa: E731
    pairs = [(0, 1), (0, 2), (1, 2)]
    manual = np.mean(
        [
            -(
                sig(R3[i] - R3[j]) * np.log(sig(r3[i] - r3[j]))
                + (1 - sig(R3[i] - R3[j])) * np.log(1 - sig(r3[i] - r3[j]))
            )
            for i, j in pairs
        ]
    )
    assert np.isclose(cross_entropy(R3, r3), manual)
    assert np.isclose(
        cross_entropy(R3, r3, rationality=0.0),
        np.mean([-(0.5 * np.log(sig(r3[i] - r3[j])) + 0.5 * np.log(1 - sig(r3[i] - r3[j]))) for i, j in pairs]),
    )
    with pytest.raises(LangprefError):
        cross_entropy(np.zeros(3), np.zeros(2))


def test_reward_of_best_on_hand_built_numbers():
    R = np.array([1.0, 3.0, 2.0])
    assert reward_of_best(R, np.array([0.0, 5.0, 1.0])) == 1.0
    assert reward_of_best(R, np.array([2.0, 0.0, 0.0])) == 0.0
    assert reward_of_best(R, np.array([0.0, 0.0, 1.0])) == 0.5
    assert np.isclose(reward_of_best(R, np.zeros(3)), 0.5)  # ties: the mean of (0, 1, 0.5)


@pytest.fixture(scope="module")
def space():
    return toy_latent_space(n=120, dim=16, seed=0)


def test_language_pairs_read_no_label_and_skip_paraphrases(space):
    table = space.table("test")
    row = 0
    answer = LanguageAnswer(LanguageQuery(int(space.split("train")[0])), table.texts[row])  # no feature/direction
    cfg = RewardConfig(num_negatives=20)
    batch = language_pairs(space, answer, cfg, np.random.default_rng(0))
    assert len(batch.weights) == 21 and np.isclose(batch.weights.sum(), 2.0)
    phi = space.phi[answer.query.shown]
    assert np.allclose(batch.winners, phi + table.psi[row])
    assert np.allclose(batch.losers[0], phi)  # explicit: improvement beats the shown trajectory
    meaning = read_meaning(space, table.psi[row])
    assert meaning == table.group[row]
    pool = space.table("train")
    negatives = batch.losers[1:] - phi
    for neg in negatives:  # no implicit negative shares the meaning of l
        j = int(np.argmin(np.linalg.norm(pool.psi - neg, axis=1)))
        assert pool.group[j] != meaning
    only = language_pairs(space, answer, RewardConfig(loss="explicit"), np.random.default_rng(0))
    assert len(only.weights) == 1
    assert len(language_pairs(space, answer, RewardConfig(loss="implicit"), np.random.default_rng(0)).weights) == 20


def test_linear_reward_with_no_data_is_flat(space):
    learner = RewardLearner(space.dim)
    learner.fit()
    assert np.all(learner.predict(space.phi) == 0.0)


@pytest.mark.parametrize("model", ["linear", "mlp"])
def test_language_feedback_recovers_the_ranking_of_w(space, model):
    w = np.array([0.8, -0.5, 0.33])
    pool = space.split("train")
    human = LanguageHuman(w, space.theta, space.table("test"), pool, space.feature_names, temperature=0.5, seed=0)
    cfg = RewardConfig(model=model)
    learner, rng = RewardLearner(space.dim, cfg, seed=0), np.random.default_rng(1)
    for _ in range(40):
        learner.add(language_pairs(space, human.answer(LanguageQuery(int(rng.choice(pool)))), cfg, rng))
        learner.fit()
    rho = spearmanr(learner.predict(space.phi), space.theta @ w)[0]
    assert rho > (0.9 if model == "linear" else 0.8)


def test_fit_depends_on_relative_pair_weights_only(space):
    """The loss is the weighted mean over pairs: doubling every weight, or repeating all feedback, fits the same
    r_xi, so the L2 prior weighs the same against each loss term whatever the method's pairs per query."""
    rng = np.random.default_rng(0)
    answer = LanguageAnswer(LanguageQuery(int(space.split("train")[0])), space.table("test").texts[0])
    batch = language_pairs(space, answer, RewardConfig(), rng)
    fits = []
    for batches in ([batch], [replace(batch, weights=2 * batch.weights)], [batch, batch]):
        learner = RewardLearner(space.dim)
        for b in batches:
            learner.add(b)
        learner.fit()
        fits.append(learner.predict(space.phi))
    assert np.abs(fits[0]).max() > 0.1
    np.testing.assert_allclose(fits[1], fits[0], atol=1e-6)
    np.testing.assert_allclose(fits[2], fits[0], atol=1e-6)
    stronger = RewardLearner(space.dim, RewardConfig(weight_decay=4.0))
    stronger.add(batch)
    stronger.fit()
    assert np.abs(stronger.predict(space.phi)).max() < 0.5 * np.abs(fits[0]).max()  # a stronger prior, a humbler fit


def test_comparisons_recover_the_ranking_of_w(space):
    w = sample_weights(3, 5)
    pool = space.split("train")
    R = space.theta @ w
    learner, rng = RewardLearner(space.dim, RewardConfig()), np.random.default_rng(0)
    for _ in range(60):
        a, b = (int(i) for i in rng.choice(pool, 2, replace=False))
        learner.add(comparison_pairs(space, ComparisonAnswer(ComparisonQuery(a, b), 0 if R[a] > R[b] else 1)))
    learner.fit()
    assert spearmanr(learner.predict(space.phi), R)[0] > 0.9


def test_language_beats_comparisons_on_a_perfect_space(space):
    res = {
        fb: learn_reward(space, LearnRewardConfig(feedback=fb, queries=15, humans=3, seeds=2), progress=False)
        for fb in ("language", "comparison")
    }
    lang, comp = (np.array(res[fb]["cross_entropy"]) for fb in ("language", "comparison"))
    assert lang[0] == comp[0] == pytest.approx(np.log(2) - 0.0, abs=0.2)  # same flat start
    assert lang[1:].mean() < comp[1:].mean()
    assert res["language"]["auc_true_reward"] > res["comparison"]["auc_true_reward"]
    for r in res.values():
        assert len(r["cross_entropy"]) == len(r["true_reward_of_best"]) == 16


def test_same_seed_same_curves(space):
    cfg = LearnRewardConfig(queries=5)
    w = sample_weights(3, 0)
    a, b = run_reward_learning(space, w, cfg, (0, 0, 0)), run_reward_learning(space, w, cfg, (0, 0, 0))
    assert a.cross_entropy == b.cross_entropy and a.true_reward_of_best == b.true_reward_of_best
    c = run_reward_learning(space, w, cfg, (0, 0, 1))
    assert c.cross_entropy != a.cross_entropy


def test_bad_configs_are_one_line_errors(space):
    for cfg in (
        LearnRewardConfig(feedback="gestures"),
        LearnRewardConfig(queries=0),
        LearnRewardConfig(reward=RewardConfig(loss="neither")),
        LearnRewardConfig(human=HumanConfig(temperature=0.0)),
    ):
        with pytest.raises(LangprefError):
            learn_reward(space, cfg, progress=False)


# ---- command line and experiments, on datasets written to disk ---------------------------------------------------


def test_cli_learn_reward_json(tmp_path, capsys):
    data = write_dataset(tmp_path / "d", env="metaworld", n=24, horizon=8, like_task=True)
    for fb in ("language", "comparison"):
        assert (
            main(
                [
                    "learn-reward",
                    "--data",
                    str(data),
                    "--perfect-latent",
                    "--feedback",
                    fb,
                    "--queries",
                    "4",
                    "--humans",
                    "1",
                    "--seeds",
                    "2",
                    "--json",
                ]
            )
            == 0
        )
        out = json.loads(capsys.readouterr().out)
        assert len(out["cross_entropy"]) == len(out["true_reward_of_best"]) == 5
        assert out["num_runs"] == 2 and out["feedback"] == fb
    assert (
        main(
            [
                "learn-reward",
                "--data",
                str(data),
                "--perfect-latent",
                "--feedback",
                "language",
                "--phrasing-split",
                "val",
                "--num-negatives",
                "0",
                "--json",
            ]
        )
        == 2
    )
    assert "num_negatives" in capsys.readouterr().err


@pytest.fixture(scope="module")
def untrained_model(tmp_path_factory):
    """A real (untrained) checkpoint of a metaworld model: encoders exercised end to end."""
    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    spec = get_task("metaworld")
    info = DataInfo(
        env="metaworld",
        feature_names=list(spec.features),
        obs_layout=[asdict(f) for f in spec.obs_layout],
        obs_dim=spec.obs_dim,
        action_dim=spec.action_dim,
        horizon=8,
        schema_version=1,
        tie_thresholds=[0.0] * len(spec.features),
        feature_std=[1.0] * len(spec.features),
    )
    cfg = ModelConfig(latent_dim=8, max_length=12)
    torch.manual_seed(0)
    model = build_model(cfg, info, None, None)
    return save_model(model, tmp_path_factory.mktemp("m") / "model", model_cfg=cfg, lang_finetuned=False)


def test_cli_with_a_real_model_and_mismatched_env(tmp_path, capsys, untrained_model):
    data = write_dataset(tmp_path / "mw", env="metaworld", n=24, horizon=8, like_task=True)
    assert (
        main(
            [
                "learn-reward",
                "--model",
                str(untrained_model),
                "--data",
                str(data),
                "--feedback",
                "language",
                "--queries",
                "2",
                "--humans",
                "1",
                "--seeds",
                "1",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert len(out["cross_entropy"]) == 3 and "model" in out["space"]
    other = write_dataset(tmp_path / "rs", env="robosuite", n=24, horizon=8, like_task=True)
    for argv in (["learn-reward", "--feedback", "comparison"], ["improve"]):
        assert main([*argv, "--model", str(untrained_model), "--data", str(other), "--seeds", "1"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and "trained on metaworld" in err and err.count("\n") == 1
