"""`langpref experiment active` with the mixed learner: its arm beside the single kinds, curves and areas over
modelled seconds up to the time every run reaches, and paired intervals per query and per second."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from scipy import stats

from langpref.experiments.active import MIXED, per_second, run_seconds
from langpref.reward import LearnRewardConfig, RewardConfig

torch.set_num_threads(1)


def test_per_second_areas_reach_the_common_horizon_and_fall_back_to_one_kind():
    methods = {"a": LearnRewardConfig(feedback="language"), "b": LearnRewardConfig(feedback="comparison")}
    runs = {
        "a/0/0": {"cross_entropy": [0.7, 0.5, 0.4], "true_reward_of_best": [0.0, 1.0, 1.0]},  # recorded without times
        "b/0/0": {
            "cross_entropy": [0.7, 0.6, 0.3],
            "true_reward_of_best": [0.0, 0.0, 1.0],
            "seconds": [0.0, 1.0, 2.0],
            "kinds": ["comparison", "comparison"],
        },
    }
    assert run_seconds(runs["a/0/0"], "language", methods["a"].costs) == pytest.approx([0.0, 0.887, 1.774])
    timed = per_second(runs, methods, ["0/0"])
    assert timed["horizon"] == pytest.approx(1.774)  # two language queries; comparisons would take 2
    a, b = timed["methods"]["a"], timed["methods"]["b"]
    assert a["auc_true_reward"] == pytest.approx((1.774 - 0.887) / 1.774)
    assert b["auc_true_reward"] == pytest.approx(0.0)  # its second answer comes after the horizon
    assert a["seconds_for_q"] == pytest.approx(1.774) and b["seconds_for_q"] == 2.0
    assert len(a["true_reward_of_best"]) == len(timed["grid"]) and a["true_reward_of_best"][-1] == 1.0


def test_active_experiment_reports_the_mixed_arm_per_query_and_per_second(tmp_path, make_synthetic_dataset):
    from langpref.experiments.active import run_active_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=40)
    cfg = LearnRewardConfig(queries=3, candidates=8, reward=RewardConfig(num_negatives=3, max_iter=20))
    res = run_active_experiment(
        "metaworld", data, None, tmp_path / "a", perfect=True, config=cfg, humans=2, seeds=1, progress=False
    )
    mixed = res["methods"][MIXED]
    assert len(mixed["cross_entropy"]) == len(mixed["true_reward_of_best"]) == 4
    assert mixed["config"]["feedback"] == "mixed" and len(mixed["kinds_asked"]) == 2
    # the share and the modelled time are those of the kinds the mixed learner asked, run by run
    asked = np.array(mixed["kinds_asked"])
    assert asked.shape == (2, 3) and set(asked.ravel()) <= {"language", "comparison"}
    assert res["language_share"][MIXED] == pytest.approx((asked == "language").mean())
    assert res["language_share"]["language-random"] == 1.0 and res["language_share"]["comparison-random"] == 0.0
    spent = [sum(cfg.costs[k] for k in run) for run in asked]
    assert res["per_second"]["methods"][MIXED]["seconds_for_q"] == pytest.approx(np.mean(spent))
    timed = res["per_second"]
    assert timed["horizon"] == pytest.approx(min(m["seconds_for_q"] for m in timed["methods"].values()))
    assert timed["methods"]["comparison-random"]["seconds_for_q"] == pytest.approx(3.0)
    assert timed["methods"]["language-random"]["seconds_for_q"] == pytest.approx(3 * 0.887)
    for name in (f"{MIXED} - language-infogain", f"{MIXED} - comparison-infogain"):
        c = res["contrasts"][name]
        assert c["auc_true_reward_per_second"]["low"] <= c["auc_true_reward_per_second"]["mean"]
    assert np.isfinite(res["per_run_auc_per_second"][MIXED]).all()
    md = (tmp_path / "a" / "active.md").read_text()
    assert "Over the person's time" in md and "AUC best per second" in md and f"| {MIXED} |" in md
    assert json.loads((tmp_path / "a" / "active.json").read_text())["costs"] == {"language": 0.887, "comparison": 1.0}


def test_active_experiment_writes_curves_intervals_and_targets(tmp_path, make_synthetic_dataset):
    import json

    from langpref.experiments.active import ACTIVE_METHODS, run_active_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=40)
    cfg = LearnRewardConfig(queries=3, candidates=10, reward=RewardConfig(num_negatives=3, max_iter=20))
    res = run_active_experiment(
        "metaworld", data, None, tmp_path / "a", perfect=True, config=cfg, humans=3, seeds=2, progress=False
    )
    assert set(res["methods"]) == set(ACTIVE_METHODS) and len(res["targets"]) == 11
    # the contrasts' unit is the human: each human's two seeds averaged, a t-interval over the 3 humans
    a, b = (
        np.array(res["per_run_auc"][m]).reshape(3, 2).mean(axis=1) for m in ("language-infogain", "language-random")
    )
    got = res["contrasts"]["language-infogain - language-random"]["auc_true_reward"]
    half = stats.t.ppf(0.975, 2) * (a - b).std(ddof=1) / np.sqrt(3)
    assert np.isclose(got["mean"], (a - b).mean()) and np.isclose(got["high"] - got["mean"], half)
    assert all(len(r["true_reward_of_best"]) == 4 for r in res["methods"].values())
    assert "language-infogain - language-lal-infogain" in res["contrasts"]
    assert (tmp_path / "a" / "active.png").read_bytes()[:4] == b"\x89PNG"
    assert "Paired differences" in (tmp_path / "a" / "active.md").read_text()
    assert json.loads((tmp_path / "a" / "active.json").read_text())["command"].startswith(
        "langpref experiment active --env metaworld"
    )


def test_every_active_method_names_a_registered_kind_and_one_of_its_strategies():
    """The methods table is data: each feedback is a registered kind (or `mixed`) and each selection one the kind has,
    under a learner that exists; the answer-model rows name kinds that learner reads."""
    from langpref.experiments.active import ACTIVE_METHODS
    from langpref.feedback.kind import MIXED, RANDOM, asked_kinds, kind_names
    from langpref.reward.learners import get_learner, learner_names
    from langpref.reward.selection import strategies_of

    for name, (feedback, strategy, learner, _) in ACTIVE_METHODS.items():
        assert feedback in (*kind_names(), MIXED) and learner in learner_names(), name
        assert (strategy or RANDOM) in (*strategies_of(feedback), RANDOM), name
        assert all(get_learner(learner).reads(kind) for kind in asked_kinds(feedback)), name
