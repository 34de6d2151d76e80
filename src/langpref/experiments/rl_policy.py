"""One policy of `langpref experiment rl`: the reward it is trained on, its training with Stable-Baselines3, and its
evaluation by the synthetic human's true reward and the task's success.

Reward sources (`SOURCES`), each a Gymnasium wrapper around the task's env (whose own reward is 0 every step):

    language, comparison   the reward learned from Q answers of that kind (`langpref.reward.saved.LearnedReward`,
                           which pays T r_t at step t, an episode of T steps returning T r_xi(tau))
    true                   the synthetic human's R = w . theta, paid the same way: w . (f_t - mu) / sd at step t
                           (f_t the step's features, mu and sd the dataset's train split's), summing to T R(tau)
    success                the task's sparse success: 1 at every step the task counts as solved, else 0

With `normalise`, the learned and true rewards are divided by the std of their trajectory reward over the dataset,
so every source reaches the learner at a similar scale (a positive factor leaves the optimal policy unchanged).

Evaluation (`evaluate`): deterministic rollouts of the policy from fixed scenes, the same scenes for every run, each
scored by the true reward of its normalised features (0 = the test split's worst trajectory, 1 its best, as the
reward experiments' `true_reward_of_best`) and by success at its last step. The policy is never shown either.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError

LEARNED = ("language", "comparison")
SOURCES = (*LEARNED, "true", "success")
"""Every reward a policy may be trained on (the order of the figure and the tables)."""
EVAL_SEED = 1_000_003
"""Scene seed of the first evaluation episode (episode k uses EVAL_SEED + k): far from the training scenes' draws."""


@dataclass(frozen=True)
class Judge:
    """What the experimenter scores a rollout with: the human's weights, the dataset's feature scale, and the
    test split's range of true rewards (for the 0..1 scale). Never given to a policy."""

    w: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    low: float
    high: float

    def theta(self, step_features: np.ndarray) -> np.ndarray:
        """Normalised trajectory features of a rollout's (T, F) per-step features (their mean, standardised)."""
        return (np.asarray(step_features, dtype=np.float64).mean(axis=0) - self.mean) / self.std

    def true_reward(self, step_features: np.ndarray) -> float:
        """R(tau) = w . theta(tau) on the 0..1 scale of the test split (may leave it either side)."""
        raw = float(self.w @ self.theta(step_features))
        return (raw - self.low) / max(self.high - self.low, 1e-12)


@dataclass(frozen=True)
class PolicyJob:
    """One run: a reward source for one human and seed, with everything a worker process needs."""

    name: str
    task: str
    source: str
    human: int
    seed: int
    judge: Judge
    scale: float
    """The reward paid is divided by this (1.0 without normalisation)."""
    reward_path: str | None = None
    """The saved learned reward (learned sources only)."""


def _gym():
    import gymnasium

    import langpref.tasks.gym  # noqa: F401  (registers langpref/...)

    return gymnasium


def env_id(task: str) -> str:
    """The Gymnasium id of a task (`langpref.tasks.gym`)."""
    from langpref.tasks.gym import NAMES

    return NAMES.get(task, f"langpref/{task}")


class _Scaled(_gym().Wrapper):
    """Divides the wrapped env's reward by a positive constant."""

    def __init__(self, env, scale: float):
        super().__init__(env)
        self.scale = float(scale)

    def step(self, action):
        obs, r, terminated, truncated, info = self.env.step(action)
        return obs, float(r) / self.scale, terminated, truncated, info


class TrueReward(_gym().Wrapper):
    """Pays the synthetic human's true reward per step, w . (f_t - mu) / sd (an episode of T steps returns
    T R(tau)); the env's own reward goes to `info["env_reward"]`."""

    def __init__(self, env, judge: Judge):
        super().__init__(env)
        self.judge = judge

    def step(self, action):
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        f = (np.asarray(info["features"], dtype=np.float64) - self.judge.mean) / self.judge.std
        return obs, float(self.judge.w @ f), terminated, truncated, {**info, "env_reward": env_reward}


class SuccessReward(_gym().Wrapper):
    """Pays 1 at every step the task counts as solved, else 0 (the sparse task reward)."""

    def step(self, action):
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        return obs, float(bool(info["success"])), terminated, truncated, {**info, "env_reward": env_reward}


def make_env(job: PolicyJob, horizon: int):
    """The task's env of `horizon` steps paying `job`'s reward source (what the policy trains on)."""
    from langpref.reward.saved import LearnedReward

    env = _gym().make(env_id(job.task), horizon=horizon)
    if job.source in LEARNED:
        if job.reward_path is None:
            raise LangprefError(f"run {job.name}: a learned reward source needs its saved reward")
        env = LearnedReward(env, job.reward_path)
    elif job.source == "true":
        env = TrueReward(env, job.judge)
    elif job.source == "success":
        env = SuccessReward(env)
    else:
        raise LangprefError(f"unknown reward source {job.source!r}: choose from {', '.join(SOURCES)}")
    return env if job.scale == 1.0 else _Scaled(env, job.scale)


def import_sb3():
    """stable_baselines3, or a one-line error saying how to install it (it comes with the `test` extra)."""
    from langpref.extras import MissingExtra, message

    try:
        import stable_baselines3
    except ModuleNotFoundError:
        raise MissingExtra(message("test", "langpref experiment rl", "stable_baselines3")) from None
    return stable_baselines3


def make_agent(algorithm: str, env, cfg, seed: int):
    """A Stable-Baselines3 SAC or PPO agent on `env`, sized by the experiment's config `cfg` (`RLConfig`)."""
    sb3 = import_sb3()
    kw: dict[str, Any] = {"seed": seed, "device": "cpu", "verbose": 0, "policy_kwargs": {"net_arch": list(cfg.hidden)}}
    if algorithm == "sac":
        return sb3.SAC("MlpPolicy", env, learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, **kw)
    if algorithm == "ppo":
        n_steps = max(2, min(2048, cfg.steps))  # a tiny budget is not overrun by one default-sized rollout
        return sb3.PPO("MlpPolicy", env, n_steps=n_steps, batch_size=min(cfg.batch_size, n_steps), **kw)
    raise LangprefError(f"unknown algorithm {algorithm!r}: choose sac or ppo")


def evaluate(policy, job: PolicyJob, horizon: int, episodes: int, env=None) -> dict[str, Any]:
    """Deterministic rollouts of `policy` (anything with SB3's `predict`) from scenes EVAL_SEED + k: the mean true
    reward (0..1 scale of the test split), the success rate, and for a learned source the mean learned reward
    r_xi(tau) of the rollouts (what the policy was trained to raise)."""
    env = env or _gym().make(env_id(job.task), horizon=horizon)
    learned = _load_reward(job.reward_path) if job.source in LEARNED else None
    true, success, own = [], [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + k)
        observations, actions, features, done, info = [], [], [], False, {}
        while not done:
            action, _ = policy.predict(obs, deterministic=True)
            action = np.asarray(action, dtype=np.float32)
            observations.append(obs)
            actions.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            features.append(info["features"])
            done = terminated or truncated
        true.append(job.judge.true_reward(np.array(features)))
        success.append(float(bool(info.get("success", False))))
        if learned is not None:
            own.append(learned.trajectory_reward(np.array(observations), np.array(actions)))
    out = {"true_reward": float(np.mean(true)), "success": float(np.mean(success))}
    if own:
        out["own_reward"] = float(np.mean(own))
    return out


_REWARDS: dict[str, Any] = {}


def _load_reward(path: str):
    """A saved reward, loaded once per process."""
    from langpref.reward import load

    if path not in _REWARDS:
        _REWARDS[path] = load(path)
    return _REWARDS[path]


def _curve_callback(job: PolicyJob, cfg, curve: dict[str, list]):
    """An SB3 callback that evaluates the policy every `cfg.eval_every` steps (and before the first) into `curve`."""
    from stable_baselines3.common.callbacks import BaseCallback

    env = _gym().make(env_id(job.task), horizon=cfg.horizon)

    class EvalCurve(BaseCallback):
        def _record(self) -> None:
            res = evaluate(self.model, job, cfg.horizon, cfg.eval_episodes, env)
            curve["steps"].append(int(self.num_timesteps))
            for key, value in res.items():
                curve.setdefault(key, []).append(value)

        def _on_training_start(self) -> None:
            self._record()

        def _on_step(self) -> bool:
            if self.num_timesteps % cfg.eval_every == 0 or self.num_timesteps == cfg.steps:
                self._record()
            return True

    return EvalCurve()


def train_policy(job: PolicyJob, cfg, callbacks: tuple = ()) -> dict[str, Any]:
    """Train `cfg.algorithm` on `job`'s reward for `cfg.steps` steps of `cfg.horizon`-step episodes; its learning
    curve (evaluated every `cfg.eval_every` steps), the final evaluation, and the wall time. `callbacks` (SB3
    callbacks) join the evaluation's, e.g. to record what the agent received."""
    import torch

    torch.set_num_threads(cfg.threads)
    t0 = time.perf_counter()
    env = make_env(job, cfg.horizon)
    agent = make_agent(cfg.algorithm, env, cfg, job.seed)
    curve: dict[str, list] = {"steps": []}
    agent.learn(total_timesteps=cfg.steps, callback=[_curve_callback(job, cfg, curve), *callbacks])
    final = {k: v[-1] for k, v in curve.items() if k != "steps"}
    env.close()
    return {
        "source": job.source,
        "human": job.human,
        "seed": job.seed,
        "scale": job.scale,
        "curve": curve,
        "final": final,
        "wall_s": time.perf_counter() - t0,
    }


def policy_job(_state: Any, payload: tuple[PolicyJob, Any]) -> tuple[str, dict[str, Any]]:
    """A sweep job (`langpref.experiments.common.run_sweep`): (the run's name, its result)."""
    job, cfg = payload
    return job.name, train_policy(job, cfg)
