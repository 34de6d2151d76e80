"""Generate a trajectory dataset: scripted controllers, parameters stratified by Latin hypercube, rolled out in the
real simulator by parallel worker processes.

The paper trains RL policies for reward weights drawn by stratified sampling so that the rollouts span every feature.
We reach the same coverage within a CPU budget: each env ships a closed-loop waypoint controller with a dozen
parameters, and one Latin hypercube row per trajectory sets them (see each env module for what they mean).

Determinism: the hypercube and every trajectory's seeds derive from `seed` alone, and each trajectory is rolled out
independently (a reused env carries nothing from one episode into the next), so the dataset is identical whatever the
number of workers, the order they take the trajectories in, or the BLAS threads. It is not identical across CPUs
for every task: robosuite's arm controller (OSC) does its linear algebra through numpy's BLAS, whose kernel OpenBLAS
picks at run time for the CPU, and contacts amplify the last-bit differences (with the kernel forced from SkylakeX to
Haswell or Nehalem, trajectory 3 of the default robosuite data drifts by up to 0.27 in an observation; Meta-World's
rollouts, which use no BLAS, stay bit-identical). `made_with` in meta.json's config records the stack and the kernel;
`langpref inspect` prints the checksum that tells two datasets apart.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from langpref.backends import Backend, run_jobs
from langpref.dataset.frames import FrameOptions, FrameSpec, load_frames, render_trajectory_frames, save_frames
from langpref.dataset.storage import (
    DatasetMeta,
    Trajectory,
    load_trajectory,
    save_trajectory,
    shuffle_into_splits,
    trajectory_path,
    write_meta,
)
from langpref.errors import LangprefError
from langpref.tasks import get_simulator, get_task
from langpref.tasks.base import Task


@dataclass(frozen=True)
class GenerateConfig:
    env: str
    """Task with a simulator: metaworld, robosuite, or a plugin's task (see `langpref tasks`)."""
    out: Path
    """Dataset directory to create."""
    num_trajectories: int | None = None
    """Number of rollouts; default the task's (the paper's 324 metaworld, 448 robosuite)."""
    horizon: int | None = None
    """Steps per rollout; default the paper's T = 500."""
    workers: int | None = None
    """Worker processes; default all cores."""
    seed: int = 0
    """Master seed: the same seed gives the same dataset."""
    force: bool = False
    """Overwrite an existing dataset."""
    backend: Backend = "local"
    """Where the rollouts run: local worker processes, or Ray tasks, one per chunk of trajectories (pip install
    'langpref[ray]')."""
    ray_address: str | None = None
    """With --backend ray: a running cluster to join (e.g. auto or HOST:6379); default a local instance."""
    frames: FrameOptions = field(default_factory=FrameOptions)
    """Camera frames (--images, --frame-size, --frame-stride), rendered from each trajectory's simulator states."""

    @property
    def frame_spec(self) -> FrameSpec | None:
        """The frames the dataset keeps, rendered from the simulator states; None without --images."""
        return self.frames.spec("render")

    def resolved(self) -> GenerateConfig:
        sim = get_simulator(self.env)
        cfg = GenerateConfig(
            env=self.env,
            out=Path(self.out),
            num_trajectories=sim.default_num_trajectories if self.num_trajectories is None else self.num_trajectories,
            horizon=sim.default_horizon if self.horizon is None else self.horizon,
            workers=(os.cpu_count() or 1) if self.workers is None else self.workers,
            seed=self.seed,
            force=self.force,
            backend=self.backend,
            ray_address=self.ray_address,
            frames=self.frames,
        )
        self.frames.validate()
        if cfg.num_trajectories < 3:
            raise LangprefError("--num-trajectories must be at least 3 (one per split)")
        if cfg.horizon < 2:
            raise LangprefError("--horizon must be at least 2")
        if cfg.workers < 1:
            raise LangprefError("--workers must be at least 1")
        return cfg

    def identity(self) -> dict[str, Any]:
        """What fixes the dataset's content (not where or how fast it is made): the env and its simulator's version
        (`Simulator.version`: data made before a change of the env is recognisable, and never resumed into), frames
        only when there are some."""
        out: dict[str, Any] = {
            "env": self.env,
            "env_version": get_simulator(self.env).version,
            "num_trajectories": self.num_trajectories,
            "horizon": self.horizon,
            "seed": self.seed,
        }
        spec = self.frame_spec
        if spec is not None:
            out["frames"] = spec.to_dict()
        return out


def split_sizes(env: str, n: int) -> dict[str, int]:
    """The paper's split sizes for the default n, the same proportions otherwise (at least one per split)."""
    train, val, test = get_task(env).default_splits
    total = train + val + test
    n_val = max(1, round(n * val / total))
    n_test = max(1, round(n * test / total))
    return {"train": n - n_val - n_test, "val": n_val, "test": n_test}


def assign_splits(env: str, n: int, seed: int) -> dict[str, list[int]]:
    return shuffle_into_splits(n, split_sizes(env, n), seed)


def controller_units(env: str, n: int, seed: int) -> np.ndarray:
    """One Latin hypercube row per trajectory: stratified cover of the controller's parameter space."""
    from scipy.stats import qmc

    dim = get_simulator(env).controller_dim
    return qmc.LatinHypercube(d=dim, seed=np.random.default_rng([seed, 2])).random(n)


def trajectory_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, 3, index]).generate_state(1)[0])


def rollout(env: Any, task: Task, unit: np.ndarray, traj_seed: int, horizon: int, index: int) -> Trajectory:
    """Roll out one controller for `horizon` steps, recording what the dataset stores."""
    controller = task.simulator.make_controller(unit, np.random.default_rng(traj_seed))
    obs = env.reset(traj_seed)
    observations = np.zeros((horizon, task.obs_dim), np.float32)
    actions = np.zeros((horizon, task.action_dim), np.float32)
    features = np.zeros((horizon, len(task.features)), np.float32)
    qpos0, qvel0 = env.get_state()
    qpos = np.zeros((horizon, len(qpos0)))
    qvel = np.zeros((horizon, len(qvel0)))
    for t in range(horizon):
        observations[t] = obs
        qpos[t], qvel[t] = env.get_state()
        actions[t] = controller.act(env, obs, t)
        obs = env.step(actions[t])
        features[t] = env.step_features()
    return Trajectory(
        index=index,
        observations=observations,
        actions=actions,
        step_features=features,
        qpos=qpos,
        qvel=qvel,
        success=env.is_success(),
        seed=traj_seed,
        controller_params=controller.params,
    )


# ---- parallel rollouts ---------------------------------------------------------------------------------------------


def make_worker_env(env_name: str, horizon: int) -> tuple[Any, Any]:
    import warnings

    warnings.filterwarnings("ignore")
    os.environ.setdefault("MUJOCO_GL", "egl")
    task = get_task(env_name)
    return task, get_simulator(env_name).make_env(horizon)


def _rollout_job(
    state: tuple[Task, Any], job: tuple[int, np.ndarray, int, int, FrameSpec | None]
) -> tuple[Trajectory, np.ndarray | None]:
    """One rollout, and its camera frames when the dataset keeps them (replayed after it, in the same env)."""
    task, env = state
    index, unit, traj_seed, horizon, spec = job
    traj = rollout(env, task, unit, traj_seed, horizon, index)
    return traj, None if spec is None else render_trajectory_frames(env, traj, spec)


def made_with(env: str) -> dict[str, Any]:
    """The numerical stack that made the trajectories (provenance, not content): machine, Python, numpy, scipy (its
    Latin hypercube draws the controllers), MuJoCo and the simulator's package versions, and numpy's BLAS with the
    kernel it chose for this CPU (needs threadpoolctl; absent without it)."""
    import platform
    from importlib import metadata

    out: dict[str, Any] = {"machine": platform.machine(), "python": platform.python_version()}
    for package in ("numpy", "scipy", "mujoco", get_simulator(env).extra):
        try:
            out[package] = metadata.version(package) if package else None
        except metadata.PackageNotFoundError:
            pass
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return {k: v for k, v in out.items() if v is not None}
    blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    mine = [i for i in blas if "numpy" in str(i.get("filepath", ""))] or blas
    if mine:
        out["blas"] = f"{mine[0].get('internal_api')} {mine[0].get('version')} {mine[0].get('architecture')}"
    return {k: v for k, v in out.items() if v is not None}


def _prepare_out(cfg: GenerateConfig) -> None:
    """Create the output dir, refusing to clobber a finished dataset and resuming an interrupted identical run."""
    out = cfg.out
    stamp = out / "generate_config.json"
    if (out / "meta.json").exists() and not cfg.force:
        raise LangprefError(f"{out} already holds a dataset; pass --force to overwrite it or choose another --out")
    if out.exists() and cfg.force:
        shutil.rmtree(out)
    if out.exists() and any(out.iterdir()):
        if not stamp.exists() or json.loads(stamp.read_text()) != cfg.identity():
            raise LangprefError(
                f"{out} exists and is not an interrupted run of the same generation; choose another --out"
            )
    out.mkdir(parents=True, exist_ok=True)
    stamp.write_text(json.dumps(cfg.identity()) + "\n")


def _finished(cfg: GenerateConfig, index: int) -> tuple[np.ndarray, bool] | None:
    """Features and success of a trajectory an interrupted run already wrote, if it reads back whole."""
    if not trajectory_path(cfg.out, index).exists():
        return None
    meta = DatasetMeta.of_task(get_task(cfg.env), cfg.horizon, {}, cfg.num_trajectories)
    try:
        traj = load_trajectory(cfg.out, index, meta)
        if cfg.frame_spec is not None:
            load_frames(cfg.out, index, cfg.frame_spec, cfg.horizon)
    except LangprefError:
        return None
    return traj.features, traj.success


def _roll_out(cfg: GenerateConfig, jobs: list, features: np.ndarray, success: np.ndarray) -> None:
    """Run the rollouts of `jobs` on the backend and store each trajectory as it arrives, filling its row of
    `features` and `success`."""
    n = len(success)
    bar = tqdm(total=n, initial=n - len(jobs), desc=f"generate {cfg.env}", unit="traj", dynamic_ncols=True)
    results = run_jobs(
        _rollout_job,
        jobs,
        setup=make_worker_env,
        setup_args=(cfg.env, cfg.horizon),
        backend=cfg.backend,
        workers=cfg.workers,
        ray_address=cfg.ray_address,
        chunk=4,
    )
    for traj, frames in results:
        if frames is not None:  # frames first: a trajectory file without its frames would pass for finished
            save_frames(cfg.out, traj.index, frames)
        save_trajectory(cfg.out, traj)  # one file per trajectory, written as it arrives: a rerun skips it
        features[traj.index], success[traj.index] = traj.features, traj.success
        bar.update(1)
        bar.set_postfix(success=f"{success.sum() / bar.n:.0%}")
    bar.close()


def generate(cfg: GenerateConfig) -> dict[str, Any]:
    """Generate and store a dataset; returns a summary. Interrupted runs resume where they stopped."""
    cfg = cfg.resolved()
    task = get_task(cfg.env)
    spec = cfg.frame_spec
    _prepare_out(cfg)
    n = cfg.num_trajectories
    units = controller_units(cfg.env, n, cfg.seed)
    features = np.zeros((n, len(task.features)))
    success = np.zeros(n, bool)
    jobs = []
    for i in range(n):
        done = _finished(cfg, i)
        if done is None:
            jobs.append((i, units[i], trajectory_seed(cfg.seed, i), cfg.horizon, spec))
        else:
            features[i], success[i] = done
    start = time.time()
    _roll_out(cfg, jobs, features, success)
    wall = time.time() - start
    meta = DatasetMeta.of_task(
        task,
        cfg.horizon,
        assign_splits(cfg.env, n, cfg.seed),
        n,
        config={
            **cfg.identity(),
            "generator": "latin-hypercube waypoint controllers",
            "wall_s": round(wall, 1),
            "workers": cfg.workers,
            "backend": cfg.backend,
            "success_rate": float(success.mean()),
            "made_with": made_with(cfg.env),
        },
        frames=None if spec is None else spec.to_dict(),
    )
    write_meta(cfg.out, meta, features)
    return {
        "out": str(cfg.out),
        "env": cfg.env,
        "num_trajectories": n,
        "horizon": cfg.horizon,
        "success_rate": float(success.mean()),
        "wall_s": wall,
        "workers": cfg.workers,
        "backend": cfg.backend,
        "steps_per_s": len(jobs) * cfg.horizon / wall if jobs else None,
        **({} if spec is None else {"frames": spec.to_dict()}),
    }
