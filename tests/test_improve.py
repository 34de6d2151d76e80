"""Iterative improvement: Eq. 4's argmax, the paper and history strategies, the CLI and the resumable experiment."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.feedback import toy_latent_space
from langpref.improve import (
    ImproveConfig,
    cosine_objective,
    human_weights,
    improve,
    improvement_step,
    plot_improvement,
    printed_objective,
    run_improvement,
)

torch.set_num_threads(1)


def write_features_dataset(root: Path, env: str = "metaworld", n: int = 40, seed: int = 0) -> Path:
    """A dataset directory with meta.json and features.npy only (enough for --perfect-latent)."""
    from langpref.dataset.storage import DatasetMeta, write_meta
    from langpref.tasks import get_task

    rng = np.random.default_rng(seed)
    feats = rng.normal(size=(n, len(get_task(env).features)))
    order = rng.permutation(n).tolist()
    splits = {
        "train": sorted(order[: n // 2]),
        "val": sorted(order[n // 2 : 3 * n // 4]),
        "test": sorted(order[3 * n // 4 :]),
    }
    meta = DatasetMeta(env, 10, [{"name": "obs", "start": 0, "stop": 4}], 2, list(get_task(env).features), splits, n)
    write_meta(root, meta, feats)
    return root


def test_cosine_objective_and_argmax_on_hand_built_embeddings():
    phi = np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 2.0], [-1.0, 0.5]])
    current = np.array([1.0, 0.0])
    psi = np.array([0.0, 2.0])  # "more of dimension 2"; its norm must not matter
    # cos(phi' - phi^t, psi): 0 for the current one itself, then 1/sqrt(2), 2/sqrt(5), 0.5/sqrt(4.25)
    assert np.allclose(cosine_objective(phi, current, psi), [0.0, 1 / 2**0.5, 2 / 5**0.5, 0.5 / 4.25**0.5])
    assert improvement_step(phi, current, psi) == 2
    assert improvement_step(phi, current, -psi) == 0  # nothing lowers dim 2 below the current one: stay


def test_printed_objective_favours_small_embeddings_against_the_feedback():
    # Eq. 4 as printed divides by |phi'|: a short candidate that barely moves along psi beats a long one that moves
    # far along it; the cosine of the difference follows the feedback.
    phi = np.array([[0.0, 0.0], [0.1, 0.1], [0.0, 5.0]])
    current, psi = np.array([0.0, -0.2]), np.array([0.0, 1.0])
    assert np.allclose(
        printed_objective(phi, current, psi),
        (phi - current) @ psi / np.maximum(np.linalg.norm(phi, axis=1), 1e-12) / 0.2,
    )
    assert improvement_step(phi[1:], current, psi, "printed") == 0
    assert improvement_step(phi[1:], current, psi, "cosine") == 1


@pytest.fixture(scope="module")
def space():
    return toy_latent_space(n=100, seed=0)


@pytest.mark.parametrize("strategy,objective", [("paper", "cosine"), ("paper", "printed"), ("history", "cosine")])
def test_improvement_with_a_perfect_latent_space_raises_the_reward(space, strategy, objective):
    result = improve(
        space, ImproveConfig(strategy=strategy, objective=objective, seeds=20, iterations=8), progress=False
    )
    assert len(result["curve"]) == len(result["curve_std"]) == 9
    assert result["optimal"] == 1.0
    assert result["curve"][-1] - result["curve"][0] > 0.25
    assert 0.0 <= min(result["curve"]) and max(result["curve"]) <= 1.0


def test_history_ends_at_least_as_high_as_paper(space):
    curves = {
        s: improve(space, ImproveConfig(strategy=s, seeds=20, iterations=8), progress=False)["curve"]
        for s in ("paper", "history")
    }
    assert curves["history"][-1] >= curves["paper"][-1] - 0.02


def test_same_seed_same_curve_and_runs_differ(space):
    cfg = ImproveConfig(strategy="history", seeds=4, iterations=4)
    assert improve(space, cfg, progress=False)["curve"] == improve(space, cfg, progress=False)["curve"]
    cfg.seed = 1
    runs = [run_improvement(space, human_weights(3, 0, s), cfg, (0, s)).shown for s in range(4)]
    assert len({tuple(r) for r in runs}) > 1


def test_exclude_shown_never_repeats(space):
    cfg = ImproveConfig(strategy="history", iterations=10, exclude_shown=True)
    run = run_improvement(space, human_weights(3, 0, 0), cfg, (0, 0))
    assert len(set(run.shown)) == len(run.shown) == 11


def test_bad_config_is_a_one_line_error(space):
    with pytest.raises(LangprefError, match="strategy"):
        improve(space, ImproveConfig(strategy="greedy"), progress=False)
    with pytest.raises(LangprefError, match="objective"):
        improve(space, ImproveConfig(objective="dot"), progress=False)
    with pytest.raises(LangprefError, match="split"):
        improve(space, ImproveConfig(candidate_split="holdout", seeds=1), progress=False)


def test_plot_writes_a_png(space, tmp_path):
    res = improve(space, ImproveConfig(seeds=3, iterations=3), progress=False)
    out = plot_improvement({"paper": res}, tmp_path / "fig" / "improve.png")
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_cli_improve_json(tmp_path, capsys):
    data = write_features_dataset(tmp_path / "d")
    assert (
        main(
            [
                "improve",
                "--data",
                str(data),
                "--perfect-latent",
                "--seeds",
                "3",
                "--iterations",
                "4",
                "--strategy",
                "history",
                "--figure",
                str(tmp_path / "f.png"),
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert len(out["curve"]) == len(out["curve_std"]) == 5 and out["optimal"] == 1.0
    assert Path(out["figure"]).is_file()
    assert main(["improve", "--data", str(data)]) == 2  # neither a model nor --perfect-latent
    assert "--perfect-latent" in capsys.readouterr().err


def test_experiment_improve_writes_and_resumes(tmp_path, monkeypatch, capsys):
    import langpref.improve as improve_module
    from langpref.experiments.improve import run_improve_experiment

    data = write_features_dataset(tmp_path / "d")
    out = tmp_path / "res"
    cfg = ImproveConfig(seeds=3, iterations=3)
    first = run_improve_experiment("metaworld", data, None, out, perfect=True, config=cfg, progress=False)
    assert {p.name for p in out.iterdir()} >= {"improve.json", "improve.png", "improve.md", "runs.json"}
    assert set(first["strategies"]) == {"paper", "paper-printed", "history"}
    assert first["strategies"]["paper-printed"]["config"]["objective"] == "printed"
    assert "| paper |" in (out / "improve.md").read_text()

    def boom(*args, **kwargs):
        raise AssertionError("a finished seed was rerun")

    monkeypatch.setattr(improve_module, "run_improvement", boom)
    again = run_improve_experiment("metaworld", data, None, out, perfect=True, config=cfg, progress=False)
    assert again["strategies"]["paper"]["curve"] == first["strategies"]["paper"]["curve"]
    with pytest.raises(LangprefError, match="another configuration"):
        run_improve_experiment(
            "metaworld", data, None, out, perfect=True, config=ImproveConfig(seeds=3, iterations=4), progress=False
        )
    monkeypatch.undo()
    assert (
        main(
            [
                "experiment",
                "improve",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--out",
                str(out),
                "--seeds",
                "3",
                "--iterations",
                "4",
                "--force",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert len(summary["strategies"]["history"]["curve"]) == 5
    assert asdict(ImproveConfig())["seeds"] == 100 and ImproveConfig().iterations == 15


@pytest.mark.parametrize("kind, flag", [("improve", "--seeds"), ("reward", "--queries"), ("prior", "--humans")])
def test_experiment_refuses_a_zero_override_and_writes_nothing(tmp_path, capsys, kind, flag):
    data = write_features_dataset(tmp_path / "d")
    out = tmp_path / "res"
    assert (
        main(
            [
                "experiment",
                kind,
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--out",
                str(out),
                flag,
                "0",
            ]
        )
        == 2
    )  # 0 is a value, not "use the paper's setting"
    assert "must" in capsys.readouterr().err and not out.exists()


def test_experiment_command_is_the_command_line_that_ran_it(tmp_path, monkeypatch, capsys):
    """The command an experiment writes into its .md/.json is the one that ran it (without --json); from Python,
    its base command, the options being in the summary's configs."""
    from langpref.experiments.improve import run_improve_experiment
    from langpref.feedback import HumanConfig

    monkeypatch.chdir(tmp_path)
    data = write_features_dataset(tmp_path / "d")
    phrasings = Path(__file__).resolve().parents[1] / "heldout" / "utterances.json"
    argv = ["experiment", "improve", "--env", "metaworld", "--data", str(data), "--perfect-latent"]
    argv += ["--seeds", "2", "--iterations", "2", "--phrasings", str(phrasings)]
    assert main([*argv, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert Path(res["figure"]).parent == Path("results/improve/metaworld-perfect-phrasings")
    assert res["command"] == " ".join(["langpref", *argv])
    assert f"`{res['command']}`" in Path(res["figure"]).with_suffix(".md").read_text()
    cfg = ImproveConfig(seeds=2, iterations=2, human=HumanConfig(phrasings=str(phrasings)))
    res = run_improve_experiment("metaworld", data, None, tmp_path / "o", perfect=True, config=cfg, progress=False)
    assert (
        res["command"]
        == f"langpref experiment improve --env metaworld --data {data} --perfect-latent --out {tmp_path / 'o'}"
    )
    assert res["strategies"]["paper"]["config"]["human"]["phrasings"] == str(phrasings)


def test_run_cache_outlives_an_option_added_later_but_not_a_changed_one(tmp_path):
    from langpref.experiments.common import RunCache

    path = tmp_path / "runs.json"
    RunCache(path, {"seeds": 3, "human": {"temperature": 1.0}}).put("paper/0", [0.5])
    again = RunCache(path, {"seeds": 3, "human": {"temperature": 1.0, "phrasings": None}})  # a new, unset option
    assert "paper/0" in again
    with pytest.raises(LangprefError, match="another configuration"):
        RunCache(path, {"seeds": 3, "human": {"temperature": 1.0, "phrasings": "mine.json"}})


def test_experiment_improve_with_another_phrasing_split(tmp_path, monkeypatch, capsys):
    """--phrasing-split all: its own default output, and the command that reproduces it."""
    data = write_features_dataset(tmp_path / "d")
    monkeypatch.chdir(tmp_path)
    assert (
        main(
            [
                "experiment",
                "improve",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--seeds",
                "2",
                "--iterations",
                "2",
                "--phrasing-split",
                "all",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert Path(summary["figure"]).parent == Path("results/improve/metaworld-perfect-bank-all")
    assert summary["command"].endswith("--phrasing-split all")
    assert summary["strategies"]["paper"]["config"]["human"]["phrasing_split"] == "all"
