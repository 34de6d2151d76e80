"""`langpref experiment choose`: the answer model's settings scored on val with other humans, each value against the
default paired by human (the unit of its intervals), and the pick the lowest cross-entropy."""

from __future__ import annotations

import numpy as np
from scipy import stats

from langpref.experiments.choose import GRIDS, SYMBOL, run_choose_experiment
from langpref.reward import LearnRewardConfig
from langpref.reward.answer_model import AnswerModelConfig
from tests.factories import write_dataset


def test_choose_pairs_each_value_with_the_default_by_human(tmp_path):
    data = write_dataset(tmp_path / "d", env="metaworld", n=40, horizon=8, like_task=True)
    cfg = LearnRewardConfig(queries=3, humans=3, seeds=2)
    res = run_choose_experiment("metaworld", data, None, tmp_path / "c", perfect=True, config=cfg, progress=False)
    assert res["eval_split"] == "val" and res["phrasings"] == "val" and set(res["rows"]) == set(GRIDS)
    for name, row in res["rows"].items():
        _, field, values, selection = GRIDS[name]
        assert row["default"] == getattr(AnswerModelConfig(), field) and len(row["values"]) == len(values)
        ce = {float(v): c["mean_cross_entropy_1_to_q"] for v, c in row["values"].items()}
        assert ce[row["lowest_ce"]] == min(ce.values())
        methods = {v: res["methods"][f"{name} {SYMBOL[field]}={v:g}"] for v in values}
        for value, method in methods.items():
            assert method["config"]["answer_model"][field] == value
            assert method["config"]["query_selection"] == selection and method["config"]["learner"] == "answer-model"
        # the interval counts the humans (3), each human's seeds averaged first
        auc = {
            v: np.array([h["auc_true_reward"] for _, h in sorted(m["per_human"].items())]) for v, m in methods.items()
        }
        d = auc[values[-1]] - auc[row["default"]]
        half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
        got = row["values"][f"{values[-1]:g}"]["auc_true_reward_minus_default"]
        assert np.isclose(got["mean"], d.mean()) and np.isclose(got["high"] - got["mean"], half)
    assert (tmp_path / "c" / "choose.png").read_bytes()[:4] == b"\x89PNG"
    assert "| active language | c = -30 |" in (tmp_path / "c" / "choose.md").read_text()
