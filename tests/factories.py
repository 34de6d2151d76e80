"""Test data without a simulator, shared by every test folder: one dataset factory (`write_dataset`), the image
dataset of the frame encoder's toy task, a few phrasings, the tiny training config, and the CLI's parsers. A module
rather than a conftest, so a test imports it by one name (`from tests.factories import ...`) whichever folders run
together.

`write_dataset` writes the real on-disk format. Each trajectory wanders around its own random level per observation
dimension; the features are the means of the first observation dimensions, so a per-step MLP averaged over time can
learn them exactly. `make_image_dataset` is the toy task of the image encoder: the answer is only in the pixels (a
coloured square's position and brightness in 32x32 frames), the observations and actions are noise.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

import numpy as np
import pytest

from langpref.dataset.storage import DatasetMeta, Trajectory, save_trajectory, write_meta

MW_FEATURES = ["height", "speed", "distance_to_button"]


def require(module: str, install: str):
    """`module`, imported. Where it is missing the test is skipped (a partial install), except under CI (the env var
    CI set, as `.ci/run` sets it): `make test` installs it (`install` says how), so there a missing module is a
    broken install, and its own ImportError fails the test (or the module, at module level) rather than a skip."""
    if os.environ.get("CI"):
        return importlib.import_module(module)
    return pytest.importorskip(module, reason=f"{module} is not installed ({install})")


def _toy_splits(n: int) -> dict[str, list[int]]:
    """train 62.5%, then val and test halves of the rest, in index order."""
    n_train, n_val = int(n * 0.625), (n - int(n * 0.625)) // 2
    return {
        "train": list(range(n_train)),
        "val": list(range(n_train, n_train + n_val)),
        "test": list(range(n_train + n_val, n)),
    }


def write_dataset(
    root: Path,
    *,
    env: str = "metaworld",
    n: int = 16,
    horizon: int = 20,
    obs_dim: int = 6,
    action_dim: int = 2,
    seed: int = 0,
    feature_names: list[str] | None = None,
    like_task: bool = False,
) -> Path:
    """A dataset of `n` trajectories of `horizon` steps at `root`. By default a toy one (`obs_dim` observations,
    `action_dim` actions, Meta-World's feature names or `feature_names`, 62.5% train). `like_task`: shaped as
    `env`'s generated datasets are (its observation and action sizes, layout, features and split rule, and
    controller parameters per trajectory), for tests of code that reads a task's data."""
    rng = np.random.default_rng(seed)
    if like_task:
        from langpref.dataset.generate import assign_splits
        from langpref.tasks import get_task

        task = get_task(env)
        obs_dim, action_dim, names = task.obs_dim, task.action_dim, list(task.features)
        layout = [{"name": f.name, "start": f.start, "stop": f.stop} for f in task.obs_layout]
        splits = assign_splits(env, n, seed)
    else:
        names = feature_names or MW_FEATURES
        layout = [{"name": "hand", "start": 0, "stop": 3}, {"name": "rest", "start": 3, "stop": obs_dim}]
        splits = _toy_splits(n)
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
            controller_params={"i": i} if like_task else {},
        )
        save_trajectory(root, traj)
        feats.append(traj.features)
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
    meta = DatasetMeta(
        env="metaworld",
        horizon=horizon,
        obs_layout=[{"name": "noise", "start": 0, "stop": 4}],
        action_dim=2,
        feature_names=MW_FEATURES,
        splits=_toy_splits(n),
        num_trajectories=n,
        frames=spec.to_dict(),
    )
    write_meta(root, meta, np.array(feats))
    return root


TRAIN_TEXTS = {
    "height": {
        "increase": ["Move higher.", "Go up more.", "Raise your arm."],
        "decrease": ["Move lower.", "Go down more.", "Lower your arm."],
    },
    "speed": {
        "increase": ["Move faster.", "Speed up.", "Go quicker."],
        "decrease": ["Move slower.", "Slow down.", "Go more slowly."],
    },
    "distance_to_button": {
        "increase": ["Stay away from the button.", "Move farther from the button."],
        "decrease": ["Get closer to the button.", "Move nearer to the button."],
    },
}
VAL_TEXTS = {
    "height": {"increase": ["Lift up higher."], "decrease": ["Drop lower down."]},
    "speed": {"increase": ["Be quicker."], "decrease": ["Be slower."]},
    "distance_to_button": {"increase": ["Keep further from the button."], "decrease": ["Approach the button."]},
}


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
        augment_phrasings=0,  # the tiny phrasings as given (tests/model/test_keep.py covers the augmentation)
        device="cpu",
        seed=0,
    )
    for k, v in overrides.items():
        setattr(cfg, k, v)
    return cfg


def parsers():
    """{"train": its parser, "experiment improve": ..., ...} with every command's options built."""
    import argparse

    from langpref.cli import build_parser

    out = {}

    def walk(p, path):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    out[" ".join([*path, name])] = sub
                    walk(sub, [*path, name])

    walk(build_parser(), [])
    return out


def untrained_checkpoint(out: Path, seed: int = 0) -> Path:
    """A real (untrained) Meta-World checkpoint at `out`: its trajectory encoder is what a saved reward reads."""
    from dataclasses import asdict

    import torch

    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.encoders import step_input_dim
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    spec = get_task("metaworld")
    layout = [asdict(f) for f in spec.obs_layout]
    info = DataInfo("metaworld", list(spec.features), layout, spec.obs_dim, spec.action_dim, 8, 1, [0.0] * 3, [1.0] * 3)
    torch.manual_seed(seed)
    dim = step_input_dim(spec.obs_dim, spec.action_dim, True)
    rng = np.random.default_rng(seed)
    cfg = ModelConfig(latent_dim=8, max_length=12)
    model = build_model(cfg, info, rng.normal(size=dim) * 0.1, 0.5 + rng.random(dim))
    return save_model(model, out, model_cfg=cfg, lang_finetuned=False)
