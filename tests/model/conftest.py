"""Tiny synthetic datasets (no simulator) and small phrasing tables for the latent-space tests.

Each trajectory wanders around its own random level per observation dimension; the three features are the means of
observation dimensions 0, 1, 2, so a per-step MLP averaged over time can learn them exactly.

`make_image_dataset` is the toy task of the image encoder: the answer is only in the pixels (a coloured square's
position and brightness in 32x32 frames), the observations and actions are noise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from langpref.dataset.storage import DatasetMeta, Trajectory, save_trajectory, write_meta
from langpref.language.pairs import phrasings_from_mapping

torch.set_num_threads(1)

MW_FEATURES = ["height", "speed", "distance_to_button"]


def make_dataset(
    root: Path,
    *,
    env: str = "metaworld",
    n: int = 16,
    horizon: int = 20,
    obs_dim: int = 6,
    action_dim: int = 2,
    seed: int = 0,
    feature_names: list[str] | None = None,
) -> Path:
    rng = np.random.default_rng(seed)
    names = feature_names or MW_FEATURES
    layout = [{"name": "hand", "start": 0, "stop": 3}, {"name": "rest", "start": 3, "stop": obs_dim}]
    feats = []
    for i in range(n):
        level = rng.uniform(-1, 1, size=obs_dim)
        obs = (level + 0.3 * rng.standard_normal((horizon, obs_dim))).astype(np.float32)
        act = rng.standard_normal((horizon, action_dim)).astype(np.float32)
        step_features = (
            obs[:, : len(names)].astype(np.float64) if len(names) <= obs_dim else np.tile(obs[:, :1], (1, len(names)))
        )
        traj = Trajectory(
            index=i,
            observations=obs,
            actions=act,
            step_features=step_features,
            qpos=np.zeros((horizon, 2)),
            qvel=np.zeros((horizon, 2)),
            success=bool(i % 2),
            seed=i,
        )
        save_trajectory(root, traj)
        feats.append(traj.features)
    n_train, n_val = int(n * 0.625), (n - int(n * 0.625)) // 2
    splits = {
        "train": list(range(n_train)),
        "val": list(range(n_train, n_train + n_val)),
        "test": list(range(n_train + n_val, n)),
    }
    meta = DatasetMeta(
        env=env,
        horizon=horizon,
        obs_layout=layout,
        action_dim=action_dim,
        feature_names=names,
        splits=splits,
        num_trajectories=n,
    )
    write_meta(root, meta, np.array(feats))
    return root


def square_frame(x: float, y: float, red: float, size: int = 32, side: int = 6) -> np.ndarray:
    """A black frame with a square of `side` pixels whose corner is at (x, y) in [0, 1] of the free range, its red
    channel `red` in [0, 1] (green and blue fixed)."""
    frame = np.zeros((size, size, 3), np.uint8)
    free = size - side
    col, row = int(round(x * free)), int(round(y * free))
    frame[row : row + side, col : col + side] = (int(80 + 175 * red), 200, 60)
    return frame


def make_image_dataset(
    root: Path, *, n: int = 24, horizon: int = 8, stride: int = 2, size: int = 32, seed: int = 0
) -> Path:
    """A dataset with frames whose features are only in the pixels: per step, the square's row (`height`), its
    brightness (`speed`) and its column (`distance_to_button`) of the frame the step is shown; observations and
    actions are noise."""
    from langpref.dataset.frames import FrameSpec, save_frames

    rng = np.random.default_rng(seed)
    spec = FrameSpec(width=size, height=size, stride=stride, source="render")
    feats = []
    for i in range(n):
        level = rng.uniform(0.1, 0.9, size=3)
        kept = range(0, horizon, stride)
        values = np.clip(level + 0.05 * rng.standard_normal((len(kept), 3)), 0, 1)
        save_frames(root, i, np.stack([square_frame(x, y, r, size) for y, r, x in values]))
        step_features = values[np.arange(horizon) // stride]
        traj = Trajectory(
            index=i,
            observations=rng.standard_normal((horizon, 4)).astype(np.float32),
            actions=rng.standard_normal((horizon, 2)).astype(np.float32),
            step_features=step_features,
            qpos=None,
            qvel=None,
            success=False,
            seed=None,
        )
        save_trajectory(root, traj)
        feats.append(traj.features)
    n_train, n_val = int(n * 0.625), (n - int(n * 0.625)) // 2
    meta = DatasetMeta(
        env="metaworld",
        horizon=horizon,
        obs_layout=[{"name": "noise", "start": 0, "stop": 4}],
        action_dim=2,
        feature_names=MW_FEATURES,
        splits={
            "train": list(range(n_train)),
            "val": list(range(n_train, n_train + n_val)),
            "test": list(range(n_train + n_val, n)),
        },
        num_trajectories=n,
        frames=spec.to_dict(),
    )
    write_meta(root, meta, np.array(feats))
    return root


@pytest.fixture(scope="session")
def image_data(tmp_path_factory) -> Path:
    return make_image_dataset(tmp_path_factory.mktemp("data") / "squares")


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("data") / "tiny")


@pytest.fixture(scope="session")
def phrasings(tiny_texts):
    train_texts, val_texts = tiny_texts
    return (phrasings_from_mapping(train_texts, MW_FEATURES), phrasings_from_mapping(val_texts, MW_FEATURES))


def tiny_config(data: Path, out: Path, **overrides):
    from langpref.model.config import ModelConfig, TrainConfig

    cfg = TrainConfig(
        data=str(data),
        out=str(out),
        model=ModelConfig(latent_dim=16, max_length=12),
        stage1_epochs=6,
        stage1_batch_size=32,
        stage1_lr=1e-2,
        stage1_head_lr=1e-2,
        stage2_epochs=1,
        stage2_batch_size=128,
        stage2_phrasings_per_step=6,
        patience=0,
        frame_pretrain_steps=40,  # the default 1500 would dominate a tiny image model's training
        device="cpu",
        seed=0,
    )
    for k, v in overrides.items():
        setattr(cfg, k, v)
    return cfg


@pytest.fixture(scope="session")
def trained(tiny_data, phrasings, tmp_path_factory):
    """One small run of both stages, shared by the tests that only read a trained model: (result, stage-1 dir)."""
    from langpref.model.train import train

    root = tmp_path_factory.mktemp("models")
    cfg = tiny_config(tiny_data, root / "cofinetuned")
    result = train(
        cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False, stage1_out=root / "frozen"
    )
    return result
