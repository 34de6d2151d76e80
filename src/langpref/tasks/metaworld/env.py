"""Meta-World Sawyer button press (`button-press-v3`) with the paper's features. Its scripted controller is
`langpref.tasks.metaworld.controller`.

Features per step (paper Appendix A), in metres and metres per second:
  height              end-effector (hand) z
  speed               end-effector velocity norm over the step, |p_{t+1} - p_t| / dt
  distance_to_button  end-effector to the button face (both as Meta-World observes them)

The env is built straight from Meta-World's class rather than through `gym.make`, so that `reset(seed)` fixes the
button position from our seed alone and a stored trajectory replays exactly. It is fully observable: obs[36:39] is
the goal (the button's pressed position) on every step (`SIMULATOR_VERSION` 2; datasets made before, version 1 or no
version recorded, hold zeros there after the first step).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from langpref.tasks.base import ObsField

FEATURES = ("height", "speed", "distance_to_button")
OBS_LAYOUT = (
    ObsField("hand_pos", 0, 3),
    ObsField("gripper_opening", 3, 4),
    ObsField("button_pos", 4, 7),
    ObsField("button_quat", 7, 11),
    ObsField("padding", 11, 18),
    ObsField("prev_hand_pos", 18, 21),
    ObsField("prev_gripper_opening", 21, 22),
    ObsField("prev_button_pos", 22, 25),
    ObsField("prev_button_quat", 25, 29),
    ObsField("prev_padding", 29, 36),
    ObsField("goal", 36, 39),
)
OBS_DIM = OBS_LAYOUT[-1].stop
ACTION_DIM = 4
SIMULATOR_VERSION = 2
"""1: obs[36:39] (the goal) was zero after the first step of every rollout. 2: it carries the goal on every step."""


class MetaWorldButtonPress:
    """`SimEnv` over Meta-World's SawyerButtonPressEnvV3."""

    def __init__(self, horizon: int = 500):
        from langpref.extras import needs

        with needs("metaworld", "task 'metaworld'"):
            import metaworld  # noqa: F401  (registers the envs; needs `packaging`)
            from metaworld.envs.sawyer_button_press_v3 import SawyerButtonPressEnvV3

        self.horizon = horizon
        self._env = SawyerButtonPressEnvV3()
        self._env.max_path_length = max(horizon, 1)
        self._env._set_task_called = True
        observe_goal(self._env)
        self.dt = float(self._env.dt)
        self._obs = np.zeros(OBS_DIM)
        self._features = np.zeros(len(FEATURES))
        self._success = False

    def reset(self, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        space = self._env._random_reset_space
        self._env._last_rand_vec = rng.uniform(space.low, space.high)
        self._env._freeze_rand_vec = True
        self._env.seed(int(seed) % (2**31))
        obs, _ = self._env.reset()
        self._obs = obs.astype(np.float64)
        self._success = False
        return self._obs.astype(np.float32)

    def step(self, action: np.ndarray) -> np.ndarray:
        prev = self._obs
        obs, _, _, _, info = self._env.step(np.clip(action, -1.0, 1.0).astype(np.float32))
        self._obs = obs.astype(np.float64)
        self._success = self._success or bool(info["success"])
        self._features = step_features(prev, self._obs, self.dt)
        return self._obs.astype(np.float32)

    def step_features(self) -> np.ndarray:
        return self._features

    def is_success(self) -> bool:
        return self._success

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._env.data.qpos.copy(), self._env.data.qvel.copy()

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        self._env.set_state(np.asarray(qpos, dtype=np.float64), np.asarray(qvel, dtype=np.float64))

    def mujoco_handles(self) -> tuple[object, object]:
        return self._env.model, self._env.data

    def camera(self) -> dict:
        return {"lookat": [0.0, 0.62, 0.12], "distance": 1.25, "azimuth": 135.0, "elevation": -25.0}

    def close(self) -> None:
        self._env.close()


def observe_goal(env: Any) -> None:
    """Turn on full observability, so that obs[36:39] carries the goal on every step, not on reset alone.

    Meta-World builds (and caches) its observation space while the env is still partially observable, with the goal
    slot bounded to [0, 0], and `step()` clips every observation to that space: flipping `_partially_observable`
    alone gives the goal at reset and zeros at every later step. Drop the cached space and rebuild it, as
    `set_task` does when it changes observability, so the goal slot is bounded by the goal space instead.
    """
    env._partially_observable = False
    env.__dict__.pop("sawyer_observation_space", None)  # a functools.cached_property: rebuilt on the next read
    env.observation_space = env.sawyer_observation_space


def step_features(prev_obs: np.ndarray, obs: np.ndarray, dt: float) -> np.ndarray:
    """theta(s_t, a_t): height and distance of the state reached, speed over the step."""
    hand, prev_hand, button = obs[0:3], prev_obs[0:3], obs[4:7]
    return np.array([hand[2], np.linalg.norm(hand - prev_hand) / dt, np.linalg.norm(hand - button)])


def make(horizon: int = 500) -> MetaWorldButtonPress:
    return MetaWorldButtonPress(horizon)
