"""The learned reward r_xi saved for outside tools (`langpref learn-reward --save-reward DIR`), and a Gymnasium wrapper
any RL library can train on.

    import gymnasium as gym
    from langpref.reward.saved import LearnedReward
    env = LearnedReward(gym.make("langpref/metaworld-button-press"), "DIR")   # DIR/reward.json, or a reward file

The file format, loading and the per-step reward are `langpref.reward.api` (`langpref.reward.load`). The wrapper pays,
at step t, t r_xi(phi_t) - (t - 1) r_xi(phi_{t-1}) (phi_t the running mean of the per-step embeddings), which
telescopes: an episode of T steps returns T r_xi(tau), T times `Reward.compute_reward`'s share at every step (the
wrapper cannot divide by a T it does not know until the episode ends). For the linear r_xi = xi . phi this is
xi . e_t, a function of the step alone (Markov in the observation and the previous one); for the `mlp` r_xi it
depends on the history through phi_t: a dense, exact shaping of T r_xi(tau), not a Markov reward of the step.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.reward.api import DEFAULT_NAME, FORMAT, FORMAT_VERSION, Reward, load


def check_saveable(model: str | Path | None) -> dict:
    """The checkpoint config of `model` if its r_xi can be saved (checked before any run, not after the first);
    a `LangprefError` if there is no trajectory encoder (the oracle space) or it sees camera frames."""
    from langpref.model.checkpoint import read_config

    if model is None:
        raise LangprefError(
            "--save-reward needs --model: a saved reward reads phi from a trained trajectory encoder "
            "(the oracle --perfect-latent space has none)"
        )
    cfg = read_config(Path(model).resolve())
    seen = cfg["model"].get("observations") or "state"  # None or absent: a state model
    if seen != "state":
        raise LangprefError(
            f"--save-reward: the model in {Path(model).resolve()} sees camera frames ({seen}); the Gymnasium "
            "wrapper rebuilds phi from the state alone, so only a state model's reward can be saved"
        )
    return cfg


def write_reward(
    out: str | Path,
    name: str,
    *,
    kind: str,
    params: dict[str, list],
    reward_config: dict[str, Any],
    env: str,
    model: str | Path,
    queries: int,
    wants: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
    default: bool = False,
) -> Path:
    """Write a reward r_xi of `kind` with `params` as OUT/reward-NAME.json (and as OUT/reward.json when `default`).
    The model is referred to by its path relative to OUT (so that the two move together) beside its absolute path
    and the checksum of its weights; `wants` is what the reward wants in the task's features
    (`langpref.reward.wants`); `extra` adds fields (where the answers came from)."""
    from langpref import __version__
    from langpref.model.checkpoint import WEIGHTS

    cfg = check_saveable(model)
    model = Path(model).resolve()
    out = Path(out)
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "written_by": f"langpref {__version__}",
        "task": env,
        "kind": kind,
        "params": params,
        "model": {
            "path": str(model),
            "relative": os.path.relpath(model, out.resolve()),
            "sha256": cfg["files"][WEIGHTS]["sha256"],
        },
        "normalisation": cfg.get("normalisation", {}),
        "observation_deltas": bool(cfg["model"].get("observation_deltas", False)),
        "obs_dim": cfg["data"]["obs_dim"],
        "action_dim": cfg["data"]["action_dim"],
        "dataset_horizon": cfg["data"]["horizon"],
        "features": list(cfg["data"]["feature_names"]),
        "queries": int(queries),
        "reward_config": reward_config,
        **({"wants": wants} if wants is not None else {}),
        **(extra or {}),
    }
    path = out / f"reward-{name}.json"
    text = json.dumps(doc) + "\n"
    try:
        out.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        if default:
            (out / DEFAULT_NAME).write_text(text)
    except OSError as exc:
        raise LangprefError(
            f"cannot write the reward into {out} ({exc.strerror or exc}); pass another folder"
        ) from None
    return path


def save_learned_reward(
    learner,
    out: str | Path,
    *,
    env: str,
    model: str | Path | None,
    name: str = "reward",
    default: bool = False,
    space=None,
    extra: dict[str, Any] | None = None,
) -> Path:
    """Write a learner's r_xi as its learner type saves it (`langpref.reward.learners`; `write_reward`): the paper
    learner's parameters, or the answer-model learner's posterior-mean reward as the linear r = xi . phi it is. With
    `space` (the latent space of the dataset it was learned on), also what the reward wants in the task's
    features."""
    from langpref.reward.learners import learner_type_of

    check_saveable(model)
    kind, params, reward_config = learner_type_of(learner).saved(learner)
    wants = None
    if space is not None:
        from langpref.reward.wants import what_it_wants

        wants = what_it_wants(learner.predict(space.phi), space.theta, space.feature_names)
    return write_reward(
        out,
        name,
        kind=kind,
        params=params,
        reward_config=reward_config,
        env=env,
        model=model,
        queries=learner.num_queries,
        wants=wants,
        extra=extra,
        default=default,
    )


def _import_gym():
    import gymnasium

    import langpref.tasks.gym  # noqa: F401  (registers langpref/...)

    return gymnasium


class LearnedReward(_import_gym().Wrapper):
    """Replaces the wrapped env's reward with the learned r_xi, per step (see the module docstring); the env's own
    reward goes to `info["env_reward"]`, the running r_xi(phi_t) to `info["r_xi"]`."""

    def __init__(self, env, reward: str | Path | Reward):
        super().__init__(env)
        self.reward = reward if isinstance(reward, Reward) else load(reward)
        task = getattr(getattr(env.unwrapped, "task", None), "name", None)
        if task is not None and task != self.reward.task:
            raise LangprefError(
                f"the reward {self.reward.path} was learned on task {self.reward.task!r}, not on this env's task "
                f"{task!r}: use langpref/{self.reward.task}, or learn a reward on {task!r}"
            )
        shape = getattr(env.observation_space, "shape", None)
        if shape != (self.reward.obs_dim,) or env.action_space.shape != (self.reward.action_dim,):
            raise LangprefError(
                f"the reward was learned on observations of {self.reward.obs_dim} and actions of "
                f"{self.reward.action_dim} numbers; this env has {shape} and "
                f"{env.action_space.shape}: use langpref/{self.reward.task}"
            )
        self._obs = self._prev = None
        self._sum = np.zeros(0)
        self._t = 0
        self._last = 0.0

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        self._obs = self._prev = np.asarray(obs, dtype=np.float32)
        self._sum, self._t, self._last = np.zeros(self.reward.encoder.dim), 0, 0.0
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise LangprefError("call reset() before step()")
        steps = np.stack([self._prev, self._obs])  # the previous observation gives the change of observation
        e = self.reward.step_embeddings(steps, np.stack([action, action]).astype(np.float32))[1]
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        self._t += 1
        self._sum = self._sum + e
        value = self.reward.value(self._sum / self._t)
        r = float(self.reward.params["xi"] @ e) if self.reward.kind == "linear" else self._t * value - self._last
        self._last = self._t * value
        self._prev, self._obs = self._obs, np.asarray(obs, dtype=np.float32)
        return obs, r, terminated, truncated, {**info, "env_reward": env_reward, "r_xi": value}
