"""`ModelConfig.delta_magnitudes`: the size of each step's change of observation as an input of the trajectory side."""

import json

import numpy as np
import torch

from langpref.dataset.storage import load_dataset
from langpref.model.checkpoint import load_model
from langpref.model.encoders import step_input_dim, step_inputs
from langpref.model.train import train
from langpref.reward.steps import StepEncoder
from tests.factories import tiny_config


def test_step_inputs_carry_the_change_and_its_size():
    obs = np.array([[[0.0, 1.0], [1.0, 3.0], [0.5, 2.0]]])
    act = np.zeros((1, 3, 1))
    x = step_inputs(obs, act, observation_deltas=True, delta_magnitudes=True)
    assert x.shape == (1, 3, step_input_dim(2, 1, True, True)) == (1, 3, 7)
    np.testing.assert_allclose(x[0, :, 2:4], [[0, 0], [1, 2], [-0.5, -1]])
    np.testing.assert_allclose(x[0, :, 4:6], [[0, 0], [1, 2], [0.5, 1]])
    only = step_inputs(obs, act, observation_deltas=False, delta_magnitudes=True)
    np.testing.assert_allclose(only[0, :, 2:4], x[0, :, 4:6])
    assert step_inputs(obs, act, True).shape[-1] == step_input_dim(2, 1, True) == 5  # unchanged without the option


def test_a_model_with_magnitudes_saves_loads_and_rebuilds_per_step(tiny_data, phrasings, tmp_path):
    cfg = tiny_config(tiny_data, tmp_path / "m", stage1_epochs=1, stage2_epochs=1)
    cfg.model.delta_magnitudes = True
    result = train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)
    saved = json.loads((tmp_path / "m" / "config.json").read_text())
    assert saved["model"]["delta_magnitudes"] is True
    assert len(saved["normalisation"]["mean"]) == 6 * 3 + 2  # obs, deltas, |deltas|, action
    model, dataset = load_model(tmp_path / "m"), load_dataset(tiny_data)
    obs, act = dataset.arrays("test")
    assert model.traj.delta_magnitudes
    assert torch.equal(model.encode_trajectories(obs, act), result.model.encode_trajectories(obs, act))
    steps = StepEncoder.from_checkpoint(tmp_path / "m").embeddings(obs[0], act[0])  # what a saved reward reads
    np.testing.assert_allclose(steps.mean(axis=0), model.encode_trajectories(obs[:1], act[:1])[0].numpy(), atol=1e-5)


def test_a_checkpoint_from_before_the_option_loads_without_magnitudes(trained, tmp_path):
    import shutil

    old = tmp_path / "old"
    shutil.copytree(trained.out, old)
    cfg = json.loads((old / "config.json").read_text())
    cfg["model"].pop("delta_magnitudes", None)
    (old / "config.json").write_text(json.dumps(cfg))
    model = load_model(old)
    assert not model.traj.delta_magnitudes
    assert model.traj.mean.shape[0] == step_input_dim(6, 2, True)
