"""What `langpref train` says when it ends: its curve, a stage still improving at its last epoch, TensorBoard; and
one line, nothing lost, for an output it cannot write."""

from __future__ import annotations

import json
import sys
import types

import pytest

from langpref.cli import main
from langpref.cli.training import still_improving, train_text
from langpref.model.config import TrainConfig


def _history(stage: int, vals: list[float]) -> list[dict]:
    return [
        {"stage": stage, "epoch": i + 1, "loss": 1.0, "align": 1.0, "train_acc": v, "val_acc": v}
        for i, v in enumerate(vals)
    ]


def test_a_stage_still_rising_at_its_last_epoch_is_named_with_more_epochs():
    cfg = TrainConfig(data="d", out="o", stage1_epochs=10, stage2_epochs=5)
    rising = _history(1, [0.5, 0.55, 0.6, 0.62, 0.64, 0.66, 0.68, 0.7, 0.72, 0.75])
    flat = _history(2, [0.75, 0.76, 0.76, 0.76, 0.76])
    (w,) = still_improving(rising + flat, cfg)
    assert (w["stage"], w["flag"], w["suggest"], w["best_epoch"], w["epochs"]) == (1, "--epochs", 20, 10, 10)
    assert w["rise"] == pytest.approx(0.75 - 0.68)
    text = train_text(
        {
            "out": "o",
            "best_val_accuracy": 0.76,
            "stages": 2,
            "epochs": 15,
            "wall_s": 3.0,
            "training_curve": "o/training_curve.png",
            "still_improving": [w],
        }
    )
    assert "training curve o/training_curve.png: train loss, and alignment accuracy" in text
    assert "still improving" in text and "try --epochs 20" in text


@pytest.mark.parametrize(
    "vals,why",
    [
        ([0.5, 0.6, 0.7, 0.7, 0.69, 0.68], "stopped early: fewer epochs than planned"),
        ([0.5, 0.6, 0.7, 0.7, 0.7, 0.7, 0.7, 0.7, 0.7, 0.705], "a rise of 0.005: a plateau"),
        ([0.5, 0.8, 0.7, 0.7, 0.7, 0.7, 0.7, 0.7, 0.7, 0.75], "best epoch 2, long before the end"),
    ],
)
def test_no_warning_for_a_stage_that_stopped_or_levelled_off(vals, why):
    assert still_improving(_history(1, vals), TrainConfig(data="d", out="o", stage1_epochs=10)) == [], why


def test_train_names_its_curve(tiny_data, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    args = ["train", "--data", str(tiny_data), "--out", str(tmp_path / "m"), "--freeze-language", "--epochs", "2"]
    args += ["--latent-dim", "8", "--device", "cpu"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["training_curve"] == str(tmp_path / "m" / "training_curve.png") and isinstance(
        out["still_improving"], list
    )


def test_tensorboard_without_the_package_is_one_line_before_training(tiny_data, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # as if tensorboard were not installed
    argv = ["train", "--data", str(tiny_data), "--out", str(tmp_path / "m"), "--tensorboard", str(tmp_path / "tb")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --tensorboard needs the tensorboard package: pip install tensorboard"]
    assert not (tmp_path / "m").exists()


def test_tensorboard_gets_each_epoch(tmp_path, monkeypatch):
    from langpref.cli.training import write_tensorboard

    written = []

    class Writer:
        def __init__(self, log_dir):
            written.append(("dir", log_dir))

        def add_scalar(self, tag, value, step):
            written.append((tag, value, step))

        def close(self):
            written.append(("closed",))

    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", types.SimpleNamespace(SummaryWriter=Writer))
    write_tensorboard(_history(1, [0.5, 0.6]) + _history(2, [0.7]), tmp_path / "tb")
    assert written[0] == ("dir", str(tmp_path / "tb")) and written[-1] == ("closed",)
    assert ("train/val_acc", 0.7, 3) in written and ("train/stage", 2.0, 3) in written


def _blocked(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("kept")
    return blocker


@pytest.mark.parametrize(
    "argv",
    [
        ["train", "--data", "{data}", "--out", "{blocked}/m"],
        ["evaluate", "--model", "{blocked}/m", "--data", "{data}", "--figure", "{blocked}/f.png"],
        ["bank", "check", "metaworld", "--figure", "{blocked}/f.png"],
        ["inspect", "{data}", "--figure", "{blocked}/f.png"],
        ["learn-reward", "--model", "m", "--data", "{data}", "--feedback", "language", "--save-reward", "{blocked}/r"],
        ["label", "{data}", "--reward", "r", "--out", "{blocked}/o"],
    ],
)
def test_an_unwritable_output_is_one_line_and_nothing_is_lost(tiny_data, tmp_path, capsys, argv):
    pytest.importorskip("matplotlib")
    blocker = _blocked(tmp_path)
    argv = [a.format(data=tiny_data, blocked=blocker) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and str(blocker) in err[0], err
    assert blocker.read_text() == "kept"


def test_evaluate_and_bank_check_say_what_chance_and_good_are(trained, tiny_data, capsys):
    assert main(["evaluate", "--model", str(trained.out), "--data", str(tiny_data), "--split", "val"]) == 0
    text = capsys.readouterr().out
    assert "chance: accuracy 0.5" in text and "good: 0.80 or more" in text, text
    assert main(["evaluate", "--model", str(trained.out), "--data", str(tiny_data), "--split", "val", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["chance"] == {"accuracy": 0.5, "reading_accuracy": 1 / 6} and out["good"] == 0.8
    assert main(["bank", "check", "metaworld"]) == 0
    text = capsys.readouterr().out
    assert "chance: 1/6 = 0.17" in text and "good: 0.80 or more per meaning" in text, text


def test_a_wait_says_what_it_does_at_a_terminal(capsys, monkeypatch):
    """At a terminal the command says what it loads before the seconds pass; in a pipe or a log it says nothing."""
    assert main(["embed", "--model", "no-such-model", "Faster."]) == 2
    assert capsys.readouterr().err.startswith("error:")  # not a terminal: no status line
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["embed", "--model", "no-such-model", "Faster."]) == 2
    first, *_ = capsys.readouterr().err.splitlines()
    assert first == "loading torch and the model no-such-model ..."
