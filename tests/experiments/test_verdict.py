"""`langpref experiment verdict`: language vs comparisons paired run by run over several reward experiments, with
intervals, and the verdict worded from them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.experiments.verdict import VerdictConfig, interval, run_verdict_experiment


def _write_runs(folder, gap: float, seed: int, noise: float = 0.02, ce_gap: float = 0.0, swing: float = 0.0):
    """A reward experiment's runs.json: 3 humans x 3 seeds, language's true-reward curve `gap` above comparisons',
    plus `swing` above and below by turns (pairs that disagree)."""
    rng = np.random.default_rng(seed)
    runs = {}
    for h in range(3):
        for s in range(3):
            base = np.linspace(0.5, 0.9, 11) + rng.normal(0, noise, 11)
            ce = np.linspace(1.0, 0.4, 11)
            runs[f"comparison/{h}/{s}"] = {"true_reward_of_best": base.tolist(), "cross_entropy": ce.tolist()}
            lang = base + gap + swing * (-1) ** (3 * h + s) + rng.normal(0, noise, 11)
            runs[f"language/{h}/{s}"] = {"true_reward_of_best": lang.tolist(), "cross_entropy": (ce + ce_gap).tolist()}
    folder.mkdir(parents=True)
    (folder / "runs.json").write_text(json.dumps({"config_key": "x", "runs": runs}))
    return str(folder)


def test_a_clear_gap_is_language_better_and_none_is_not_told_apart(tmp_path):
    better = [_write_runs(tmp_path / f"m{k}", 0.05, k, ce_gap=-0.1) for k in range(3)]
    s = run_verdict_experiment(VerdictConfig(env="toy", runs=tuple(better), out=str(tmp_path / "v")))
    assert s["pooled"]["auc"]["n"] == 27 and s["pooled"]["auc"]["low"] > 0
    assert s["verdict"] == {"auc": "language better", "mean_ce": "language better"}
    assert s["pooled"]["auc"]["mean"] == pytest.approx(0.05, abs=0.01)
    same = [_write_runs(tmp_path / f"n{k}", 0.0, 10 + k, swing=0.05) for k in range(3)]
    s = run_verdict_experiment(VerdictConfig(env="toy", runs=tuple(same), out=str(tmp_path / "w")))
    assert s["verdict"]["auc"] == "not told apart" and s["pooled"]["auc"]["low"] < 0 < s["pooled"]["auc"]["high"]
    assert "not told apart" in (tmp_path / "w" / "verdict.md").read_text()


def test_the_interval_is_the_paired_t_interval():
    from scipy import stats

    d = [0.1, 0.2, 0.15, 0.05]
    iv = interval(d)
    res = stats.ttest_1samp(d, 0.0).confidence_interval(0.95)
    assert iv["low"] == pytest.approx(res.low) and iv["high"] == pytest.approx(res.high)


def test_a_missing_folder_is_one_line(tmp_path, capsys):
    code = main(["experiment", "verdict", "--env", "metaworld", "--runs", str(tmp_path / "nope")])
    err = capsys.readouterr().err
    assert code == 2 and "experiment reward" in err and err.count("\n") == 1


def test_two_other_methods_of_the_same_runs(tmp_path):
    folder = _write_runs(tmp_path / "m", 0.05, 0)
    runs = json.loads((tmp_path / "m" / "runs.json").read_text())
    renamed = {k.replace("language/", "am-language-infogain/"): v for k, v in runs["runs"].items()}
    (tmp_path / "m" / "runs.json").write_text(json.dumps({"runs": renamed}))
    cfg = VerdictConfig(env="toy", runs=(folder,), methods=("am-language-infogain", "comparison"), out=str(tmp_path))
    s = run_verdict_experiment(cfg)
    assert s["verdict"]["auc"] == "am-language-infogain better"
    assert "--methods am-language-infogain,comparison" in (tmp_path / "verdict.md").read_text()
    with pytest.raises(LangprefError, match="the runs hold am-language-infogain, comparison"):
        run_verdict_experiment(VerdictConfig(env="toy", runs=(folder,), out=str(tmp_path)))
