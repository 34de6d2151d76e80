"""The interface every simulated environment of langpref implements.

Shaped after robomimic's env wrappers: reset, step, get/set simulator state, success, features. The generator, the
renderer and everything downstream talk to an env only through this, so any stored trajectory replays and renders.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class ObsField:
    """A named slice [start, stop) of the flat observation vector."""

    name: str
    start: int
    stop: int


@dataclass(frozen=True)
class EnvSpec:
    """Static facts about an env, known without importing its simulator."""

    name: str
    features: tuple[str, ...]
    obs_layout: tuple[ObsField, ...]
    action_dim: int
    default_horizon: int
    default_num_trajectories: int
    default_splits: tuple[int, int, int]  # train/val/test for the default number of trajectories
    success_name: str  # what "success" means, e.g. "button pressed"

    @property
    def obs_dim(self) -> int:
        return self.obs_layout[-1].stop


class SimEnv(Protocol):
    """A live simulator instance. `step` returns the next observation; per-step features are read after a step."""

    spec: EnvSpec
    dt: float

    def reset(self, seed: int) -> np.ndarray: ...

    def step(self, action: np.ndarray) -> np.ndarray: ...

    def step_features(self) -> np.ndarray:
        """theta(s_t, a_t) for the step just taken, in `spec.features` order."""
        ...

    def is_success(self) -> bool: ...

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(qpos, qvel) of the MuJoCo simulation, enough to re-render this instant."""
        ...

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None: ...

    def mujoco_handles(self) -> tuple[object, object]:
        """(mujoco.MjModel, mujoco.MjData) of the underlying simulation, for offscreen rendering."""
        ...

    def camera(self) -> dict:
        """Default camera for videos: either {"name": cam} or {"lookat": [x,y,z], "distance", "azimuth", "elevation"}."""
        ...

    def close(self) -> None: ...


class Controller(Protocol):
    """A closed-loop scripted policy with parameters drawn per trajectory (the stand-in for the paper's RL policies)."""

    def act(self, env: SimEnv, obs: np.ndarray, t: int) -> np.ndarray: ...
