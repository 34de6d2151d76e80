"""The trajectory encoder per step, in numpy: what a saved reward reads and what the value-order metric needs.

phi(tau) = (1/T) sum_t e_t, the time mean of per-step embeddings e_t = W h(s_t, a_t) + c: the encoder's last layer is
linear, so the mean can be taken after it as well as before (`langpref.model.encoders`). `StepEncoder` gives every
e_t of a trajectory, and `prefix_means` the running means phi_t = (1/t) sum_{k<=t} e_k, phi_T being phi(tau). Only the
trajectory encoder's weights are read (no language model, no torch module is built), and only a state model's:
one that sees camera frames cannot be rebuilt from the state.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError


@dataclass(frozen=True, eq=False)
class StepEncoder:
    """A state model's trajectory encoder as numpy arrays: input normalisation, hidden layers, linear output."""

    mean: np.ndarray
    std: np.ndarray
    body: tuple[tuple[np.ndarray, np.ndarray], ...]
    out: tuple[np.ndarray, np.ndarray]
    observation_deltas: bool
    obs_dim: int
    action_dim: int
    sha256: str
    """Checksum of the checkpoint's weights file, so a reward can tell when the encoder it was learned on changed."""
    delta_magnitudes: bool = False
    """The encoder also reads |s_t - s_{t-1}| (`ModelConfig.delta_magnitudes`)."""

    @classmethod
    def from_checkpoint(cls, model: str | Path) -> StepEncoder:
        """The trajectory encoder of the `langpref train` checkpoint `model`; a one-line error for a model that
        sees camera frames."""
        from safetensors.numpy import load_file

        from langpref.model.checkpoint import WEIGHTS, read_config

        model = Path(model)
        cfg = read_config(model)
        seen = cfg["model"].get("observations") or "state"  # None or absent: a state model
        if seen != "state":
            raise LangprefError(
                f"the model in {model} sees camera frames ({seen}); its per-step reward cannot be rebuilt from the "
                "state alone: use a state model"
            )
        state = load_file(str(model / WEIGHTS))
        layers = sorted({int(k.split(".")[2]) for k in state if k.startswith("traj.body.")})

        def f64(name: str) -> np.ndarray:
            return state[name].astype(np.float64)

        return cls(
            mean=f64("traj.mean"),
            std=f64("traj.std"),
            body=tuple((f64(f"traj.body.{i}.weight"), f64(f"traj.body.{i}.bias")) for i in layers),
            out=(f64("traj.out.weight"), f64("traj.out.bias")),
            observation_deltas=bool(cfg["model"].get("observation_deltas", False)),
            obs_dim=int(cfg["data"]["obs_dim"]),
            action_dim=int(cfg["data"]["action_dim"]),
            sha256=str(cfg["files"][WEIGHTS]["sha256"]),
            delta_magnitudes=bool(cfg["model"].get("delta_magnitudes", False)),
        )

    @property
    def dim(self) -> int:
        """D, the latent dimension."""
        return int(self.out[1].shape[0])

    def embeddings(self, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """e_t of every step (T, D) of one trajectory, observations (T, obs_dim) and actions (T, A): the encoder's
        MLP on (s_t, [s_t - s_{t-1}, zero at t = 1], [its absolute value], a_t), normalised as in training."""
        obs = np.asarray(observations, dtype=np.float32)
        act = np.asarray(actions, dtype=np.float32)
        if obs.ndim != 2 or act.ndim != 2 or len(obs) != len(act) or len(obs) == 0:
            raise LangprefError(
                f"a trajectory is observations (T, obs_dim) and actions (T, A) with the same T >= 1; got "
                f"{obs.shape} and {act.shape}"
            )
        if obs.shape[1] != self.obs_dim or act.shape[1] != self.action_dim:
            raise LangprefError(
                f"the reward reads observations of {self.obs_dim} and actions of {self.action_dim} numbers; got "
                f"{obs.shape[1]} and {act.shape[1]}"
            )
        delta = np.diff(obs, axis=0, prepend=obs[:1])
        parts = [obs] + [delta] * self.observation_deltas + [np.abs(delta)] * self.delta_magnitudes
        x = np.concatenate([*parts, act], axis=1).astype(np.float32).astype(np.float64)
        h = (x - self.mean) / self.std
        for w, b in self.body:
            h = np.maximum(h @ w.T + b, 0.0)
        return h @ self.out[0].T + self.out[1]


def prefix_means(embeddings: np.ndarray) -> np.ndarray:
    """phi_t = (1/t) sum_{k<=t} e_k for t = 1..T (T, D): the embedding of the trajectory up to each step."""
    e = np.asarray(embeddings, dtype=np.float64)
    return np.cumsum(e, axis=0) / np.arange(1, len(e) + 1)[:, None]


@dataclass(frozen=True, eq=False)
class SuccessEpisodes:
    """The successful episodes of an evaluation split, step by step: what the value-order metric reads rewards on."""

    phi: list[np.ndarray]
    """Per episode, phi_t (T, D): the model's embedding of the episode up to each step."""
    theta: list[np.ndarray]
    """Per episode, theta_t (T, F): the synthetic humans' features of the episode up to each step, on the scale
    of the space's theta (so that w . theta_t is the true reward of the episode so far)."""


def success_prefixes(
    data: str | Path | Any, model: str | Path, split: str = "test", feature_scale: str = "standardised"
) -> SuccessEpisodes | None:
    """Every successful episode of `split` of the dataset `data` (a directory, or the dataset a command already
    opened, so it is not read again), step by step: phi_t embedded by the state model `model` (its trajectory
    encoder's weights as numpy, `StepEncoder`, as a saved reward reads them), and theta_t, the per-step features
    averaged up to step t and standardised as the space's theta (`feature_scale` "standardised"), or summed up to
    t (the paper's scale). None when the model sees camera frames (its steps cannot be embedded one by one from the
    state), the recording has no success labels (an import without them) or none of the split succeeded."""
    from langpref.dataset.storage import load_dataset
    from langpref.feedback.space import FeatureScale
    from langpref.model.checkpoint import read_config

    if (read_config(model)["model"].get("observations") or "state") != "state":
        return None
    dataset = load_dataset(data) if isinstance(data, str | Path) else data
    if not dataset.meta.config.get("success_known", True):
        return None
    episodes = [t for t in map(dataset.load, dataset.split(split)) if t.success]
    if not episodes:
        return None
    encoder = StepEncoder.from_checkpoint(model)
    scale = FeatureScale.fit(np.asarray(dataset.features, dtype=np.float64)[dataset.split("train")])
    if feature_scale == "standardised":
        theta = [scale(prefix_means(t.step_features)) for t in episodes]
    else:
        theta = [np.cumsum(np.asarray(t.step_features, dtype=np.float64), axis=0) for t in episodes]
    return SuccessEpisodes([prefix_means(encoder.embeddings(t.observations, t.actions)) for t in episodes], theta)
