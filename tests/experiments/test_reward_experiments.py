"""`langpref experiment reward|ablation|prior`: writing, resuming, the paired differences and the prior's picks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from langpref.cli import main
from langpref.feedback import HumanConfig
from langpref.reward import LearnRewardConfig, RewardConfig
from tests.factories import write_dataset


def test_experiments_reward_and_ablation_write_and_resume(tmp_path, monkeypatch):
    import langpref.reward as reward_module
    from langpref.experiments.reward import run_ablation_experiment, run_reward_experiment

    data = write_dataset(tmp_path / "d", env="metaworld", n=40, horizon=8, like_task=True)
    cfg = LearnRewardConfig(queries=4, humans=2, seeds=1)
    res = run_reward_experiment("metaworld", data, None, tmp_path / "r", perfect=True, config=cfg, progress=False)
    assert set(res["methods"]) == {"language", "comparison"} and len(res["targets"]) == 3
    assert (
        len(res["ce_difference"]["mean"]) == 5
        and "paired by human (each human's seeds averaged)" in (tmp_path / "r" / "reward.md").read_text()
    )
    abl = run_ablation_experiment("metaworld", data, None, tmp_path / "a", perfect=True, config=cfg, progress=False)
    assert set(abl["methods"]) == {"both", "explicit", "implicit"}
    for out, name in ((tmp_path / "r", "reward"), (tmp_path / "a", "ablation")):
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
        assert json.loads((out / f"{name}.json").read_text())["queries"] == 4
        assert "Paper:" in (out / f"{name}.md").read_text()
    monkeypatch.setattr(reward_module, "run_reward_learning", lambda *a, **k: pytest.fail("rerun"))
    again = run_reward_experiment("metaworld", data, None, tmp_path / "r", perfect=True, config=cfg, progress=False)
    assert again["methods"]["language"]["cross_entropy"] == res["methods"]["language"]["cross_entropy"]


def test_paired_difference_on_hand_built_numbers():
    from langpref.experiments.reward import paired_difference

    b = np.zeros((3, 2))
    a = np.array([[1.0, 0.5], [2.0, 0.5], [3.0, 0.5]])
    d = paired_difference(a, b)
    half = 4.302653 / np.sqrt(3)  # t(0.975, 2) * sd 1 / sqrt(3)
    assert d["mean"] == pytest.approx([2.0, 0.5])
    assert d["low"] == pytest.approx([2.0 - half, 0.5], rel=1e-6) and d["high"] == pytest.approx(
        [2.0 + half, 0.5], rel=1e-6
    )


def test_prior_experiment_picks_each_methods_lowest_val_cross_entropy(tmp_path):
    from langpref.experiments.prior import PRIOR_METHODS, run_prior_experiment

    data = write_dataset(tmp_path / "d", env="metaworld", n=40, horizon=8, like_task=True)
    cfg = LearnRewardConfig(queries=3, humans=1, seeds=1)
    res = run_prior_experiment(
        "metaworld", data, None, tmp_path / "p", perfect=True, config=cfg, progress=False, grid=(0.1, 10.0)
    )
    assert res["eval_split"] == "val" and res["seed"] != LearnRewardConfig().seed
    assert res["reward_model"] == "linear" and res["default"] == RewardConfig().weight_decay
    assert set(res["picks"]) == set(PRIOR_METHODS)
    for name, pick in res["picks"].items():
        ce = {wd: np.mean(res["methods"][f"{name} wd={wd:g}"]["cross_entropy"][1:]) for wd in (0.1, 10.0)}
        assert ce[pick] == min(ce.values())
    assert (tmp_path / "p" / "prior.png").read_bytes()[:4] == b"\x89PNG"
    assert "| language |" in (tmp_path / "p" / "prior.md").read_text()


def test_experiment_records_the_command_that_ran_it(tmp_path, monkeypatch, capsys):
    """From the command line, the command that ran it (without --json); from Python, its base command (the options
    are in the summary's configs). Each setting has its own default output."""
    from langpref.experiments.reward import run_reward_experiment

    monkeypatch.chdir(tmp_path)
    data = write_dataset(tmp_path / "d", env="metaworld", n=40, horizon=8, like_task=True)
    argv = ["experiment", "reward", "--env", "metaworld", "--data", str(data), "--perfect-latent"]
    argv += ["--queries", "2", "--humans", "1", "--seeds", "1", "--reward-model", "mlp"]
    assert main([*argv, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert Path(res["figure"]).parent == Path("results/reward/metaworld-perfect-mlp")  # not the linear model's runs
    assert res["command"] == " ".join(["langpref", *argv])
    cfg = LearnRewardConfig(queries=2, humans=1, seeds=1, human=HumanConfig(phrasing_split="all"))
    res = run_reward_experiment("metaworld", data, None, None, perfect=True, config=cfg, progress=False)
    assert Path(res["figure"]).parent == Path("results/reward/metaworld-perfect-bank-all")
    assert res["command"].endswith("--perfect-latent --out results/reward/metaworld-perfect-bank-all")
    assert res["methods"]["language"]["config"]["human"]["phrasing_split"] == "all"
