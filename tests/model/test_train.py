import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.model.encoders import transformer_state_fingerprint
from langpref.model.train import Trainer, train
from tests.factories import tiny_config


def test_loss_falls_and_train_accuracy_rises_well_above_chance(trained):
    stage1 = [h for h in trained.history if h["stage"] == 1]
    assert stage1[-1]["loss"] < 0.75 * stage1[0]["loss"]
    assert max(h["train_acc"] for h in stage1) > 0.8
    assert trained.results["best_val_accuracy"] > 0.7


def test_both_stages_ran_and_wrote_both_checkpoints(trained):
    assert {h["stage"] for h in trained.history} == {1, 2}
    assert (trained.out / "language_model").is_dir() and (trained.out / "training_curve.png").is_file()
    assert trained.stage1_out is not None and not (trained.stage1_out / "language_model").exists()
    assert (trained.stage1_out / "config.json").is_file()


def test_frozen_stage_leaves_the_transformer_unchanged(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", stage1_epochs=2), *phrasings, progress=False)
    before = {k: v.clone() for k, v in trainer.model.lang.transformer.state_dict().items()}
    head_before = trainer.model.lang.head.weight.detach().clone()
    trainer.stage1()
    after = trainer.model.lang.transformer.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)
    assert not torch.equal(head_before, trainer.model.lang.head.weight)  # ...while the head did learn
    fp = transformer_state_fingerprint(trainer.model.lang.transformer)
    trainer.stage2(0.0)
    assert transformer_state_fingerprint(trainer.model.lang.transformer) != fp  # co-finetuning moves it


def test_same_seed_same_numbers(tiny_data, phrasings, tmp_path):
    runs = []
    for i in range(2):
        cfg = tiny_config(tiny_data, tmp_path / f"m{i}", stage1_epochs=2, freeze_language=True)
        r = train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)
        runs.append(r)
    strip = [[{k: v for k, v in h.items() if k != "seconds"} for h in r.history] for r in runs]
    assert strip[0] == strip[1]
    s0, s1 = runs[0].model.state_dict(), runs[1].model.state_dict()
    assert all(torch.equal(s0[k], s1[k]) for k in s0)
    cfg = tiny_config(tiny_data, tmp_path / "m2", stage1_epochs=2, freeze_language=True, seed=1)
    other = train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)
    assert not torch.equal(other.model.traj.out.weight, runs[0].model.traj.out.weight)


def test_mixed_precision_leaves_the_cpu_path_unchanged(tiny_data, phrasings, tmp_path):
    runs = [
        train(
            tiny_config(tiny_data, tmp_path / f"amp{amp}", stage1_epochs=1, stage2_epochs=1, mixed_precision=amp),
            train_phrasings=phrasings[0],
            val_phrasings=phrasings[1],
            progress=False,
        )
        for amp in (True, False)
    ]
    s0, s1 = runs[0].model.state_dict(), runs[1].model.state_dict()
    assert all(torch.equal(s0[k], s1[k]) for k in s0)


def test_config_fails_fast(tiny_data, tmp_path):
    (tmp_path / "exists").mkdir()
    with pytest.raises(LangprefError, match="already exists"):
        train(tiny_config(tiny_data, tmp_path / "exists"), progress=False)
    with pytest.raises(LangprefError, match="stage1_lr"):
        train(tiny_config(tiny_data, tmp_path / "x", stage1_lr=0.0), progress=False)
    with pytest.raises(LangprefError, match="does not exist"):
        train(tiny_config(tmp_path / "nodata", tmp_path / "y"), progress=False)
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_unique_trajectories_are_encoded_once(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m"), *phrasings, progress=False)
    a, b = np.array([0, 1, 1, 3]), np.array([1, 0, 3, 0])
    with torch.no_grad():
        phi_a, phi_b = trainer._phi(trainer.train, a, b)
        full = trainer.model.traj(trainer.train.steps)
    assert torch.allclose(phi_a, full[a], atol=1e-6) and torch.allclose(phi_b, full[b], atol=1e-6)


def test_time_samples_are_stratified_and_training_uses_them(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", time_samples=5), *phrasings, progress=False)
    t = trainer._time_index(7, 20).numpy()
    assert t.shape == (7, 5)
    assert np.all(t // 4 == np.arange(5))  # one step in each segment of 4
    a, b = np.array([0, 1]), np.array([1, 2])
    phi_a, _ = trainer._phi(trainer.train, a, b)
    assert phi_a.shape == (2, 16)
    trainer.cfg.time_samples = 0
    assert trainer._time_index(7, 20) is None
