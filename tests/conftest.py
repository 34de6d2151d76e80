"""Shared test setup: headless rendering, one torch thread, and fixtures over `tests.factories` (test data without a
simulator)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")

from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from tests.ci_collect import pytest_make_collect_report  # noqa: E402, F401  (a hook: see tests/ci_collect.py)
from tests.factories import MW_FEATURES, TRAIN_TEXTS, VAL_TEXTS, make_image_dataset, tiny_config, write_dataset  # noqa: E402

try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover
    pass


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI (the env var CI set, as `.ci/run` runs) a skipped test fails: CI installs every extra, Chromium and
    nginx, so a skip there means a claim went untested while the run stayed green. A whole module skipped or kept
    from collection by a missing module is one failing test named after it (`tests/ci_collect.py`), so that one
    missing extra does not interrupt the run."""
    outcome = yield
    report = outcome.get_result()
    _fail_a_skip_under_ci(report)


def _fail_a_skip_under_ci(report) -> None:
    if os.environ.get("CI") and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[-1] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome, report.longrepr = "failed", f"skipped under CI, which must run every test: {reason}"


@pytest.fixture
def synthetic_dataset(tmp_path: Path) -> Path:
    """12 trajectories of 20 steps shaped as Meta-World's (`tests.factories.write_dataset`)."""
    return write_dataset(tmp_path / "synthetic", n=12, like_task=True)


@pytest.fixture
def make_synthetic_dataset():
    """`write_dataset` shaped as a task's (Meta-World's unless `env=`), 12 trajectories of 20 steps unless given."""
    return partial(write_dataset, n=12, like_task=True)


@pytest.fixture(scope="session")
def tiny_texts() -> tuple[dict, dict]:
    """A few Meta-World train and val phrasings (utterance-file schema) for tiny training runs."""
    return TRAIN_TEXTS, VAL_TEXTS


@pytest.fixture(scope="session")
def image_data(tmp_path_factory) -> Path:
    """The image encoder's toy dataset (`tests.factories.make_image_dataset`)."""
    return make_image_dataset(tmp_path_factory.mktemp("data") / "squares")


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory) -> Path:
    """The toy dataset the latent-space tests train on (`tests.factories.write_dataset`, 16 trajectories)."""
    return write_dataset(tmp_path_factory.mktemp("data") / "tiny")


@pytest.fixture(scope="session")
def phrasings(tiny_texts):
    """(train, val) phrasing tables of `tiny_texts` over Meta-World's features."""
    from langpref.language.pairs import phrasings_from_mapping

    train_texts, val_texts = tiny_texts
    return (phrasings_from_mapping(train_texts, MW_FEATURES), phrasings_from_mapping(val_texts, MW_FEATURES))


@pytest.fixture(scope="session")
def trained(tiny_data, phrasings, tmp_path_factory):
    """One small run of both stages, shared by the tests that only read a trained model: (result, stage-1 dir)."""
    from langpref.model.train import train

    root = tmp_path_factory.mktemp("models")
    cfg = tiny_config(tiny_data, root / "cofinetuned")
    return train(
        cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False, stage1_out=root / "frozen"
    )


@pytest.fixture(scope="session")
def real_data(tmp_path_factory):
    """A tiny Meta-World dataset made by `langpref generate` in the simulator (30 rollouts of 30 steps)."""
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.storage import load_dataset

    out = tmp_path_factory.mktemp("gen") / "mw"
    generate(GenerateConfig(env="metaworld", out=out, num_trajectories=30, horizon=30, workers=1))
    return load_dataset(out)
