"""`langpref experiment alignment`, the command behind the alignment headline (README's 0.847 on Meta-World), run
end to end at tiny size: one training whose stage 1 is the frozen row, both rows evaluated on the test split with
the bank's test phrasings, the table and the record written."""

from __future__ import annotations

import json

import pytest

from langpref.cli import main
from langpref.experiments.alignment import PAPER
from tests.factories import tiny_config


@pytest.fixture
def tiny_train_config(monkeypatch, tmp_path):
    """`TrainConfig()` as the command builds it, made tiny (the command itself has no size options)."""
    import langpref.model.config as model_config

    tiny = tiny_config(tmp_path, tmp_path)  # data and out are set by the command
    monkeypatch.setattr(model_config, "TrainConfig", lambda: tiny)


def test_the_alignment_command_trains_once_and_evaluates_both_rows(
    make_synthetic_dataset, tmp_path, capsys, tiny_train_config
):
    data = make_synthetic_dataset(tmp_path / "mw", n=16)
    out = tmp_path / "alignment"
    assert (
        main(["experiment", "alignment", "--env", "metaworld", "--data", str(data), "--out", str(out), "--json"]) == 0
    )
    summary = json.loads(capsys.readouterr().out)
    for row in ("cofinetune", "frozen"):
        assert 0.0 <= summary[row]["accuracy"] <= 1.0 and summary[row]["num_samples"] > 0
        assert set(summary[row]["per_feature"]) == {"height", "speed", "distance_to_button"}
        assert (out / ("cofinetuned" if row == "cofinetune" else "frozen") / "config.json").exists()
    assert summary["paper"] == PAPER["metaworld"] and summary["train_wall_s"] > 0
    assert summary["command"] == f"langpref experiment alignment --env metaworld --data {data} --out {out}"
    md = (out / "alignment.md").read_text()
    assert "| Co-finetune | " in md and f"{summary['cofinetune']['accuracy']:.3f} | 0.829" in md
    assert json.loads((out / "alignment.json").read_text())["cofinetune"] == summary["cofinetune"]
    assert (out / "alignment.config.json").exists()


def test_an_unknown_task_is_refused_before_training(tmp_path, capsys):
    assert (
        main(["experiment", "alignment", "--env", "drawer-open", "--data", str(tmp_path), "--out", str(tmp_path)]) == 2
    )
    assert "unknown env 'drawer-open'" in capsys.readouterr().err
