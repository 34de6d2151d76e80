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
    monkeypatch.setattr(bank_cli, "_embedder", lambda args, task: (bag_of_words, "bag of words"))
    png = tmp_path / "bank.png"
    code, out, err = _run(capsys, "bank", "check", str(task), "--figure", str(png), "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["figure"] == str(png) and "height/decrease" in result["weak"]
    assert_picture(png)
    code, out, _ = _run(capsys, "bank", "check", str(task), "--figure", str(png))
    assert code == 0 and out.rstrip().endswith(f"figure {png}")
