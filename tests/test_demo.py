"""`langpref demo`, the first command a reader runs, end to end at tiny size: every stage (generate in the simulator,
inspect, render, train, evaluate, improve, learn rewards) runs and leaves what it says it made."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.factories import tiny_config

pytestmark = pytest.mark.slow  # runs the simulator and renders (`pytest -m 'not slow'` leaves it out)


def test_the_demo_runs_every_stage_at_tiny_size(tmp_path, capsys):
    from langpref.demo import run_demo

    tiny = tiny_config(tmp_path, tmp_path)  # data and out are set by the demo
    made = run_demo(tmp_path, workers=1, num_trajectories=16, horizon=16, train_config=tiny)
    printed = capsys.readouterr().out
    for stage in ("== 1. Generating 16", "(T = 16)", "== 4.", "== 6.", "Done in"):
        assert stage in printed
    for key in ("dataset", "inspect", "video_success", "video_failure", "model", "improvement_figure", "reward_figure"):
        assert Path(made[key]).exists(), key
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert 0.0 <= summary["accuracy"]["accuracy"] <= 1.0
    assert {len(curve) for curve in summary["improvement"].values()} == {16}  # iteration 0 and 15 rounds
    assert set(summary["reward"]) == {"language", "comparison"}
    assert all(len(r["cross_entropy"]) == 21 for r in summary["reward"].values())  # query counts 0..20
