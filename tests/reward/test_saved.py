"""The learned reward outside langpref: Gymnasium registration, the per-step wrapper, an RL library training on it."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from tests.factories import require

HORIZON = 40


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A Meta-World checkpoint with a small random trajectory encoder (the reward only reads that part)."""
    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.encoders import step_input_dim
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    task = get_task("metaworld")
    torch.manual_seed(0)
    cfg = ModelConfig(latent_dim=8, traj_hidden=(16, 16), max_length=12)
    info = DataInfo(
        "metaworld",
        list(task.features),
        [asdict(f) for f in task.obs_layout],
        task.obs_dim,
        task.action_dim,
        HORIZON,
        2,
        [0.1, 0.1, 0.1],
        [1.0, 1.0, 1.0],
    )
    dim = step_input_dim(task.obs_dim, task.action_dim, True)
    rng = np.random.default_rng(0)
    model = build_model(cfg, info, rng.normal(size=dim) * 0.1, 0.5 + rng.random(dim))
    return save_model(model, tmp_path_factory.mktemp("ckpt") / "mw", model_cfg=cfg, lang_finetuned=False)


def _learner(kind: str, dim: int = 8):
    from langpref.reward import RewardConfig, RewardLearner

    learner = RewardLearner(dim, RewardConfig(model=kind), seed=1)
    with torch.no_grad():
        for p in learner.params:
            p.copy_(torch.randn(p.shape, generator=torch.Generator().manual_seed(p.numel()), dtype=torch.float64))
    return learner


def test_simulated_tasks_are_gymnasium_envs():
    import gymnasium as gym

    import langpref.tasks.gym  # noqa: F401
    from langpref.tasks import get_task

    env = gym.make("langpref/metaworld-button-press", horizon=5)
    obs, info = env.reset(seed=3)
    assert obs.shape == (get_task("metaworld").obs_dim,) and obs.dtype == np.float32
    for t in range(5):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert r == 0.0 and not term and trunc == (t == 4) and info["features"].shape == (3,)
    again, _ = env.reset(seed=3)
    first, _ = gym.make("langpref/metaworld").reset(seed=3)
    assert np.array_equal(again, first)  # the seed fixes the scene, whatever the id


@pytest.mark.parametrize("kind", ["linear", "mlp"])
def test_per_step_rewards_sum_to_T_r_xi_on_a_real_rollout(checkpoint, tmp_path, kind):
    import gymnasium as gym

    from langpref.model.checkpoint import load_model
    from langpref.reward import load
    from langpref.reward.saved import LearnedReward, save_learned_reward
    from langpref.tasks.metaworld.controller import expert_unit, make_controller

    learner = _learner(kind)
    save_learned_reward(learner, tmp_path, env="metaworld", model=checkpoint, name="x", default=True)
    env = LearnedReward(gym.make("langpref/metaworld-button-press", horizon=HORIZON), tmp_path)
    obs, _ = env.reset(seed=7)
    controller = make_controller(expert_unit(), np.random.default_rng(7))
    inner = env.unwrapped.sim
    observations, actions, rewards, done = [], [], [], False
    while not done:
        action = controller.act(inner, obs, len(actions)).astype(np.float32)
        observations.append(obs)
        actions.append(action)
        obs, r, term, trunc, info = env.step(action)
        rewards.append(r)
        done = term or trunc
    assert len(rewards) == HORIZON
    phi = load_model(checkpoint).encode_trajectories(np.array(observations)[None], np.array(actions)[None])
    r_xi = float(learner.predict(phi.double().numpy())[0])
    assert sum(rewards) == pytest.approx(HORIZON * r_xi, rel=1e-4, abs=1e-4)
    assert info["r_xi"] == pytest.approx(r_xi, rel=1e-4, abs=1e-5)
    # the wrapper pays T times the API's per-step share, step by step
    per_step = load(tmp_path).compute_reward(np.array(observations), np.array(actions))
    np.testing.assert_allclose(rewards, HORIZON * per_step, rtol=1e-6, atol=1e-9)


def test_a_reward_of_another_task_is_refused(checkpoint, tmp_path):
    import gymnasium as gym

    from langpref.errors import LangprefError
    from langpref.reward.saved import LearnedReward, save_learned_reward

    save_learned_reward(_learner("linear"), tmp_path, env="metaworld", model=checkpoint, default=True)
    with pytest.raises(LangprefError, match="langpref/metaworld"):
        LearnedReward(gym.make("CartPole-v1"), tmp_path)
    with pytest.raises(LangprefError, match="needs --model"):
        save_learned_reward(_learner("linear"), tmp_path, env="metaworld", model=None)


def test_learn_reward_refuses_an_unsaveable_reward_before_any_run(tmp_path):
    """--save-reward with the oracle space (no encoder) fails at once, not after the first run."""
    from langpref.errors import LangprefError
    from langpref.reward import LearnRewardConfig, learn_reward

    class NoSpace:  # any use of the space would fail differently: the check must come first
        def __getattr__(self, name):
            raise AssertionError(f"the space was used ({name}) before the check")

    with pytest.raises(LangprefError, match="needs --model"):
        learn_reward(NoSpace(), LearnRewardConfig(), progress=False, save_reward=str(tmp_path), model=None)


def _learned_return(env, policy, seeds) -> np.ndarray:
    """The learned reward summed over one episode of `policy`'s deterministic actions, per reset seed."""
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            action, _ = policy.predict(obs, deterministic=True)
            obs, r, term, trunc, info = env.step(action)
            assert info["env_reward"] == 0.0  # whatever PPO learned, it learned from r_xi
            total, done = total + r, term or trunc
        returns.append(total)
    return np.array(returns)


def test_ppo_from_stable_baselines3_trains_on_the_learned_reward(checkpoint, tmp_path):
    """PPO's policy earns more of the learned reward after 2048 steps than before, on scenes it did not train on
    (about -6.4 to -4.2..-4.7 per 64-step episode over training seeds 0-2)."""
    sb3 = require("stable_baselines3", "pip install 'langpref[test]'")
    import gymnasium as gym

    from langpref.reward.saved import LearnedReward, save_learned_reward

    save_learned_reward(_learner("linear"), tmp_path, env="metaworld", model=checkpoint, default=True)
    env = LearnedReward(gym.make("langpref/metaworld-button-press", horizon=64), tmp_path)
    model = sb3.PPO("MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu", verbose=0)
    unseen = range(100, 104)
    before = _learned_return(env, model, unseen)
    model.learn(total_timesteps=2048)
    after = _learned_return(env, model, unseen)
    assert (after > before).all() and after.mean() > before.mean() + 1.0, (before, after)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(np.asarray(action, dtype=np.float32))


def test_the_answer_model_learner_saves_its_reward_as_the_linear_reward_it_is(checkpoint, tmp_path):
    """Saved, the answer-model learner's posterior-mean reward is xi . phi, equal to its own prediction up to one
    constant for every trajectory."""
    import json

    from langpref.feedback import toy_latent_space
    from langpref.feedback.language import LanguageAnswer, LanguageQuery
    from langpref.reward.answer_model import AnswerModelLearner
    from langpref.reward.saved import save_learned_reward

    space = toy_latent_space("metaworld", n=30, dim=8, seed=2)
    pool = space.split("train")
    learner = AnswerModelLearner(space, pool, seed=0)
    table = space.table("train")
    learner.observe("language", LanguageAnswer(LanguageQuery(int(pool[0])), table.texts[int(table.rows(1, 0)[0])]))
    learner.fit()
    path = save_learned_reward(learner, tmp_path, env="metaworld", model=checkpoint, name="am")
    doc = json.loads(path.read_text())
    assert doc["kind"] == "linear" and doc["reward_config"]["learner"] == "answer-model"
    gap = space.phi @ np.array(doc["params"]["xi"]) - learner.predict(space.phi)
    np.testing.assert_allclose(gap, gap[0], atol=1e-9)
    assert np.ptp(learner.predict(space.phi)) > 0


def _trajectory(seed: int, T: int = 25) -> tuple[np.ndarray, np.ndarray]:
    from langpref.tasks import get_task

    task = get_task("metaworld")
    rng = np.random.default_rng(seed)
    obs = np.cumsum(rng.normal(scale=0.02, size=(T, task.obs_dim)), axis=0).astype(np.float32)
    return obs, rng.uniform(-1, 1, size=(T, task.action_dim)).astype(np.float32)


@pytest.mark.parametrize("kind", ["linear", "mlp"])
def test_the_reward_api_per_step_rewards_sum_to_the_trajectory_reward(checkpoint, tmp_path, kind):
    """`langpref.reward.load(PATH).compute_reward` splits r_xi(tau) into per-step shares that sum to it, and
    r_xi(tau) is what the learner gives the trajectory's phi from the torch model."""
    from langpref.model.checkpoint import load_model
    from langpref.reward import load
    from langpref.reward.saved import save_learned_reward

    learner = _learner(kind)
    path = save_learned_reward(learner, tmp_path, env="metaworld", model=checkpoint, name="x")
    reward = load(path)
    assert (reward.task, reward.kind) == ("metaworld", kind)
    obs, actions = _trajectory(3)
    per_step = reward.compute_reward(obs, actions)
    total = reward.trajectory_reward(obs, actions)
    assert per_step.shape == (len(obs),)
    assert per_step.sum() == pytest.approx(total, rel=1e-9, abs=1e-12)
    phi = load_model(checkpoint).encode_trajectories(obs[None], actions[None])
    assert total == pytest.approx(float(learner.predict(phi.double().numpy())[0]), rel=1e-4, abs=1e-5)
    progress = reward.progress(obs, actions)
    assert progress[-1] == pytest.approx(total) and np.ptp(progress) > 0
    if kind == "linear":  # a function of the step alone: the same step pays the same in another trajectory
        other_obs, other_actions = _trajectory(4)
        other_obs[5], other_obs[6], other_actions[6] = obs[5], obs[6], actions[6]
        assert reward.compute_reward(other_obs, other_actions)[6] == pytest.approx(per_step[6])
    with pytest.raises(LangprefError, match="observations of 39"):
        reward.compute_reward(obs[:, :10], actions)


def test_reward_files_are_versioned(checkpoint, tmp_path):
    """A file of a newer format version is refused in one line; one without a version (the first) is read."""
    import json

    from langpref.reward import load
    from langpref.reward.api import FORMAT_VERSION
    from langpref.reward.saved import save_learned_reward

    path = save_learned_reward(_learner("linear"), tmp_path, env="metaworld", model=checkpoint, name="v")
    doc = json.loads(path.read_text())
    assert doc["format_version"] == FORMAT_VERSION == 1
    obs, actions = _trajectory(5)
    expected = load(path).trajectory_reward(obs, actions)

    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps({**doc, "format_version": FORMAT_VERSION + 1}))
    with pytest.raises(LangprefError) as err:
        load(newer)
    message = str(err.value)
    assert "\n" not in message and f"format version {FORMAT_VERSION + 1}" in message and "upgrade langpref" in message

    unversioned = tmp_path / "unversioned.json"
    unversioned.write_text(json.dumps({k: v for k, v in doc.items() if k != "format_version"}))
    assert load(unversioned).trajectory_reward(obs, actions) == pytest.approx(expected)

    for bad, match in (
        ({**doc, "format_version": "1"}, "invalid reward format version"),
        ({**doc, "format": "something-else"}, "not a langpref reward"),
        ({**doc, "kind": "transformer"}, "does not know"),
        ({k: v for k, v in doc.items() if k != "params"}, "incomplete"),
    ):
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(bad))
        with pytest.raises(LangprefError, match=match):
            load(path)
    with pytest.raises(LangprefError, match="no saved reward"):
        load(tmp_path / "absent.json")


def test_success_prefixes_embed_each_successful_episode_step_by_step(checkpoint, tmp_path, make_synthetic_dataset):
    """The last phi_t of an episode is the model's phi of the whole episode, and the last theta_t its standardised
    features, as the space holds them: value-order reads the same reward the metrics score."""
    from langpref.dataset.storage import load_dataset
    from langpref.feedback.space import _normalised_theta
    from langpref.model.checkpoint import load_model
    from langpref.reward.steps import success_prefixes

    data = make_synthetic_dataset(tmp_path / "ds", n=16, horizon=HORIZON)
    dataset = load_dataset(data)
    rows = [i for i in dataset.split("test") if dataset.success[i]]
    episodes = success_prefixes(data, checkpoint, "test")
    assert rows and len(episodes.phi) == len(episodes.theta) == len(rows)
    obs, actions = dataset.arrays(None)
    phi = load_model(checkpoint).encode_trajectories(obs[rows], actions[rows]).double().numpy()
    np.testing.assert_allclose([p[-1] for p in episodes.phi], phi, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose([t[-1] for t in episodes.theta], _normalised_theta(dataset)[rows], atol=1e-6)
    assert all(p.shape == (HORIZON, phi.shape[1]) for p in episodes.phi)


def test_learn_reward_reports_the_standard_metrics_with_a_model(checkpoint, tmp_path, make_synthetic_dataset, capsys):
    """With a state model and a recording with success labels, learn-reward adds Kendall's tau, EPIC and the
    value-order correlation (of the learned and of the true reward) to its JSON and its text."""
    import json

    from langpref.cli import main

    data = make_synthetic_dataset(tmp_path / "ds", n=16, horizon=HORIZON)
    args = ["learn-reward", "--model", str(checkpoint), "--data", str(data), "--feedback", "language", "--queries", "2"]
    assert main([*args, "--humans", "1", "--seeds", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["kendall_tau"]) == len(out["epic_distance"]) == 3
    assert len(out["value_order_correlation_runs"]) == 2 and "value_order_correlation_true_reward" in out
    assert main([*args, "--humans", "1", "--seeds", "1"]) == 0
    text = capsys.readouterr().out
    assert "Kendall tau" in text and "EPIC distance" in text and "value-order correlation" in text
