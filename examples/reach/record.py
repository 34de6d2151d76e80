"""Record reach episodes: a scripted Sawyer arm moving its hand toward a goal in Meta-World's `reach-v3`.

Like `examples/own_robot/record.py`, this stands in for a lab's own recording pipeline and knows nothing of langpref:
it writes `episode_NNNN.npz` (observations, actions, success) per episode, the plain recording layout that
`langpref import` reads (no camera video: this recording is for training and evaluating the latent space).

Each episode draws its own controller parameters from a seeded RNG, so the recording spans what a person watching
would comment on: how high the hand travels (`cruise`), how fast it moves (`max_step`, and a `jitter` that adds speed
without moving the hand far), and how close to the goal it ends up (`miss`, the distance of the end point from the
goal). Those are drawn independently of each other, and so is the episode's length, so some episodes stop before
the hand arrives and some hover at the end for a long time.

    MUJOCO_GL=egl .venv/bin/python examples/reach/record.py --out data/reach_recording --episodes 60

`--proprio` records as a lab without Meta-World's full state would: the observation keeps the hand position, the
gripper opening and the goal (7 numbers, no previous frame), and the per-step features are computed here from the
full observation and written into each episode (task file `task_proprio.toml`). `--target-actions` stores each action
as the absolute hand position commanded (x, y, z, grip), as position-controlled arms log it, instead of the move.
Together they leave speed visible only in how the observations change from step to step.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from features import step_features  # beside this script (the folder of the script run is on sys.path)

PROPRIO = np.r_[0:4, 36:39]  # hand position, gripper opening, goal
HAND_LOW, HAND_HIGH = np.array([-0.45, 0.40, 0.05]), np.array([0.45, 0.95, 0.40])


@dataclass(frozen=True)
class Plan:
    """One episode's scripted behaviour, drawn by `draw_plan`.

    The hand waits `wait` steps, moves to the height `cruise` where it is, travels at that height to above the end
    point, drops (or rises) onto it and hovers there, shaken by `jitter`, until `length` steps are recorded. The end
    point lies `miss` metres from the goal in a random direction. Moves are capped at `max_step` per step.
    """

    goal: tuple[float, float, float]
    length: int
    wait: int
    max_step: float  # largest commanded move per step, in action units (1 = 1 cm)
    cruise: float  # travel height (m)
    miss: float  # distance of the end point from the goal (m)
    direction: tuple[float, float, float]  # unit vector from the goal to the end point
    jitter: float  # amplitude of a move that flips sign every step while hovering (action units)
    noise: float  # std of Gaussian noise on every commanded move


def draw_plan(rng: np.random.Generator) -> Plan:
    """Draw an episode's parameters; the feature-driving ones (cruise, max_step, jitter, miss) independently."""
    direction = rng.normal(size=3)
    return Plan(
        goal=(float(rng.uniform(-0.1, 0.1)), float(rng.uniform(0.8, 0.9)), float(rng.uniform(0.05, 0.3))),
        length=int(rng.integers(60, 201)),
        wait=int(rng.integers(0, 21)),
        max_step=float(rng.uniform(0.15, 1.0)),
        cruise=float(rng.uniform(0.08, 0.35)),
        miss=float(rng.uniform(0.0, 0.25)),
        direction=tuple(float(x) for x in direction / np.linalg.norm(direction)),
        jitter=float(rng.uniform(0.0, 0.6)),
        noise=float(rng.uniform(0.0, 0.05)),
    )


class ReachScript:
    """Waypoint controller for `Plan`: wait -> level (to the cruise height) -> travel -> settle -> hover."""

    GAIN = 10.0  # action units per metre of error (0.1 m off -> a full 1 cm step)

    def __init__(self, plan: Plan, rng: np.random.Generator):
        self.plan = plan
        self._rng = rng
        self.phase = "wait"
        end = np.asarray(plan.goal) + plan.miss * np.asarray(plan.direction)
        self.end = np.clip(end, HAND_LOW, HAND_HIGH)

    def _target(self, hand: np.ndarray, t: int) -> np.ndarray:
        """The position to steer to at step t; advances the phase when its waypoint is reached."""
        p = self.plan
        if self.phase == "wait":
            if t < p.wait:
                return hand
            self.phase, self._start = "level", hand.copy()
        if self.phase == "level":
            level = np.array([self._start[0], self._start[1], p.cruise])
            if abs(hand[2] - p.cruise) > 0.01:
                return level
            self.phase = "travel"
        if self.phase == "travel":
            over = np.array([self.end[0], self.end[1], p.cruise])
            if np.linalg.norm((over - hand)[:2]) > 0.01:
                return over
            self.phase = "settle"
        if self.phase == "settle" and np.linalg.norm(self.end - hand) < 0.01:
            self.phase = "hover"
        return self.end

    def act(self, obs: np.ndarray, t: int) -> np.ndarray:
        """The 4-D Meta-World action (dx, dy, dz, grip effort) for observation `obs` at step t."""
        hand = obs[0:3].astype(np.float64)
        target = np.clip(self._target(hand, t), HAND_LOW, HAND_HIGH)
        move = np.clip(self.GAIN * (target - hand), -self.plan.max_step, self.plan.max_step)
        if self.phase == "hover":
            move = move + self.plan.jitter * (-1.0) ** t * np.asarray(self.plan.direction)
        if self.phase != "wait":
            move = move + self._rng.normal(0.0, self.plan.noise, size=3)
        return np.concatenate([np.clip(move, -1.0, 1.0), [-1.0]]).astype(np.float32)


def make_env():
    """Meta-World's reach env, built from its class so that the goal comes from our seed alone."""
    import metaworld  # noqa: F401  (registers Meta-World's envs)
    from metaworld.envs.sawyer_reach_v3 import SawyerReachEnvV3

    env = SawyerReachEnvV3()
    env.max_path_length = 10_000
    env._set_task_called = True  # we set the random reset vector ourselves, no Meta-World task object
    env._partially_observable = False  # observe the goal on every step...
    env.__dict__.pop("sawyer_observation_space", None)  # ...and drop the cached bounds that clip it to zeros
    return env


def record(env, seed: int, index: int, proprio: bool = False, target_actions: bool = False) -> dict[str, np.ndarray]:
    """Episode `index` of a recording seeded `seed`: observations, actions, success (and per-step features with
    `proprio`); see the module docstring for the two options."""
    rng = np.random.default_rng([seed, index])
    plan = draw_plan(rng)
    env._last_rand_vec = np.array([0.0, 0.6, 0.02, *plan.goal])  # the puck (unused) and the goal
    env._freeze_rand_vec = True
    env.seed(int(rng.integers(2**31)))
    obs, _ = env.reset()
    script = ReachScript(plan, rng)
    observations, actions, success = [], [], False
    for t in range(plan.length):
        action = script.act(obs, t)
        observations.append(obs.astype(np.float32))
        if target_actions:  # Meta-World moves the hand's target by action / 100 metres
            actions.append(np.concatenate([obs[0:3] + action[:3] / 100.0, action[3:]]).astype(np.float32))
        else:
            actions.append(action)
        obs, _, _, _, info = env.step(action)
        success = success or bool(info["success"])
    episode = {"observations": np.stack(observations), "actions": np.stack(actions), "success": np.bool_(success)}
    if proprio:
        episode["features"] = step_features(episode["observations"], episode["actions"])
        episode["observations"] = episode["observations"][:, PROPRIO]
    return episode


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("data/reach_recording"), help="output folder")
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--proprio", action="store_true", help="hand, gripper and goal only; features per step")
    parser.add_argument("--target-actions", action="store_true", help="actions as absolute hand targets")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    env, start, lengths, successes = make_env(), time.time(), [], []
    for i in range(args.episodes):
        ep = record(env, args.seed, i, args.proprio, args.target_actions)
        np.savez_compressed(args.out / f"episode_{i:04d}.npz", **ep)
        lengths.append(len(ep["actions"]))
        successes.append(bool(ep["success"]))
    env.close()
    print(
        f"recorded {args.episodes} episodes into {args.out} in {time.time() - start:.1f}s: lengths "
        f"{min(lengths)}-{max(lengths)} (mean {np.mean(lengths):.0f}), success {np.mean(successes):.0%}"
    )


if __name__ == "__main__":
    main()
