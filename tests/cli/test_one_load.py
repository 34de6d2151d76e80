"""Objects, not paths, down one command (issue 43, item 3): `learn-reward --optimize` reads the dataset once and loads
the model once, and a space embeds a new trajectory (`LatentSpace.phi_of`) as it embedded the dataset's."""

from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)


@pytest.fixture(scope="module")
def checkpoint(real_data, tmp_path_factory):
    """A Meta-World state model of the real dataset's layout with a small random trajectory encoder (what the
    generation and the value-order metric read of it) and the default language model."""
    import torch

    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.encoders import step_input_dim
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    task = get_task("metaworld")
    torch.manual_seed(0)
    cfg = ModelConfig(latent_dim=8, traj_hidden=(16, 16), max_length=12)
    layout = [asdict(f) for f in task.obs_layout]
    info = DataInfo("metaworld", list(task.features), layout, task.obs_dim, task.action_dim, 30, 2, [0.1] * 3)
    dim = step_input_dim(task.obs_dim, task.action_dim, True)
    rng = np.random.default_rng(0)
    model = build_model(cfg, info, rng.normal(size=dim) * 0.1, 0.5 + rng.random(dim))
    return save_model(model, tmp_path_factory.mktemp("ckpt") / "mw", model_cfg=cfg, lang_finetuned=False)


def _counting(monkeypatch, module, name: str, counts: dict[str, int]) -> None:
    real = getattr(module, name)

    def counted(*args, **kwargs):
        counts[name] = counts.get(name, 0) + 1
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)


def test_learn_reward_optimize_loads_the_dataset_and_the_model_once(real_data, checkpoint, monkeypatch, capsys):
    """The latent space, the value-order metric's episodes and the generation of r_xi's optimum all come from one
    `load_dataset` and one `load_model` (before: 3 dataset reads and 2 model loads, the generation reopening both from
    their paths)."""
    from langpref.cli import main
    from langpref.dataset import storage
    from langpref.model import checkpoint as ckpt

    counts: dict[str, int] = {}
    _counting(monkeypatch, storage, "load_dataset", counts)
    _counting(monkeypatch, ckpt, "load_model", counts)
    argv = ["learn-reward", "--data", str(real_data.root), "--model", str(checkpoint), "--feedback", "language"]
    argv += ["--queries", "2", "--humans", "1", "--seeds", "1", "--optimize", "--rollouts", "2"]
    argv += ["--search-generations", "3", "--optimize-rounds", "1", "--json"]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert len(result["optimized_true_reward"]) == 1 and np.isfinite(result["optimized_true_reward"][0])
    assert counts == {"load_dataset": 1, "load_model": 1}


def test_phi_of_a_dataset_trajectory_is_its_row_of_phi(real_data, checkpoint):
    """`phi_of` embeds a trajectory in memory as the space embedded the dataset: the oracle space's (normalised
    features, 3) and a model's trajectory encoder alike, for a dataset trajectory loaded as a new rollout would be."""
    from langpref.errors import LangprefError
    from langpref.feedback.space import load_space, perfect_latent_space, toy_latent_space

    rows = [0, 7, len(real_data) - 1]
    for space in (perfect_latent_space(real_data), load_space(real_data.root, checkpoint)):
        phi = np.stack([space.phi_of(real_data.load(i)) for i in rows])
        np.testing.assert_allclose(phi, space.phi[rows], rtol=1e-5, atol=1e-6)
    with pytest.raises(LangprefError, match="no trajectory encoder"):
        toy_latent_space().phi_of(real_data.load(0))
