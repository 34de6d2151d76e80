"""`langpref experiment observations` on the toy dataset whose features are only in the pixels: one model per
observation kind, trained in its own process, evaluated, tabled, and resumed from its cache."""

from __future__ import annotations

import json

import pytest

from langpref.errors import LangprefError
from langpref.experiments.observations import ObservationsConfig, run_observations_experiment
from tests.factories import make_image_dataset, tiny_config


def test_a_model_per_kind_with_time_and_memory(tmp_path):
    """One kind only (each trains in a fresh process, which loads torch and the language model again)."""
    data = make_image_dataset(tmp_path / "squares", n=24)
    train_cfg = tiny_config(data, tmp_path / "unused", stage1_epochs=2, freeze_language=True)
    cfg = ObservationsConfig(env="metaworld", data=str(data), out=str(tmp_path / "out"), kinds=("images",))
    summary = run_observations_experiment(cfg, train_config=train_cfg)
    run = summary["runs"]["images"]
    assert run["train"]["train_s"] > 0
    # the table's accuracy is the saved model's own, on every test trajectory, with the bank's test phrasings
    from langpref.dataset.storage import load_dataset
    from langpref.language.bank import load_bank
    from langpref.language.pairs import phrasings_from_bank
    from langpref.model.checkpoint import load_model
    from langpref.model.evaluate import evaluate_split

    dataset = load_dataset(data)
    test = phrasings_from_bank(load_bank("metaworld"), "test", dataset.feature_names)
    again = evaluate_split(load_model(run["model"], dataset=dataset), dataset, "test", test)
    assert run["test"]["num_trajectories"] == len(dataset.split("test")) and run["test"]["num_samples"] > 0
    assert run["test"]["accuracy"] == pytest.approx(again["accuracy"]), "not the saved model's test accuracy"
    assert run["train"]["peak_rss_mib"] > 100  # torch and the language model are in there
    assert (tmp_path / "out" / "latent-images.png").is_file() and run["figure"].endswith("latent-images.png")
    assert json.loads((tmp_path / "out" / "images" / "config.json").read_text())["model"]["observations"] == "images"
    table = (tmp_path / "out" / "observations.md").read_text()
    assert table.splitlines()[2].startswith("| images | ") and "--kinds images" in table
    # the threads the model trained on, which an image model needs to train again bit for bit
    assert run["train"]["torch_threads"] >= 1 and f"--threads {run['train']['torch_threads']} " in table
    again = run_observations_experiment(cfg, train_config=train_cfg)  # every kind cached: nothing retrains
    assert again["runs"] == summary["runs"]
    with pytest.raises(LangprefError, match="--observations must be one of"):
        run_observations_experiment(ObservationsConfig(env="metaworld", data=str(data), kinds=("pixels",)))


def test_the_reproducing_command_carries_the_frame_loss_settings():
    from langpref.experiments.observations import observations_command
    from langpref.model.config import TrainConfig

    cfg = ObservationsConfig(env="metaworld", data="d", out="o", kinds=("images",))
    assert "--frame" not in observations_command(cfg, TrainConfig())
    line = observations_command(cfg, TrainConfig(frame_contrastive=1.0, frame_pretrain_steps=1500))
    assert line.endswith("--frame-contrastive 1 --frame-pretrain-steps 1500 --kinds images")


def test_the_reproducing_command_carries_the_small_bank_and_thread_settings():
    """A row of docs/results.md measured before small banks were augmented by default reruns with
    `--augment-phrasings 0`; an image model trains again bit for bit on as many threads."""
    from langpref.experiments.observations import observations_command
    from langpref.model.config import TrainConfig

    cfg = ObservationsConfig(env="drawer-open-hidden", data="d", out="o", kinds=("state", "images+state"))
    line = observations_command(cfg, TrainConfig(augment_phrasings=0), threads=2)
    assert line.endswith("--augment-phrasings 0 --threads 2 --kinds state,images+state")
    assert "--threads 3" in observations_command(cfg, TrainConfig(threads=3))
    assert "--augment" not in observations_command(cfg, TrainConfig())
