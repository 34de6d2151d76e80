"""Iterative improvement: Eq. 4's argmax, the paper and history strategies, the CLI and the resumable experiment."""

from __future__ import annotations

import json
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
from tests.factories import write_dataset

torch.set_num_threads(1)


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


def test_recorded_candidates_search_every_split_on_the_test_scale():
    """`recorded`: the generator's baseline. Same start, human and normalisation as `test`, a pool of every row."""
    space = toy_latent_space(n=100, seed=0)
    test_rows = set(space.split("test").tolist())
    outside, above = 0, 0
    for seed in range(5):
        w = human_weights(len(space.feature_names), 0, seed)
        base = run_improvement(space, w, ImproveConfig(iterations=4, seeds=1, strategy="history"), (0, seed))
        wide = run_improvement(
            space, w, ImproveConfig(iterations=4, seeds=1, strategy="history", candidate_split="recorded"), (0, seed)
        )
        assert wide.shown[0] == base.shown[0] and wide.reward[0] == base.reward[0]
        assert wide.optimal_raw == base.optimal_raw  # normalised by the test split's best, as `test` is
        outside += sum(s not in test_rows for s in wide.shown)
        above += max(wide.reward) > 1.0
        assert all(s in test_rows for s in base.shown) and max(base.reward) <= 1.0
    assert outside > 0  # the wider pool is used: train and val rows are shown
    assert above > 0  # and a recorded row better than every test row is reached: the scale stays the test split's


def test_cli_improve_json(tmp_path, capsys):
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
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
