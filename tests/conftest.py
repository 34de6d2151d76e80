"""Shared test setup: headless rendering, one torch thread, and a tiny synthetic dataset without a simulator."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")

from dataclasses import asdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover
    pass


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI (the env var CI set, as `.ci/run` runs) a skipped test fails: CI installs every extra, Chromium and
    nginx, so a skip there means a claim went untested while the run stayed green."""
    outcome = yield
    report = outcome.get_result()
    if os.environ.get("CI") and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[-1] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome, report.longrepr = "failed", f"skipped under CI, which must run every test: {reason}"


def write_synthetic_dataset(root: Path, n: int = 12, horizon: int = 20, env: str = "metaworld", seed: int = 0) -> Path:
    """A dataset in the real on-disk format whose features are the means of the first observation dims."""
    from langpref.dataset.generate import assign_splits
    from langpref.dataset.storage import DatasetMeta, Trajectory, save_trajectory, write_meta
    from langpref.tasks import get_task

    spec = get_task(env)
    rng = np.random.default_rng(seed)
    nf = len(spec.features)
    feats = np.zeros((n, nf))
    for i in range(n):
        obs = rng.normal(size=(horizon, spec.obs_dim)).astype(np.float32) * 0.1 + rng.normal(size=spec.obs_dim)
        step_features = obs[:, :nf].copy()
        traj = Trajectory(
            i,
            obs,
            rng.normal(size=(horizon, spec.action_dim)).astype(np.float32),
            step_features,
            np.zeros((horizon, 3)),
            np.zeros((horizon, 3)),
            bool(i % 2),
            i,
            {"i": i},
        )
        save_trajectory(root, traj)
        feats[i] = traj.features
    meta = DatasetMeta(
        env,
        horizon,
        [asdict(f) for f in spec.obs_layout],
        spec.action_dim,
        list(spec.features),
        assign_splits(env, n, seed),
        n,
    )
    write_meta(root, meta, feats)
    return root


@pytest.fixture
def synthetic_dataset(tmp_path: Path) -> Path:
    return write_synthetic_dataset(tmp_path / "synthetic")


@pytest.fixture
def make_synthetic_dataset():
    """`write_synthetic_dataset` itself, for tests that need another size (`from conftest import` may find the
    conftest of another test folder first)."""
    return write_synthetic_dataset


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


@pytest.fixture(scope="session")
def tiny_texts() -> tuple[dict, dict]:
    """A few Meta-World train and val phrasings (utterance-file schema) for tiny training runs."""
    return TRAIN_TEXTS, VAL_TEXTS
