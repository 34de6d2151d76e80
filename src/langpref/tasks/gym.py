"""langpref's simulated tasks as Gymnasium environments, so that any RL library can train on them.

    import gymnasium as gym
    import langpref.tasks.gym  # registers the ids below (or: gym.make("langpref.tasks.gym:langpref/..."))
    env = gym.make("langpref/metaworld-button-press")          # horizon 500, as the datasets
    env = gym.make("langpref/robosuite-lift-bottle", horizon=200)

Every task with a simulator is also registered as `langpref/TASK` (built-ins and installed plugins). Observations are
float32 vectors laid out as the task's datasets store them (`langpref tasks --json` lists the layout), actions are in
[-1, 1]^A, an episode is truncated after `horizon` steps and `reset(seed=...)` fixes the scene as a dataset
trajectory's seed does. The environment has no reward of its own (0 every step; `info` carries the step's features
and success): wrap it in `langpref.reward.saved.LearnedReward` for a learned one, or in your own.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

NAMES = {"metaworld": "langpref/metaworld-button-press", "robosuite": "langpref/robosuite-lift-bottle"}
"""The descriptive ids of the built-in tasks (each is also `langpref/TASK`)."""


class LangprefEnv(gym.Env):
    """A langpref `SimEnv` behind the Gymnasium API."""

    metadata = {"render_modes": []}

    def __init__(self, task: str, horizon: int | None = None):
        from langpref.tasks import get_simulator, get_task

        self.task = get_task(task)
        sim = get_simulator(task)
        self.horizon = int(horizon or sim.default_horizon)
        self.sim = sim.make_env(self.horizon)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.task.obs_dim,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.task.action_dim,), np.float32)
        self._t = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        scene = int(seed) if seed is not None else int(self.np_random.integers(2**31))
        self._t = 0
        return np.asarray(self.sim.reset(scene), dtype=np.float32), {"scene_seed": scene}

    def step(self, action):
        obs = np.asarray(self.sim.step(np.asarray(action, dtype=np.float64)), dtype=np.float32)
        self._t += 1
        info = {
            "features": np.asarray(self.sim.step_features(), dtype=np.float64).copy(),
            "success": bool(self.sim.is_success()),
        }
        return obs, 0.0, False, self._t >= self.horizon, info

    def close(self) -> None:
        self.sim.close()


def register_envs() -> list[str]:
    """Register every simulated task (idempotent); the ids registered."""
    from langpref.tasks import get_task, task_names

    ids = []
    for name in task_names():
        if get_task(name).simulator is None:
            continue
        for env_id in dict.fromkeys((NAMES.get(name, f"langpref/{name}"), f"langpref/{name}")):
            if env_id not in gym.registry:
                gym.register(
                    id=env_id,
                    entry_point="langpref.tasks.gym:LangprefEnv",
                    kwargs={"task": name},
                    disable_env_checker=True,
                )
            ids.append(env_id)
    return ids


register_envs()
