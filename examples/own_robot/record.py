"""Record "our own robot" episodes: a scripted Sawyer arm opening Meta-World's drawer (`drawer-open-v3`).

This script stands in for a lab's own recording pipeline. It knows nothing of langpref: it only writes, per episode,
`episode_NNNN.npz` (observations, actions, success) and `episode_NNNN.mp4` (a small camera video), the plain recording
layout that `langpref import` reads.

Each episode draws its own controller parameters from a seeded RNG, so the recording spans what a person watching
would comment on: how far the drawer is pulled out, which end of the handle the hand holds (left or right), and how
closed the gripper is. The parameters behind those three are drawn independently of each other, and the episode's
length is drawn too, so some episodes stop before the drawer is fully open.

    MUJOCO_GL=egl .venv/bin/python examples/own_robot/record.py --out data/own_robot_recording

The environment is built straight from Meta-World's class (not `gym.make`) so that the drawer position comes from our
seed alone and an episode is the same whichever worker records it.

`--hide-handle` records the robot as a lab without object tracking would: the observations keep only the arm's
proprioception (hand position and gripper opening, now and one step before; 8 numbers), the drawer's handle and the
goal are left out, and the three features are computed here from the full simulator state and written per step into
each episode (`features`). Where the hand holds the handle (`hand_sideways`) is then in the camera only; the hand also
backs straight off at the end instead of drifting to the side it held, which would tell the proprioception. Its task
file is `task_hidden.toml`; issue 19's observations experiment compares state and image models on it.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from features import step_features  # beside this script (the folder of the script run is on sys.path)

# Headless rendering. mujoco and metaworld are imported only inside `Recorder`, after these are set (also in the
# spawned workers, which import this module afresh).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("LP_NUM_THREADS", "1")  # Mesa's software rasterizer: one thread per worker; --workers scales

# Camera: in front of the drawer and to its left, looking at the handle, so that pulling the drawer out, the hand's
# position along the handle (left end on the left of the frame) and the fingers all show at 160x120.
CAMERA = {"lookat": (0.0, 0.66, 0.12), "distance": 0.75, "azimuth": 40.0, "elevation": -30.0}
WIDTH, HEIGHT = 160, 120  # even, and multiples of 8 so that ffmpeg does not resize
SIM_HZ = 80  # Meta-World steps per second (dt = 5 MuJoCo substeps of 2.5 ms)
FRAME_STRIDE = 2  # render every 2nd step: a 40 fps video
HAND_LOW, HAND_HIGH = np.array([-0.45, 0.42, 0.06]), np.array([0.45, 0.95, 0.40])
# --hide-handle keeps these columns of Meta-World's observation: hand position and gripper opening, now and before.
PROPRIOCEPTION = np.r_[0:4, 18:22]


@dataclass(frozen=True)
class Plan:
    """One episode's scripted behaviour, drawn by `draw_plan`.

    The hand waits, travels to a point `clearance` above the handle (shifted `offset` along it), drops onto the handle
    with the fingers open, pulls the drawer out by `pull`, holds still for `hold` steps, then lifts off and backs away
    (leaving the drawer where it is). Outside the drop and the lift the gripper is servoed to the opening `grip`
    (1 = wide open, about 0.3 = shut). Recording stops after `length` steps, wherever the script is by then.
    """

    handle_x: float  # where Meta-World places the drawer (its only random reset variable)
    length: int  # steps recorded
    wait: int  # steps standing still at the start
    max_step: float  # largest commanded move per step, in action units (1 = 1 cm)
    clearance: float  # travel height above the handle (m); under about 0.07 the fingers catch on the handle
    offset: float  # hand x minus handle-centre x while holding the handle (m); the bar spans about +-0.04
    pull: float  # how far the drawer is pulled out (m); Meta-World counts about 0.17 and more as success
    grip: float  # gripper opening to hold, as Meta-World observes it (obs[3])
    hold: int  # steps holding the drawer before letting go
    noise: float  # std of Gaussian noise on the commanded move


def draw_plan(rng: np.random.Generator) -> Plan:
    """Draw an episode's parameters; each feature-driving one (pull, offset, grip) independently and uniformly."""
    return Plan(
        handle_x=float(rng.uniform(-0.1, 0.1)),
        length=int(rng.integers(80, 201)),
        wait=int(rng.integers(0, 16)),
        max_step=float(rng.uniform(0.4, 1.0)),
        clearance=float(rng.uniform(0.08, 0.2)),
        offset=float(rng.uniform(-0.035, 0.035)),
        pull=float(rng.uniform(0.0, 0.2)),
        grip=float(rng.uniform(0.3, 1.0)),
        hold=int(rng.integers(10, 80)),
        noise=float(rng.uniform(0.0, 0.08)),
    )


class DrawerScript:
    """Closed-loop waypoint controller for `Plan`: a phase machine that steers the hand with a clipped P-controller.

    Phases: wait -> above (travel over the handle) -> drop (onto it, fingers open) -> pull (until the handle has moved
    `pull`) -> hold (keep the hand where the pull ended) -> lift (straight up, off the handle) -> away (back off).
    """

    GAIN = 10.0  # position gain, action units per metre of error (0.1 m off -> full 1 cm step)
    SLOW_STEP = 0.4  # cap on the move per step while pulling or letting go: the drawer glides on if jerked
    GRIP_GAIN = 1.5  # gripper servo gain on the observed opening (higher gains ring: the fingers have inertia)
    HOOK_DZ = -0.02  # drop the hand this far below the handle's centre to hook it (as Meta-World's expert does)
    CLOSED_HANDLE_Y = 0.73  # handle y with the drawer shut (the drawer case is always at y = 0.9)

    def __init__(self, plan: Plan, rng: np.random.Generator, drift: bool = True):
        self.plan = plan
        self._rng = rng
        self.drift = drift  # back off towards the side the handle was held on (else straight back)
        self.phase = "wait"
        self._phase_t = 0  # step at which the current phase began
        self._anchor = np.zeros(3)  # a fixed world point the current phase steers to, set on entering it

    def _enter(self, phase: str, t: int, anchor: np.ndarray | None = None) -> None:
        self.phase, self._phase_t = phase, t
        if anchor is not None:
            self._anchor = anchor

    def _target(self, hand: np.ndarray, handle: np.ndarray, t: int) -> np.ndarray:
        """The hand position to steer to at step t; advances the phase when its goal is reached (or times out)."""
        p = self.plan
        hook = handle + np.array([p.offset, 0.0, self.HOOK_DZ])
        if self.phase == "wait":
            if t < p.wait:
                return hand
            self._enter("above", t)
        if self.phase == "above":
            above = hook + np.array([0.0, 0.0, p.clearance - self.HOOK_DZ])
            if np.linalg.norm((above - hand)[:2]) > 0.012 and t - self._phase_t < 80:
                return above
            self._enter("drop", t)
        if self.phase == "drop":
            if abs(hook[2] - hand[2]) > 0.012 and t - self._phase_t < 40:
                return hook
            self._enter("pull", t)
        if self.phase == "pull":
            # Move the hand by what the handle still has to travel: closes the loop on the drawer, not the hand.
            remaining = (self.CLOSED_HANDLE_Y - p.pull) - handle[1]
            if remaining < -0.005 and t - self._phase_t < 80:
                return np.array([handle[0] + p.offset, hand[1] + remaining, hook[2]])
            self._enter("hold", t, anchor=hand.copy())
        if self.phase == "hold":
            if t - self._phase_t < p.hold:
                return self._anchor
            self._enter("lift", t, anchor=hand + np.array([0.0, 0.0, p.clearance + 0.05]))
        if self.phase == "lift":
            if abs(self._anchor[2] - hand[2]) > 0.015 and t - self._phase_t < 40:
                return self._anchor
            # Back off towards the robot, drifting further to the side the hand held the handle on.
            side = 2.0 * p.offset if self.drift else 0.0
            self._enter("away", t, anchor=hand + np.array([side, -0.1, 0.0]))
        return self._anchor

    def act(self, obs: np.ndarray, t: int) -> np.ndarray:
        """The 4-D Meta-World action (dx, dy, dz, grip effort) for observation `obs` at step t."""
        hand, handle = obs[0:3].astype(np.float64), obs[4:7].astype(np.float64)
        target = np.clip(self._target(hand, handle, t), HAND_LOW, HAND_HIGH)
        cap = min(self.plan.max_step, self.SLOW_STEP) if self.phase in ("pull", "lift") else self.plan.max_step
        move = np.clip(self.GAIN * (target - hand), -cap, cap)
        if self.phase != "wait":
            move = move + self._rng.normal(0.0, self.plan.noise, size=3)
        # Fingers wide open while dropping onto the handle (so that they straddle the bar) and while lifting off it
        # (so that they let go of it cleanly); otherwise servo the observed opening to the plan's. Positive effort
        # closes the fingers.
        if self.phase in ("drop", "lift"):
            effort = -1.0
        else:
            effort = float(np.clip(self.GRIP_GAIN * (obs[3] - self.plan.grip), -1.0, 1.0))
        return np.concatenate([np.clip(move, -1.0, 1.0), [effort]]).astype(np.float32)


class Recorder:
    """One Meta-World drawer-open env plus an offscreen renderer; records whole episodes from their index."""

    def __init__(self, video: bool, hide_handle: bool = False):
        import metaworld  # noqa: F401  (registers Meta-World's envs)
        from metaworld.envs.sawyer_drawer_open_v3 import SawyerDrawerOpenEnvV3

        env = SawyerDrawerOpenEnvV3()
        env.max_path_length = 10_000
        env._set_task_called = True  # we set the random reset vector ourselves, no Meta-World task object
        env._partially_observable = False  # observe the goal too...
        env.__dict__.pop("sawyer_observation_space", None)  # ...and drop the cached bounds that clip it to zeros
        self.env = env
        self.hide_handle = hide_handle
        self.renderer: Any = None
        self.camera: Any = None
        self.scene_option: Any = None
        if video:
            import mujoco

            # Software EGL (Mesa) on a CPU: shadows, reflections and multisampling cost about 8x the frame time
            # and add little at 160x120, so they are off.
            env.model.vis.quality.shadowsize = 0
            env.model.vis.quality.offsamples = 0
            self.renderer = mujoco.Renderer(env.model, height=HEIGHT, width=WIDTH)
            self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            self.camera = mujoco.MjvCamera()
            self.camera.lookat[:] = CAMERA["lookat"]
            self.camera.distance = CAMERA["distance"]
            self.camera.azimuth = CAMERA["azimuth"]
            self.camera.elevation = CAMERA["elevation"]
            self.scene_option = mujoco.MjvOption()
            self.scene_option.sitegroup[:] = 0  # hide Meta-World's goal marker: a real camera would not see it

    def _frame(self) -> np.ndarray:
        self.renderer.update_scene(self.env.data, camera=self.camera, scene_option=self.scene_option)
        # mujoco.Renderer already returns rows top-first (checked: the table is at the bottom of the frame).
        return self.renderer.render().copy()

    def record(self, seed: int, index: int) -> dict[str, Any]:
        """Run episode `index` of a recording seeded `seed`; returns its arrays and video frames."""
        rng = np.random.default_rng([seed, index])
        plan = draw_plan(rng)
        env = self.env
        env._last_rand_vec = np.array([plan.handle_x, 0.9, 0.0])
        env._freeze_rand_vec = True
        env.seed(int(rng.integers(2**31)))
        obs, _ = env.reset()
        script = DrawerScript(plan, rng, drift=not self.hide_handle)
        observations, actions, frames = [], [], []
        success = False
        for t in range(plan.length):
            if self.renderer is not None and t % FRAME_STRIDE == 0:
                frames.append(self._frame())
            action = script.act(obs, t)
            observations.append(obs.astype(np.float32))
            actions.append(action)
            obs, _, _, _, info = env.step(action)
            success = success or bool(info["success"])
        obs_all, act = np.stack(observations), np.stack(actions)
        episode = {"observations": obs_all, "actions": act, "success": np.bool_(success), "frames": frames}
        if self.hide_handle:
            episode["features"] = step_features(obs_all, act)  # from the full state, before the handle is dropped
            episode["observations"] = obs_all[:, PROPRIOCEPTION]
        return episode

    def close(self) -> None:
        if self.renderer is not None:
            self.renderer.close()  # explicitly, before the EGL context is torn down at exit
        self.env.close()


def write_video(frames: list[np.ndarray], path: Path) -> None:
    """H.264 in yuv420p (plays in every browser); written under a temporary name and moved, so no half file remains."""
    import imageio.v2 as imageio

    tmp = path.with_name(f".{path.stem}.tmp.mp4")  # hidden: no reader's episode_* pattern picks it up
    writer = imageio.get_writer(
        tmp,
        fps=SIM_HZ // FRAME_STRIDE,
        codec="libx264",
        pixelformat="yuv420p",
        macro_block_size=8,
        ffmpeg_log_level="error",
    )
    for frame in frames:
        writer.append_data(frame)
    writer.close()
    tmp.replace(path)


_RECORDER: Recorder | None = None


def _init_worker(video: bool, hide_handle: bool) -> None:
    global _RECORDER
    _RECORDER = Recorder(video, hide_handle)


def _record_one(job: tuple[int, int, str]) -> tuple[int, int, bool]:
    """Record and save one episode (in a worker); returns (index, length, success)."""
    seed, index, out = job
    assert _RECORDER is not None
    ep = _RECORDER.record(seed, index)
    stem = Path(out) / f"episode_{index:04d}"
    tmp = stem.with_name(f".{stem.name}.tmp.npz")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **{k: v for k, v in ep.items() if k != "frames"})
    tmp.replace(stem.with_suffix(".npz"))
    if ep["frames"]:
        write_video(ep["frames"], stem.with_suffix(".mp4"))
    return index, len(ep["actions"]), bool(ep["success"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("data/own_robot_recording"), help="output folder")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-video", action="store_true", help="write only the .npz files")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        "--hide-handle",
        action="store_true",
        help="observations without the handle and goal (the arm's proprioception only), features written per episode",
    )
    args = parser.parse_args(argv)

    args.out.mkdir(parents=True, exist_ok=True)
    jobs = [(args.seed, i, str(args.out)) for i in range(args.episodes)]
    start = time.time()
    if args.workers <= 1:
        _init_worker(not args.no_video, args.hide_handle)
        results = [_record_one(job) for job in jobs]
        assert _RECORDER is not None
        _RECORDER.close()
    else:
        # spawn: each worker makes its own EGL context; nothing GL-related is inherited from this process
        with mp.get_context("spawn").Pool(args.workers, _init_worker, (not args.no_video, args.hide_handle)) as pool:
            results = list(pool.imap_unordered(_record_one, jobs, chunksize=4))
        # (leaving the block terminates the workers, renderers and all; nothing is left to flush)
    lengths = np.array([n for _, n, _ in results])
    successes = np.array([s for _, _, s in results])
    print(
        f"recorded {len(results)} episodes into {args.out} in {time.time() - start:.1f}s: "
        f"lengths {lengths.min()}-{lengths.max()} (mean {lengths.mean():.0f}), success {successes.mean():.0%}"
    )


if __name__ == "__main__":
    main()
