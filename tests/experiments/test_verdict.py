"""`langpref experiment verdict`: language vs comparisons paired run by run over several reward experiments, with
intervals whose unit is the human, and the verdict worded from them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.experiments.clustered import cell_grid, cluster_bootstrap
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
    assert s["overall"]["auc"]["n"] == 27 and s["overall"]["auc"]["low"] > 0
    assert s["overall"]["auc"]["humans"] == 3 and s["overall"]["auc"]["method"] == "humans-models"
    assert s["verdict"] == {"auc": "language better", "mean_ce": "language better"}
    assert s["overall"]["auc"]["mean"] == pytest.approx(0.05, abs=0.01)
    same = [_write_runs(tmp_path / f"n{k}", 0.0, 10 + k, swing=0.05) for k in range(3)]
    s = run_verdict_experiment(VerdictConfig(env="toy", runs=tuple(same), out=str(tmp_path / "w")))
    assert s["verdict"]["auc"] == "not told apart" and s["overall"]["auc"]["low"] < 0 < s["overall"]["auc"]["high"]
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


def _write_correlated(folder, effects: list[float], seed: int, noise: float = 0.002) -> str:
    """A reward experiment's runs.json in which the human decides the difference: human h's language curve lies
    `effects[h]` above comparisons' in every seed, with little noise on top. Written for several models with the same
    `effects`, the models repeat one another, as models that share their humans and seeds do."""
    rng = np.random.default_rng(seed)
    runs = {}
    for h, effect in enumerate(effects):
        for s in range(3):
            base = np.linspace(0.5, 0.9, 11)
            ce = np.linspace(1.0, 0.4, 11)
            runs[f"comparison/{h}/{s}"] = {"true_reward_of_best": base.tolist(), "cross_entropy": ce.tolist()}
            lang = base + effect + rng.normal(0, noise, 11)
            runs[f"language/{h}/{s}"] = {"true_reward_of_best": lang.tolist(), "cross_entropy": (ce - effect).tolist()}
    folder.mkdir(parents=True)
    (folder / "runs.json").write_text(json.dumps({"runs": runs}))
    return str(folder)


# Ten humans whose mean gap is +0.02 and whose spread (sd 0.04) is the human's, not the run's.
EFFECTS = [0.02 + 0.04 * z for z in (-1.5, -1.0, -0.6, -0.3, 0.0, 0.0, 0.3, 0.6, 1.0, 1.5)]


def test_correlated_models_are_not_counted_as_independent_runs(tmp_path):
    """Three models that repeat one another over ten humans: 90 pairs, but ten humans' worth of evidence. The pooled
    t-interval counts 90 and calls language better; the default, with the human as the unit, does not, and its
    interval is about sqrt(90 / 10) = 3 times as wide."""
    runs = tuple(_write_correlated(tmp_path / f"m{k}", EFFECTS, k) for k in range(3))
    default = run_verdict_experiment(VerdictConfig(env="toy", runs=runs, out=str(tmp_path / "v")))
    pooled = run_verdict_experiment(VerdictConfig(env="toy", runs=runs, interval="pooled", out=str(tmp_path / "p")))
    d, p = default["overall"]["auc"], pooled["overall"]["auc"]
    assert d["n"] == p["n"] == 90 and d["humans"] == 10
    assert d["mean"] == pytest.approx(p["mean"]) == pytest.approx(0.02, abs=0.002)
    assert p["low"] > 0 and pooled["verdict"]["auc"] == "language better"
    assert d["low"] < 0 < d["high"] and default["verdict"] == {"auc": "not told apart", "mean_ce": "not told apart"}
    assert 2.0 < (d["high"] - d["low"]) / (p["high"] - p["low"]) < 4.0
    assert default["model_agreement"]["auc"] > 0.99
    md = (tmp_path / "v" / "verdict.md").read_text()
    assert "bootstrap over humans and models" in md and "correlate +1.00" in md
    assert "--interval pooled" in (tmp_path / "p" / "verdict.md").read_text()


def test_independent_runs_keep_about_the_t_interval():
    """When the pairs are independent (no human effect, only run noise), the bootstrap over humans is on average
    about as wide as the t-interval over the pairs: clustering costs little where pooling was right. Resampling the
    models as well (the default) is wider there, as the crossed bootstrap is known to be (it counts the noise once
    with the humans and once with the models), but by less than 2x. Averaged over 40 data sets: one set of ten
    humans moves a width by a third either way."""
    ratios: dict[bool, list[float]] = {False: [], True: []}
    for rep in range(40):
        rng = np.random.default_rng(rep)
        diffs = {f"m{k}": {f"{h}/{s}": rng.normal() for h in range(10) for s in range(3)} for k in range(3)}
        t = interval([d for per_model in diffs.values() for d in per_model.values()])
        for models in ratios:
            iv = cluster_bootstrap(cell_grid(diffs), resample_models=models, draws=1000, seed=rep)
            ratios[models].append((iv["high"] - iv["low"]) / (t["high"] - t["low"]))
    assert 0.8 < np.mean(ratios[False]) < 1.05 and 1.2 < np.mean(ratios[True]) < 1.8


def test_the_bootstrap_resamples_whole_humans_and_is_seeded():
    """A human's seeds travel together; the same seed gives the same interval; one model resamples humans only."""
    diffs = {"a": {f"{h}/{s}": EFFECTS[h] for h in range(10) for s in range(3)}}
    grid = cell_grid(diffs)
    assert grid.counts.tolist() == [[3.0] * 10] and grid.humans[:3] == ("0", "1", "2")
    one = cluster_bootstrap(grid, resample_models=True, draws=2000, seed=3)
    assert one == cluster_bootstrap(grid, resample_models=True, draws=2000, seed=3)
    assert one["method"] == "humans" and one["n"] == 30
    t_over_humans = interval(EFFECTS)
    assert (one["high"] - one["low"]) == pytest.approx(t_over_humans["high"] - t_over_humans["low"], rel=0.25)
    with pytest.raises(LangprefError, match="at least 100 draws"):
        cluster_bootstrap(grid, resample_models=False, draws=10)


def test_the_interval_is_chosen_on_the_command_line(tmp_path, capsys):
    runs = ",".join(_write_correlated(tmp_path / f"m{k}", EFFECTS, k) for k in range(2))
    argv = ["experiment", "verdict", "--env", "toy", "--runs", runs, "--out", str(tmp_path / "v"), "--json"]
    assert main([*argv, "--interval", "pooled"]) == 0
    assert json.loads(capsys.readouterr().out)["overall"]["auc"]["method"] == "pooled"
    assert main([*argv, "--interval", "humans", "--bootstraps", "500", "--seed", "4"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["overall"]["auc"]["method"] == "humans" and s["overall"]["auc"]["draws"] == 500
    assert "--interval humans --bootstraps 500 --seed 4" in (tmp_path / "v" / "verdict.md").read_text()
    assert main([*argv, "--bootstraps", "5"]) == 2 and "at least 100 draws" in capsys.readouterr().err
