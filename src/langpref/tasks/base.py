"""What a task is (`Task`), and the interface its simulator implements, if it has one (`SimEnv`, `Controller`).

The simulator interface is shaped after robomimic's env wrappers: reset, step, get/set simulator state, success,
features. The generator and the renderer talk to an env only through it, so any stored trajectory replays and renders.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib.abc import Traversable
from pathlib import Path
from typing import Protocol

import numpy as np

from langpref.errors import LangprefError


@dataclass(frozen=True)
class ObsField:
    """A named slice [start, stop) of the flat observation vector."""

    name: str
    start: int
    stop: int


@dataclass(frozen=True)
class Simulator:
    """What `langpref generate` needs to make trajectories of a task: a live env and a scripted controller.

    `make_env(horizon)` returns a `SimEnv`; `make_controller(unit, rng)` a `Controller` whose parameters are
    `controller_dim` numbers in [0, 1) (one Latin hypercube row per trajectory). Both are called inside worker
    processes, so they must be importable functions, not lambdas.
    """

    make_env: Callable[[int], SimEnv]
    make_controller: Callable[[np.ndarray, np.random.Generator], Controller]
    controller_dim: int
    default_horizon: int = 500
    default_num_trajectories: int = 324
    success_name: str = "success"
    extra: str | None = None
    """The langpref extra that installs this simulator (`pip install 'langpref[EXTRA]'`), checked before any rollout
    starts; None for a plugin, whose own package brings its simulator."""
    version: int = 1
    """Bumped whenever what its env or controller roll out changes (observations, features, dynamics). `generate`
    records it in every dataset (`env_version` in meta.json's config), so data made before a change is recognisable,
    and an interrupted generation is never resumed across one."""


@dataclass(frozen=True)
class Task:
    """A robot task: what its trajectories look like, what a person may say about them, and how to show them.

    Built-in tasks (`metaworld`, `robosuite`) and plugins (entry-point group `langpref.tasks`) come with a
    `simulator`; a recorded task (a TOML task file, `langpref import`) has none and brings its own videos.
    `utterances` is the task's bank: a JSON file `{train|val|test: {feature: {increase: [...], decrease: [...]}}}`.
    """

    name: str
    features: tuple[str, ...]
    feature_descriptions: tuple[str, ...]
    obs_layout: tuple[ObsField, ...]
    action_dim: int
    description: str
    """What the robot is doing, as participants of a study read it."""
    utterances: Path | Traversable
    robot: str = "a robot arm"
    examples: tuple[str, ...] = ()
    """A few phrasings shown to participants as examples of feedback."""
    default_splits: tuple[int, int, int] = (60, 20, 20)
    """train/val/test trajectory counts for the default size (other sizes keep the proportions)."""
    simulator: Simulator | None = None
    source: str = "built-in"
    """Where the task comes from: built-in, a plugin's entry point, or a task file."""

    @property
    def obs_dim(self) -> int:
        return self.obs_layout[-1].stop

    def __post_init__(self) -> None:
        if len(self.feature_descriptions) != len(self.features):
            raise LangprefError(
                f"task {self.name!r}: {len(self.features)} features but "
                f"{len(self.feature_descriptions)} feature descriptions"
            )
        if len(set(self.features)) != len(self.features):
            raise LangprefError(f"task {self.name!r} names a feature twice: {', '.join(self.features)}")


class SimEnv(Protocol):
    """A live simulator instance. `step` returns the next observation; per-step features are read after a step.

    `reset(seed)` must fix everything a trajectory's look depends on that is not in (qpos, qvel) (object placement,
    goal markers): the renderer replays a stored trajectory by `reset(seed)` and then `set_state` at every step.
    Controllers whose phases scale with the episode read `horizon`.
    """

    dt: float
    horizon: int

    def reset(self, seed: int) -> np.ndarray: ...

    def step(self, action: np.ndarray) -> np.ndarray: ...

    def step_features(self) -> np.ndarray:
        """theta(s_t, a_t) for the step just taken, in the task's feature order."""
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
        """Default camera for videos: either {"name": cam} or
        {"lookat": [x,y,z], "distance", "azimuth", "elevation"}.
        """
        ...

    def close(self) -> None: ...


class Controller(Protocol):
    """A closed-loop scripted policy with parameters drawn per trajectory (the stand-in for the paper's RL policies)."""

    def act(self, env: SimEnv, obs: np.ndarray, t: int) -> np.ndarray: ...
