"""The learned reward r_xi outside langpref: saved by `langpref learn-reward --save-reward DIR`, and given per step
by a Gymnasium wrapper any RL library can train on.

    import gymnasium as gym
    from langpref.reward.saved import LearnedReward
    env = LearnedReward(gym.make("langpref/metaworld-button-press"), "DIR")   # DIR/reward.json, or a reward file

A saved reward (`reward-NAME.json`) holds r_xi's parameters, the task, and a reference to the checkpoint whose
trajectory encoder makes phi (its path and the checksum of its weights; the encoder's input normalisation is read
from there and checked). Only the trajectory encoder is loaded, not the language model.

Per-step reward. phi(tau) = (1/T) sum_t e_t, the time mean of per-step embeddings e_t = W h(s_t, a_t) + c (the
encoder's last layer is linear). With the running mean phi_t = (1/t) sum_{k<=t} e_k, step t pays

    r_t = t r_xi(phi_t) - (t - 1) r_xi(phi_{t-1})

which telescopes: sum_t r_t = T r_xi(phi_T) = T r_xi(tau), for any r_xi. For the linear r_xi = xi . phi this is
r_t = xi . e_t, a function of the step alone (Markov in the observation and the previous one). For the `mlp` r_xi the
sum is the same but r_t depends on the whole history through phi_t: a dense, exact shaping of the episode's
T r_xi(tau), not a Markov reward of the step.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError

FORMAT = "langpref-reward"
FORMAT_VERSION = 1
DEFAULT_NAME = "reward.json"


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


def save_learned_reward(
    learner, out: str | Path, *, env: str, model: str | Path | None, name: str = "reward", default: bool = False
) -> Path:
    """Write a learner's r_xi as OUT/reward-NAME.json (and as OUT/reward.json when `default`): the paper learner's
    parameters, or the answer-model learner's posterior-mean reward as the linear r = xi . phi it is (up to a
    constant, which shifts every trajectory alike)."""
    from langpref.model.checkpoint import WEIGHTS

    cfg = check_saveable(model)
    model = Path(model).resolve()
    if hasattr(learner, "latent_weights"):  # the answer-model learner: linear in phi, up to a constant
        kind, params = "linear", {"xi": learner.latent_weights().tolist()}
        reward_config = {"learner": "answer-model", **asdict(learner.cfg)}
    else:
        kind = learner.cfg.model
        values = [p.detach().cpu().numpy().astype(np.float64).tolist() for p in learner.params]
        params = dict(zip(("xi",) if kind == "linear" else ("w1", "b1", "w2"), values))
        reward_config = dict(vars(learner.cfg))
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "task": env,
        "kind": kind,
        "params": params,
        "model": {"path": str(model), "sha256": cfg["files"][WEIGHTS]["sha256"]},
        "normalisation": cfg.get("normalisation", {}),
        "observation_deltas": bool(cfg["model"].get("observation_deltas", False)),
        "obs_dim": cfg["data"]["obs_dim"],
        "action_dim": cfg["data"]["action_dim"],
        "dataset_horizon": cfg["data"]["horizon"],
        "queries": learner.num_queries,
        "reward_config": reward_config,
    }
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"reward-{name}.json"
    text = json.dumps(doc) + "\n"
    path.write_text(text)
    if default:
        (out / DEFAULT_NAME).write_text(text)
    return path


class SavedReward:
    """A saved r_xi with the per-step trajectory encoder it reads: `step_embedding` and `value` in numpy."""

    def __init__(self, path: str | Path):
        from safetensors.numpy import load_file

        from langpref.model.checkpoint import WEIGHTS, read_config

        path = Path(path)
        path = path / DEFAULT_NAME if path.is_dir() else path
        try:
            doc = json.loads(path.read_text())
        except FileNotFoundError:
            raise LangprefError(
                f"no saved reward at {path}: write one with `langpref learn-reward ... --save-reward DIR`"
            ) from None
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise LangprefError(f"{path} is not a saved reward (not JSON)") from None
        if doc.get("format") != FORMAT or doc.get("format_version") != FORMAT_VERSION:
            raise LangprefError(f"{path} is not a langpref reward of format version {FORMAT_VERSION}")
        model = Path(doc["model"]["path"])
        cfg = read_config(model)
        if cfg["files"][WEIGHTS]["sha256"] != doc["model"]["sha256"]:
            raise LangprefError(f"the checkpoint {model} has changed since the reward {path} was saved; learn it again")
        state = load_file(str(model / WEIGHTS))
        self.path, self.doc, self.task, self.kind = path, doc, doc["task"], doc["kind"]
        self.deltas = bool(doc["observation_deltas"])
        self.obs_dim, self.action_dim = int(doc["obs_dim"]), int(doc["action_dim"])
        self.mean, self.std = state["traj.mean"].astype(np.float64), state["traj.std"].astype(np.float64)
        layers = sorted({int(k.split(".")[2]) for k in state if k.startswith("traj.body.")})
        self.body = [
            (state[f"traj.body.{i}.weight"].astype(np.float64), state[f"traj.body.{i}.bias"].astype(np.float64))
            for i in layers
        ]
        self.out = (state["traj.out.weight"].astype(np.float64), state["traj.out.bias"].astype(np.float64))
        self.params = {k: np.asarray(v, dtype=np.float64) for k, v in doc["params"].items()}

    def step_embedding(self, obs: np.ndarray, prev_obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        """e_t of one step: the encoder's MLP on (s_t, [s_t - s_{t-1}], a_t), normalised as in training."""
        parts = [obs, obs - prev_obs] if self.deltas else [obs]
        x = np.concatenate([*parts, action]).astype(np.float32).astype(np.float64)
        h = (x - self.mean) / self.std
        for w, b in self.body:
            h = np.maximum(w @ h + b, 0.0)
        return self.out[0] @ h + self.out[1]

    def value(self, phi: np.ndarray) -> float:
        """r_xi(phi)."""
        p = self.params
        if self.kind == "linear":
            return float(p["xi"] @ phi)
        return float(np.maximum(phi @ p["w1"] + p["b1"], 0.0) @ p["w2"])


def _import_gym():
    import gymnasium

    import langpref.tasks.gym  # noqa: F401  (registers langpref/...)

    return gymnasium


class LearnedReward(_import_gym().Wrapper):
    """Replaces the wrapped env's reward with the learned r_xi, per step (see the module docstring); the env's own
    reward goes to `info["env_reward"]`, the running r_xi(phi_t) to `info["r_xi"]`."""

    def __init__(self, env, reward: str | Path | SavedReward):
        super().__init__(env)
        self.reward = reward if isinstance(reward, SavedReward) else SavedReward(reward)
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
        self._sum, self._t, self._last = np.zeros_like(self.reward.out[1]), 0, 0.0
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise LangprefError("call reset() before step()")
        e = self.reward.step_embedding(self._obs, self._prev, np.asarray(action, dtype=np.float32))
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        self._t += 1
        self._sum = self._sum + e
        value = self.reward.value(self._sum / self._t)
        r = float(self.reward.params["xi"] @ e) if self.reward.kind == "linear" else self._t * value - self._last
        self._last = self._t * value
        self._prev, self._obs = self._obs, np.asarray(obs, dtype=np.float32)
        return obs, r, terminated, truncated, {**info, "env_reward": env_reward, "r_xi": value}
