"""Per-step features of the reach recording (`record.py`), from Meta-World observations alone (numpy only).

Meta-World's 39-number observation: [0:3] hand position, [3] gripper opening, [4:18] the (unused) puck's pose and
padding, [18:36] the previous frame's [0:18], [36:39] the goal the hand should reach.

Features, one row per step:
  height            hand height above the table (m)
  speed             hand speed over the step, |p_t - p_{t-1}| / dt (m/s; dt = 12.5 ms; 0 on the first step)
  distance_to_goal  distance from the hand to the goal (m)
"""

from __future__ import annotations

import numpy as np

FEATURES = ("height", "speed", "distance_to_goal")
DT = 0.0125  # seconds per Meta-World step (5 MuJoCo substeps of 2.5 ms)


def step_features(observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """(T, 3) float64 per-step features of one episode; `actions` is accepted for the interface, not used."""
    obs = np.asarray(observations, dtype=np.float64)
    if obs.ndim != 2 or obs.shape[1] < 39:
        raise ValueError(f"expected (T, 39) Meta-World observations, got shape {obs.shape}")
    del actions
    hand, prev_hand, goal = obs[:, 0:3], obs[:, 18:21], obs[:, 36:39]
    speed = np.linalg.norm(hand - prev_hand, axis=1) / DT
    speed[0] = 0.0  # Meta-World's first observation repeats the hand as its own previous frame
    return np.stack([hand[:, 2], speed, np.linalg.norm(hand - goal, axis=1)], axis=1)
