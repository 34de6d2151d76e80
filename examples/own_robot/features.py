"""Per-step features of the drawer-open recording, computed from Meta-World observations alone (numpy only).

Meta-World's 39-number observation: [0:3] hand position, [3] gripper opening (1 = wide open, about 0.3 = shut),
[4:7] drawer handle position, [7:11] its quaternion, [11:18] padding, [18:36] the previous frame's [0:18], [36:39] goal.
The world frame: x runs along the drawer's handle (to the right in the video), y away from the robot (the drawer
opens towards -y), z up.

Features, one row per step:
  drawer_opening   how far the drawer is pulled out of its case (m, 0 = shut, about 0.2 = fully open)
  hand_sideways    hand x minus handle-centre x (m): > 0 holds/hovers right of the centre, < 0 left of it
  gripper_closure  how closed the fingers are (0 = wide open, about 0.7 = shut)

Run as a script on a recording folder to print each feature's spread and the correlations of the episode means:
    python examples/own_robot/features.py data/own_robot_recording
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

FEATURES = ("drawer_opening", "hand_sideways", "gripper_closure")

# Handle y with the drawer shut: Meta-World's drawer-open-v3 always puts the drawer case at y = 0.9 (only its x is
# random), which leaves the handle at y = 0.73; it opens 0.2 m at most.
CLOSED_HANDLE_Y = 0.73


def step_features(observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """(T, 3) float64 per-step features of one episode; `actions` (T, 4) is accepted for the interface, not used."""
    obs = np.asarray(observations, dtype=np.float64)
    if obs.ndim != 2 or obs.shape[1] < 7:
        raise ValueError(f"expected (T, 39) Meta-World observations, got shape {obs.shape}")
    del actions  # every feature here is visible in the state; the commanded motion adds nothing
    hand, gripper_opening, handle = obs[:, 0:3], obs[:, 3], obs[:, 4:7]
    drawer_opening = np.clip(CLOSED_HANDLE_Y - handle[:, 1], 0.0, None)
    hand_sideways = hand[:, 0] - handle[:, 0]
    gripper_closure = 1.0 - gripper_opening
    return np.stack([drawer_opening, hand_sideways, gripper_closure], axis=1)


def summarize(folder: Path) -> None:
    """Print per-episode feature means' spread and their correlation matrix, episode lengths and success rate."""
    files = sorted(folder.glob("episode_*.npz"))
    if not files:
        raise SystemExit(f"no episode_*.npz in {folder}")
    means, lengths, successes = [], [], []
    for path in files:
        with np.load(path) as ep:
            means.append(step_features(ep["observations"], ep["actions"]).mean(axis=0))
            lengths.append(len(ep["actions"]))
            successes.append(bool(ep["success"]))
    m = np.array(means)
    print(f"{len(files)} episodes, lengths {min(lengths)}-{max(lengths)}, success rate {np.mean(successes):.1%}")
    print(f"{'feature (episode mean)':24s} {'min':>8s} {'max':>8s} {'mean':>8s} {'std':>8s}")
    for name, col in zip(FEATURES, m.T):
        print(f"{name:24s} {col.min():8.4f} {col.max():8.4f} {col.mean():8.4f} {col.std():8.4f}")
    print("Pearson r of the episode means:")
    corr = np.corrcoef(m.T)
    print(" " * 16 + "".join(f"{n[:14]:>16s}" for n in FEATURES))
    for name, row in zip(FEATURES, corr):
        print(f"{name[:16]:16s}" + "".join(f"{r:16.3f}" for r in row))


if __name__ == "__main__":
    summarize(Path(sys.argv[1] if len(sys.argv) > 1 else "data/own_robot_recording"))
