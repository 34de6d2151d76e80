"""`--figure PNG` of `inspect`, `bank check`, `evaluate` and `label`: each writes a real picture (a PNG that PIL reads,
of a readable size) and names it, in `--json` as `figure` and in the text output."""

from __future__ import annotations

import json
from pathlib import Path

from PIL import Image

from langpref.cli import main


def assert_picture(path: Path, min_size: tuple[int, int] = (600, 300)) -> None:
    """`path` is a PNG that PIL decodes, at least `min_size` pixels (width, height) and not one flat colour."""
    assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(path) as image:
        image.load()
        assert image.format == "PNG" and image.width >= min_size[0] and image.height >= min_size[1], image.size
        low, high = image.convert("L").getextrema()
        assert high - low > 100  # something is drawn on the white


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_inspect_draws_each_features_spread_and_the_correlations(synthetic_dataset, tmp_path, capsys):
    png = tmp_path / "figs" / "inspect.png"
    code, out, err = _run(capsys, "inspect", str(synthetic_dataset), "--figure", str(png), "--json")
    assert code == 0, err
    assert json.loads(out)["figure"] == str(png)
    assert_picture(png)
    code, out, _ = _run(capsys, "inspect", str(synthetic_dataset), "--figure", str(tmp_path / "again.png"))
    assert code == 0 and out.rstrip().endswith(f"figure {tmp_path / 'again.png'}")
    code, out, _ = _run(capsys, "inspect", str(synthetic_dataset), "--json")
    assert code == 0 and "figure" not in json.loads(out)


def test_bank_check_draws_which_meaning_is_read_as_which(tmp_path, capsys, monkeypatch):
    """Read with a bag of words (no language model): a meaning that copies another's phrasings shows as confused."""
    import langpref.cli.bank as bank_cli
    from tests.language.test_bank_check import BANK, _task_file, bag_of_words

    bank = json.loads(json.dumps(BANK))
    bank["height"]["decrease"] = list(bank["height"]["increase"])
    bank["speed"]["decrease"] = ["move slower"]  # too few to check: n/a
    task = _task_file(tmp_path, {s: bank for s in ("train", "val", "test")})
    monkeypatch.setattr(bank_cli, "bank_embedder", lambda args, task: (bag_of_words, "bag of words"))
    png = tmp_path / "bank.png"
    code, out, err = _run(capsys, "bank", "check", str(task), "--figure", str(png), "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["figure"] == str(png) and "height/decrease" in result["weak"]
    assert_picture(png)
    code, out, _ = _run(capsys, "bank", "check", str(task), "--figure", str(png))
    assert code == 0 and out.rstrip().endswith(f"figure {png}")


def test_label_draws_the_learned_reward_along_each_episode(tmp_path, capsys):
    from benchmarks.lerobot_check import write_random_reward
    from tests.dataset.test_label import _recording

    recording = _recording(tmp_path / "rec")
    reward = write_random_reward(tmp_path / "reward", 6, 3, kind="mlp")
    png, out = tmp_path / "figs" / "label.png", tmp_path / "out"
    argv = ["label", str(recording), "--reward", str(reward), "--out", str(out), "--figure", str(png)]
    code, stdout, err = _run(capsys, *argv, "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["figure"] == str(png) and summary["episodes"] == 3
    assert_picture(png)
    code, stdout, _ = _run(capsys, *argv, "--force")
    assert code == 0 and stdout.rstrip().endswith(f"figure {png}")


def test_label_draws_a_lerobot_datasets_episodes(tmp_path):
    from benchmarks.lerobot_check import write_random_reward
    from langpref.dataset.label import LabelConfig, label_dataset
    from langpref.reward.api import load
    from tests.dataset.test_label_lerobot import TINY

    reward = write_random_reward(tmp_path / "reward", 6, 3, kind="linear")
    cfg = LabelConfig(dataset=TINY, reward=reward, out=tmp_path / "out")
    summary = label_dataset(cfg, load(reward), progress=False, figure=tmp_path / "label.png")
    assert summary["figure"] == str(tmp_path / "label.png") and summary["episodes"] == 4
    assert_picture(tmp_path / "label.png")


def test_evaluate_draws_accuracy_per_feature_and_what_misread_phrasings_were_read_as(tmp_path, capsys):
    from tests.factories import untrained_checkpoint, write_dataset

    data = write_dataset(tmp_path / "data", env="metaworld", n=24, horizon=8, like_task=True)
    model = untrained_checkpoint(tmp_path / "model")
    png = tmp_path / "figs" / "evaluate.png"
    argv = ["evaluate", "--model", str(model), "--data", str(data), "--split", "train", "--device", "cpu"]
    code, out, err = _run(capsys, *argv, "--figure", str(png), "--json")
    assert code == 0, err
    assert json.loads(out)["figure"] == str(png)
    assert_picture(png)
    code, out, _ = _run(capsys, *argv, "--summary", "--figure", str(png))
    assert code == 0 and out.rstrip().endswith(f"figure {png}")


def test_the_evaluate_figure_names_the_misread_meanings(tmp_path):
    from langpref.model.evaluate import plot_evaluation

    misread = [{"text": f"t{i}", "meaning": "speed/decrease", "read_as": "speed/increase"} for i in range(5)]
    misread.append({"text": "u", "meaning": "height/increase", "read_as": "speed/increase"})
    out = {
        "accuracy": 0.7,
        "per_feature": {"speed": 0.45, "height": 0.9},
        "num_samples": 400,
        "split": "test",
        "utterances": "bank:test",
        "num_phrasings": 20,
        "reading_accuracy": 0.7,
        "misread": misread,
    }
    assert_picture(plot_evaluation(out, tmp_path / "e.png"))
    assert_picture(plot_evaluation({**out, "misread": []}, tmp_path / "none.png"))


def test_without_matplotlib_each_figure_fails_at_once_naming_the_extra(
    synthetic_dataset, tmp_path, capsys, monkeypatch
):
    """`require("plots")` comes before the long work: no model is loaded, nothing is labelled."""
    import langpref.extras

    real = langpref.extras.missing_modules
    monkeypatch.setattr(langpref.extras, "missing_modules", lambda e: ["matplotlib"] if e == "plots" else real(e))
    empty = tmp_path / "empty"
    empty.mkdir()
    png = str(tmp_path / "f.png")
    for argv in (
        ["inspect", str(synthetic_dataset)],
        ["bank", "check", "metaworld"],
        ["evaluate", "--model", str(empty), "--data", str(synthetic_dataset)],
        ["label", str(empty), "--reward", str(empty), "--out", str(tmp_path / "out")],
    ):
        code, out, err = _run(capsys, *argv, "--figure", png)
        assert code == 2 and out == "" and "pip install 'langpref[plots]'" in err, (argv, err)
    assert not (tmp_path / "out").exists() and not (tmp_path / "f.png").exists()
