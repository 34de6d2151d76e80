"""Meta-World Sawyer reach (`reach-v3`) as a langpref `SimEnv`, with this task's own features.

Features per step, in metres and metres per second, all measured at the fingertip centre (Meta-World's `tcp_center`,
about 4.5 cm below the hand body that observations report; Meta-World judges reach success there, within 5 cm):
  height            fingertip height above the table
  speed             fingertip speed over the step, |p_{t+1} - p_t| / dt
  distance_to_goal  fingertip to the goal point (the red dot the arm should reach)

The env is built straight from Meta-World's class rather than through `gym.make`, so that `reset(seed)` fixes the
goal and puck from our seed alone and a stored trajectory replays exactly.
"""

from __future__ import annotations

import numpy as np
from langpref.tasks import ObsField

FEATURES = ("height", "speed", "distance_to_goal")
OBS_LAYOUT = (
    ObsField("hand_pos", 0, 3),
    ObsField("gripper_opening", 3, 4),
    ObsField("puck_pos", 4, 7),
    ObsField("puck_quat", 7, 11),
    ObsField("padding", 11, 18),
    ObsField("prev_hand_pos", 18, 21),
    ObsField("prev_gripper_opening", 21, 22),
    ObsField("prev_puck_pos", 22, 25),
    ObsField("prev_puck_quat", 25, 29),
    ObsField("prev_padding", 29, 36),
    ObsField("goal", 36, 39),
)
OBS_DIM = OBS_LAYOUT[-1].stop
ACTION_DIM = 4
# reach-v3 redraws its reset until puck and goal are this far apart in x-y; with a frozen draw it would loop forever,
# so `reset` does the redrawing itself.
_MIN_PUCK_GOAL_XY = 0.15


class MetaWorldReach:
    """`SimEnv` over Meta-World's SawyerReachEnvV3: the arm starts above a puck and should reach a goal point."""

    def __init__(self, horizon: int = 150) -> None:
        import metaworld  # noqa: F401  (registers the envs; needs `packaging`)
        from metaworld.envs.sawyer_reach_v3 import SawyerReachEnvV3

        self.horizon = horizon
        self._env = SawyerReachEnvV3()
        self._env.max_path_length = max(horizon, 1)
        self._env._partially_observable = False  # show the goal in the observation...
        self._env.__dict__.pop("sawyer_observation_space", None)  # ...and stop `step` clipping it to zero
        self._env._set_task_called = True
        self.dt = float(self._env.dt)
        self._tip = np.zeros(3)
        self._goal = np.zeros(3)
        self._features = np.zeros(len(FEATURES))
        self._success = False

    def reset(self, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        space = self._env._random_reset_space  # puck xyz, then goal xyz
        while True:
            vec = rng.uniform(space.low, space.high)
            if np.linalg.norm(vec[0:2] - vec[3:5]) >= _MIN_PUCK_GOAL_XY:
                break
        self._env._last_rand_vec = vec
        self._env._freeze_rand_vec = True
        self._env.seed(int(seed) % (2**31))
        obs, _ = self._env.reset()
        self._tip = self._env.tcp_center.copy()
        self._goal = obs[36:39].astype(np.float64)
        self._features = np.zeros(len(FEATURES))
        self._success = False
        return obs.astype(np.float32)

    def step(self, action: np.ndarray) -> np.ndarray:
        obs, _, _, _, info = self._env.step(np.clip(action, -1.0, 1.0).astype(np.float32))
        tip = self._env.tcp_center.copy()
        self._features = step_features(self._tip, tip, self._goal, self.dt)
        self._tip = tip
        self._success = self._success or bool(info["success"])
        return obs.astype(np.float32)

    def step_features(self) -> np.ndarray:
        return self._features

    def is_success(self) -> bool:
        """Whether the fingertips came within 5 cm of the goal at any step (Meta-World's own test)."""
        return self._success

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._env.data.qpos.copy(), self._env.data.qvel.copy()

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        self._env.set_state(np.asarray(qpos, dtype=np.float64), np.asarray(qvel, dtype=np.float64))

    def mujoco_handles(self) -> tuple[object, object]:
        return self._env.model, self._env.data

    def camera(self) -> dict:
        return {"lookat": [0.0, 0.7, 0.15], "distance": 1.3, "azimuth": 135.0, "elevation": -25.0}

    def close(self) -> None:
        self._env.close()


def step_features(prev_tip: np.ndarray, tip: np.ndarray, goal: np.ndarray, dt: float) -> np.ndarray:
    """theta(s_t, a_t): height and distance of the fingertips at the state reached, their speed over the step."""
    return np.array([tip[2], np.linalg.norm(tip - prev_tip) / dt, np.linalg.norm(tip - goal)])


def make(horizon: int = 150) -> MetaWorldReach:
    """The `Simulator.make_env` of the task (a module-level function, so worker processes can import it)."""
    return MetaWorldReach(horizon)
