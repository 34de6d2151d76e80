"""On-disk trajectory datasets: one compressed `.npz` per trajectory plus `meta.json` and a feature table.

Layout of a dataset directory (schema 2; schema 3 when it holds camera frames):

    meta.json              schema version, task (`env`), horizon (the longest episode), per-trajectory lengths when
                           they differ, observation layout, feature names, splits, how it was made
    features.npy           (N, F) trajectory features theta(tau) (per-step features averaged over time)
    trajectories/000123.npz  observations (T, obs_dim), actions (T, A), step_features (T, F), success (), and when
                             the trajectory was simulated: qpos (T, nq), qvel (T, nv), seed (), controller_params
                             (JSON string); when it was recorded: source (the recording's episode name)
    videos/000123.mp4      the recorded camera video of a trajectory (recorded datasets; simulated ones re-render)
    frames/000123.npz      small camera frames of a trajectory, every k-th step (`generate --images`, `import
                           --images`; see `langpref.dataset.frames`), read only by models that see images
    task.json, utterances.json   the task and its bank, for a recorded task (see `langpref.tasks.taskfile`)

Schema-1 datasets (every trajectory simulated, all of one length) load unchanged. A dataset with frames is written
as schema 3, so an older langpref refuses it with its version message instead of misreading it; one without frames
is written exactly as before (schema 2). Every load checks what it reads
and fails with a one-line `LangprefError` saying what is wrong.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from langpref.dataset.frames import FrameSpec, load_frames, stack_frames
from langpref.dataset.splits import SPLITS
from langpref.errors import LangprefError
from langpref.tasks import register_task
from langpref.tasks.taskfile import load_stored_task

SCHEMA_VERSION = 2
FRAMES_SCHEMA_VERSION = 3
READABLE_SCHEMAS = (1, 2, 3)
_ARRAYS = ("observations", "actions", "step_features")
_STATE = ("qpos", "qvel")


@dataclass
class Trajectory:
    """One trajectory. `step_features[t]` is theta(s_t, a_t); `qpos/qvel[t]` is the simulator state at step t (None
    for a recorded trajectory, whose `source` names the recording's episode)."""

    index: int
    observations: np.ndarray
    actions: np.ndarray
    step_features: np.ndarray
    qpos: np.ndarray | None
    qvel: np.ndarray | None
    success: bool
    seed: int | None
    controller_params: dict[str, Any] = field(default_factory=dict)
    source: str | None = None

    @property
    def features(self) -> np.ndarray:
        """theta(tau): the per-step features averaged over the trajectory."""
        return self.step_features.mean(axis=0)

    @property
    def horizon(self) -> int:
        return len(self.actions)


@dataclass
class DatasetMeta:
    env: str
    horizon: int
    obs_layout: list[dict[str, Any]]  # [{"name", "start", "stop"}, ...]
    action_dim: int
    feature_names: list[str]
    splits: dict[str, list[int]]
    num_trajectories: int
    config: dict[str, Any] = field(default_factory=dict)
    schema_version: int = SCHEMA_VERSION
    lengths: list[int] | None = None
    """Steps of each trajectory when they differ (recordings); None when every one has `horizon` steps."""
    videos: bool = False
    """Whether every trajectory has a recorded video under `videos/` (else videos are rendered from the state)."""
    frames: dict[str, Any] | None = None
    """The camera frames under `frames/` (`FrameSpec`: width, height, stride, source), None when it has none."""

    @classmethod
    def of_task(
        cls, task: Any, horizon: int, splits: dict[str, list[int]], num_trajectories: int, **more: Any
    ) -> DatasetMeta:
        """The meta of a dataset made in `task`'s simulator: the task's name, observation layout, action size and
        features, written once for every maker of such datasets (`more`: config, frames)."""
        layout = [asdict(f) for f in task.obs_layout]
        features = list(task.features)
        return cls(task.name, horizon, layout, task.action_dim, features, splits, num_trajectories, **more)

    @property
    def obs_dim(self) -> int:
        return int(self.obs_layout[-1]["stop"])

    def length(self, index: int) -> int:
        return self.horizon if self.lengths is None else int(self.lengths[index])


def shuffle_into_splits(n: int, sizes: dict[str, int], seed: int) -> dict[str, list[int]]:
    """Trajectory indices 0..n-1 dealt into the splits at random (seeded), `sizes[split]` each, sorted per split."""
    order = np.random.default_rng([seed, 1]).permutation(n)
    out, start = {}, 0
    for name in SPLITS:
        out[name] = sorted(int(i) for i in order[start : start + sizes[name]])
        start += sizes[name]
    return out


def trajectory_path(root: Path, index: int) -> Path:
    return Path(root) / "trajectories" / f"{index:06d}.npz"


def save_trajectory(root: Path, traj: Trajectory) -> Path:
    """Write one trajectory atomically (a temp file renamed into place), so a crash never leaves half a file."""
    path = trajectory_path(root, traj.index)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    arrays = {name: getattr(traj, name) for name in _ARRAYS}
    if traj.qpos is not None and traj.qvel is not None:
        arrays.update(qpos=traj.qpos, qvel=traj.qvel)
    arrays["success"] = np.asarray(traj.success)
    if traj.seed is not None:
        arrays["seed"] = np.asarray(traj.seed)
    arrays["controller_params"] = np.asarray(json.dumps(traj.controller_params))
    if traj.source is not None:
        arrays["source"] = np.asarray(traj.source)
    np.savez_compressed(tmp, **arrays)
    tmp.replace(path)
    return path


def write_text_atomic(path: Path, text: str) -> None:
    """Write `path` through a temporary file renamed over it: a crash leaves the old file or the new, never half."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def write_meta(root: Path, meta: DatasetMeta, features: np.ndarray) -> None:
    """Write features.npy, then meta.json (each atomically, so a dataset rewritten after every trajectory, as a
    store of generated ones is, survives a crash mid-write); a dataset with frames as schema 3, one without exactly
    as before."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    tmp = root / "features.tmp.npy"
    np.save(tmp, features.astype(np.float64))
    tmp.replace(root / "features.npy")
    raw = asdict(meta)
    if meta.frames is None:
        del raw["frames"]
    else:
        raw["schema_version"] = max(meta.schema_version, FRAMES_SCHEMA_VERSION)
    write_text_atomic(root / "meta.json", json.dumps(raw, indent=2) + "\n")


def _read_meta(root: Path) -> DatasetMeta:
    path = root / "meta.json"
    if not root.exists():
        raise LangprefError(
            f"dataset {root} does not exist: create one with `langpref generate --env ENV --out {root}`"
        )
    if not path.is_file():
        raise LangprefError(f"{root} is not a langpref dataset (no meta.json); create one with `langpref generate`")
    try:
        raw = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{path} is corrupt (not valid JSON: {exc}); regenerate the dataset") from None
    version = raw.get("schema_version") if isinstance(raw, dict) else None
    if version not in READABLE_SCHEMAS:
        raise LangprefError(
            f"{path} has dataset schema version {version!r}, this langpref reads versions "
            f"{', '.join(map(str, READABLE_SCHEMAS))}; regenerate the dataset with this version"
        )
    try:
        meta = DatasetMeta(**raw)
    except TypeError as exc:
        raise LangprefError(f"{path} is not a valid dataset description ({exc}); regenerate the dataset") from None
    if meta.lengths is not None and (len(meta.lengths) != meta.num_trajectories or max(meta.lengths) != meta.horizon):
        raise LangprefError(f"{path}: 'lengths' must give one length per trajectory, the longest equal to 'horizon'")
    if meta.frames is not None:
        FrameSpec.from_dict(meta.frames, str(path))
    return meta


class Dataset:
    """A dataset on disk. Trajectories load lazily; `features` and `meta` are read at open."""

    def __init__(self, root: Path, meta: DatasetMeta, features: np.ndarray):
        self.root = Path(root)
        self.meta = meta
        self.features = features

    @property
    def env(self) -> str:
        return self.meta.env

    @property
    def feature_names(self) -> list[str]:
        return list(self.meta.feature_names)

    def __len__(self) -> int:
        return self.meta.num_trajectories

    def split(self, name: str) -> list[int]:
        """Indices of the trajectories of one split (`train`, `val`, `test`)."""
        if name not in self.meta.splits:
            raise LangprefError(f"dataset {self.root} has no split {name!r}; it has {', '.join(self.meta.splits)}")
        return list(self.meta.splits[name])

    def load(self, index: int) -> Trajectory:
        return load_trajectory(self.root, index, self.meta)

    def episode_names(self) -> list[str | None]:
        """The recording's episode name of each trajectory (`source`; None for a simulated one), read from disk."""
        return [self.load(i).source for i in range(len(self))]

    def trajectories(self, split: str | None = None) -> list[Trajectory]:
        indices = range(len(self)) if split is None else self.split(split)
        return [self.load(i) for i in indices]

    def arrays(self, split: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(observations (N, T, obs_dim), actions (N, T, A)) of a split (every trajectory when None), stacked,
        float32. Shorter trajectories are padded to the horizon by repeating their last step: `lengths` says how
        many steps are real, and the encoder averages over those only."""
        trajs = self.trajectories(split)
        return stack_steps([t.observations for t in trajs]), stack_steps([t.actions for t in trajs])

    def lengths(self, split: str | None = None) -> np.ndarray | None:
        """Steps of each trajectory of a split, or None when they all have `horizon` steps."""
        if self.meta.lengths is None:
            return None
        indices = range(len(self)) if split is None else self.split(split)
        return np.array([self.meta.lengths[i] for i in indices], dtype=np.int64)

    @property
    def frame_spec(self) -> FrameSpec | None:
        """The camera frames this dataset holds (size, stride, source), or None when it has none."""
        return None if self.meta.frames is None else FrameSpec.from_dict(self.meta.frames, str(self.root))

    def frames(self, split: str | None = None) -> np.ndarray:
        """Camera frames (N, K, height, width, 3) uint8 of a split (every trajectory when None), read from disk now;
        shorter trajectories are padded with their last frame. Frame k shows step k * stride."""
        spec = self.frame_spec
        if spec is None:
            raise LangprefError(
                f"dataset {self.root} has no camera frames; make one with `langpref generate --images` or "
                "`langpref import --images` (a recording with videos or camera images)"
            )
        indices = range(len(self)) if split is None else self.split(split)
        return stack_frames([load_frames(self.root, i, spec, self.meta.length(i)) for i in indices])

    def video_path(self, index: int) -> Path | None:
        """The recorded video of a trajectory, or None when videos are rendered from the simulator state."""
        return video_path(self.root, index) if self.meta.videos else None

    @cached_property
    def success(self) -> np.ndarray:
        return np.array([self.load(i).success for i in range(len(self))], dtype=bool)


def stack_steps(arrays: list[np.ndarray]) -> np.ndarray:
    """(N, T, d) float32 of per-step arrays (T_i, d), the shorter ones padded to the longest with their last step
    (the padding `stack_frames` gives frames)."""
    return stack_frames(arrays).astype(np.float32)


def video_path(root: Path, index: int) -> Path:
    return Path(root) / "videos" / f"{index:06d}.mp4"


def load_trajectory(root: Path, index: int, meta: DatasetMeta) -> Trajectory:
    path = trajectory_path(root, index)
    if not path.is_file():
        raise LangprefError(f"dataset {root} is incomplete: {path.name} is missing; regenerate the dataset")
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise LangprefError(f"{path} is truncated or corrupt ({type(exc).__name__}); regenerate the dataset") from None
    required = (*_ARRAYS, "success", *(("seed", "controller_params", *_STATE) if meta.schema_version == 1 else ()))
    missing = [k for k in required if k not in data]
    if missing:
        raise LangprefError(f"{path} lacks {', '.join(missing)}; regenerate the dataset")
    obs, act, feats = data["observations"], data["actions"], data["step_features"]
    steps = meta.length(index)
    if obs.shape != (steps, meta.obs_dim) or act.shape != (steps, meta.action_dim):
        raise LangprefError(
            f"{path} has observations {obs.shape} and actions {act.shape}, meta.json says {steps} steps, "
            f"obs {meta.obs_dim}, action {meta.action_dim}; the dataset is mixed up, regenerate it"
        )
    if feats.shape != (steps, len(meta.feature_names)):
        raise LangprefError(f"{path} has step_features {feats.shape}, inconsistent with meta.json; regenerate it")
    return Trajectory(
        index=index,
        observations=obs,
        actions=act,
        step_features=feats,
        qpos=data.get("qpos"),
        qvel=data.get("qvel"),
        success=bool(data["success"]),
        seed=int(data["seed"]) if "seed" in data else None,
        controller_params=json.loads(str(data["controller_params"])) if "controller_params" in data else {},
        source=str(data["source"]) if "source" in data else None,
    )


def load_dataset(root: str | Path, env: str | None = None) -> Dataset:
    """Open a dataset; with `env`, also check it is a dataset of that task. A dataset that carries its task (a
    recorded one) registers it, so the task is known by name to every later step."""
    root = Path(root)
    meta = _read_meta(root)
    stored = load_stored_task(root)
    if stored is not None:
        register_task(stored)
    if env is not None and meta.env != env:
        raise LangprefError(f"dataset {root} is a {meta.env} dataset, but {env} was asked for")
    fpath = root / "features.npy"
    try:
        features = np.load(fpath, allow_pickle=False)
    except FileNotFoundError:
        raise LangprefError(f"dataset {root} is incomplete: features.npy is missing; regenerate the dataset") from None
    except (ValueError, OSError, EOFError) as exc:
        raise LangprefError(f"{fpath} is truncated or corrupt ({exc}); regenerate the dataset") from None
    if features.shape != (meta.num_trajectories, len(meta.feature_names)):
        raise LangprefError(
            f"{fpath} has shape {features.shape}, meta.json says {meta.num_trajectories} trajectories x "
            f"{len(meta.feature_names)} features; regenerate the dataset"
        )
    return Dataset(root, meta, features)
