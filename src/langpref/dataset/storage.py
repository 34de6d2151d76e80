"""On-disk trajectory datasets: one compressed `.npz` per trajectory plus `meta.json` and a feature table.

Layout of a dataset directory:

    meta.json              schema version, env, horizon, observation layout, feature names, splits, generator config
    features.npy           (N, F) trajectory features theta(tau) (per-step features averaged over time)
    trajectories/000123.npz  observations (T, obs_dim), actions (T, A), step_features (T, F), qpos (T, nq),
                             qvel (T, nv), success (), seed (), controller_params (JSON string)

Every load checks what it reads and fails with a one-line `LangprefError` saying what is wrong.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError

SCHEMA_VERSION = 1
SPLITS = ("train", "val", "test")
_ARRAYS = ("observations", "actions", "step_features", "qpos", "qvel")


@dataclass
class Trajectory:
    """One rollout. `step_features[t]` is theta(s_t, a_t); `qpos/qvel[t]` is the simulator state at step t."""

    index: int
    observations: np.ndarray
    actions: np.ndarray
    step_features: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    success: bool
    seed: int
    controller_params: dict[str, Any] = field(default_factory=dict)

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

    @property
    def obs_dim(self) -> int:
        return int(self.obs_layout[-1]["stop"])


def trajectory_path(root: Path, index: int) -> Path:
    return Path(root) / "trajectories" / f"{index:06d}.npz"


def save_trajectory(root: Path, traj: Trajectory) -> Path:
    """Write one trajectory atomically (a temp file renamed into place), so a crash never leaves half a file."""
    path = trajectory_path(root, traj.index)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(
        tmp,
        **{name: getattr(traj, name) for name in _ARRAYS},
        success=np.asarray(traj.success),
        seed=np.asarray(traj.seed),
        controller_params=np.asarray(json.dumps(traj.controller_params)),
    )
    tmp.replace(path)
    return path


def write_meta(root: Path, meta: DatasetMeta, features: np.ndarray) -> None:
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    np.save(root / "features.npy", features.astype(np.float64))
    (root / "meta.json").write_text(json.dumps(asdict(meta), indent=2) + "\n")


def _read_meta(root: Path) -> DatasetMeta:
    path = root / "meta.json"
    if not root.exists():
        raise LangprefError(f"dataset {root} does not exist: create one with `langpref generate --env ENV --out {root}`")
    if not path.is_file():
        raise LangprefError(f"{root} is not a langpref dataset (no meta.json); create one with `langpref generate`")
    try:
        raw = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{path} is corrupt (not valid JSON: {exc}); regenerate the dataset") from None
    version = raw.get("schema_version") if isinstance(raw, dict) else None
    if version != SCHEMA_VERSION:
        raise LangprefError(
            f"{path} has dataset schema version {version!r}, this langpref reads version {SCHEMA_VERSION}; "
            "regenerate the dataset with this version"
        )
    try:
        return DatasetMeta(**raw)
    except TypeError as exc:
        raise LangprefError(f"{path} is not a valid dataset description ({exc}); regenerate the dataset") from None


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

    def trajectories(self, split: str | None = None) -> list[Trajectory]:
        indices = range(len(self)) if split is None else self.split(split)
        return [self.load(i) for i in indices]

    def arrays(self, split: str) -> tuple[np.ndarray, np.ndarray]:
        """(observations (N, T, obs_dim), actions (N, T, A)) of a split, stacked, float32."""
        trajs = self.trajectories(split)
        obs = np.stack([t.observations for t in trajs]).astype(np.float32)
        act = np.stack([t.actions for t in trajs]).astype(np.float32)
        return obs, act

    @cached_property
    def success(self) -> np.ndarray:
        return np.array([self.load(i).success for i in range(len(self))], dtype=bool)


def load_trajectory(root: Path, index: int, meta: DatasetMeta) -> Trajectory:
    path = trajectory_path(root, index)
    if not path.is_file():
        raise LangprefError(f"dataset {root} is incomplete: {path.name} is missing; regenerate the dataset")
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise LangprefError(f"{path} is truncated or corrupt ({type(exc).__name__}); regenerate the dataset") from None
    missing = [k for k in (*_ARRAYS, "success", "seed", "controller_params") if k not in data]
    if missing:
        raise LangprefError(f"{path} lacks {', '.join(missing)}; regenerate the dataset")
    obs, act, feats = data["observations"], data["actions"], data["step_features"]
    if obs.shape != (meta.horizon, meta.obs_dim) or act.shape != (meta.horizon, meta.action_dim):
        raise LangprefError(
            f"{path} has observations {obs.shape} and actions {act.shape}, meta.json says horizon {meta.horizon}, "
            f"obs {meta.obs_dim}, action {meta.action_dim}; the dataset is mixed up, regenerate it"
        )
    if feats.shape != (meta.horizon, len(meta.feature_names)):
        raise LangprefError(f"{path} has step_features {feats.shape}, inconsistent with meta.json; regenerate it")
    return Trajectory(
        index=index,
        observations=obs,
        actions=act,
        step_features=feats,
        qpos=data["qpos"],
        qvel=data["qvel"],
        success=bool(data["success"]),
        seed=int(data["seed"]),
        controller_params=json.loads(str(data["controller_params"])),
    )


def load_dataset(root: str | Path, env: str | None = None) -> Dataset:
    """Open a dataset; with `env`, also check it is a dataset of that env."""
    root = Path(root)
    meta = _read_meta(root)
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
