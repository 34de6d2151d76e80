"""`langpref label` on a plain recording folder, and the command line: --json, one-line errors, --force, --task."""

from __future__ import annotations

import json
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from benchmarks.lerobot_check import write_random_reward
from langpref.cli import main
from langpref.dataset.label import RECORD, LabelConfig, label_dataset
from langpref.dataset.label_columns import COLUMNS, EPISODE, PROGRESS, SHARE
from langpref.dataset.recording import plain_episode_files, read_plain_episode
from langpref.errors import LangprefError
from langpref.reward.api import load

LENGTHS = (9, 14, 5)


def _recording(root: Path) -> Path:
    """Three episodes (6 state, 3 action numbers; one compressed npz, features and success), a video each but the
    last, a notes file and a sub-folder."""
    root.mkdir(parents=True)
    rng = np.random.default_rng(5)
    for i, length in enumerate(LENGTHS):
        arrays = {
            "observations": rng.normal(size=(length, 6)).astype(np.float32),
            "actions": rng.normal(size=(length, 3)).astype(np.float32),
            "features": rng.random(2),
            "success": np.array(i % 2 == 0),
        }
        (np.savez_compressed if i == 1 else np.savez)(root / f"ep{i}.npz", **arrays)
        if i < 2:
            (root / f"ep{i}.mp4").write_bytes(bytes(rng.integers(0, 255, 300, dtype=np.uint8)))
    (root / "notes.txt").write_text("recorded on Tuesday\n")
    (root / "extra").mkdir()
    (root / "extra" / "calibration.json").write_text("{}")
    return root


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    return _recording(tmp_path / "rec")


@pytest.fixture(scope="module", params=["linear", "mlp"])
def reward_path(request, tmp_path_factory) -> Path:
    return write_random_reward(tmp_path_factory.mktemp(f"reward-{request.param}"), 6, 3, kind=request.param)


def test_a_plain_recording_is_labelled_beside_its_own_bytes(recording, reward_path, tmp_path):
    out = tmp_path / "out"
    summary = label_dataset(
        LabelConfig(dataset=recording, reward=reward_path, out=out), load(reward_path), progress=False
    )
    assert (summary["episodes"], summary["frames"], summary["format"]) == (3, sum(LENGTHS), "plain")
    reward = load(reward_path)
    for path in plain_episode_files(recording):
        copy = out / path.name
        with zipfile.ZipFile(path) as a, zipfile.ZipFile(copy) as b:
            assert b.namelist()[: len(a.namelist())] == a.namelist()
            for info in a.infolist():
                assert b.read(info.filename) == a.read(info.filename)
                assert b.getinfo(info.filename).compress_type == info.compress_type
        with np.load(copy) as npz:
            share, progress, total = (npz[name] for name in (SHARE, PROGRESS, EPISODE))
        episode = read_plain_episode(path)
        expected = reward.trajectory_reward(episode.observations, episode.actions)
        assert share.dtype == np.float32 and share.shape == (len(episode.observations),)
        assert float(share.astype(np.float64).sum()) == pytest.approx(expected, rel=1e-5, abs=1e-5)
        assert progress[-1] == pytest.approx(expected, rel=1e-6, abs=1e-6) and np.all(total == np.float32(expected))
        again = read_plain_episode(copy)  # langpref's reader reads the copy as the original
        assert np.array_equal(again.observations, episode.observations) and again.success == episode.success
    assert (out / "ep0.mp4").stat().st_ino == (recording / "ep0.mp4").stat().st_ino
    assert (out / "notes.txt").read_text() == "recorded on Tuesday\n"
    assert (out / "extra" / "calibration.json").is_file()
    record = json.loads((out / RECORD).read_text())
    assert list(record["columns"]) == list(COLUMNS) and record["reward"]["task"] == "lerobot-fixture"


def test_a_labelled_episode_is_not_labelled_again(recording, reward_path, tmp_path):
    label_dataset(
        LabelConfig(dataset=recording, reward=reward_path, out=tmp_path / "once"), load(reward_path), progress=False
    )
    with pytest.raises(LangprefError, match="labelled before"):
        label_dataset(
            LabelConfig(dataset=tmp_path / "once", reward=reward_path, out=tmp_path / "twice"), load(reward_path), False
        )
    assert not (tmp_path / "twice").exists() and not list(tmp_path.glob(".twice.*"))


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_json_force_and_the_config_record(recording, reward_path, tmp_path, capsys):
    out = tmp_path / "out"
    started = time.perf_counter()
    code, stdout, _ = _run(capsys, "label", str(recording), "--reward", str(reward_path), "--out", str(out), "--json")
    took = time.perf_counter() - started
    assert code == 0
    summary = json.loads(stdout)
    assert summary["episodes"] == 3 and summary["frames"] == sum(LENGTHS) and summary["out"] == str(out)
    assert 0 < summary["seconds"] <= took + 0.01 and (out / "label.config.json").is_file()
    code, _, err = _run(capsys, "label", str(recording), "--reward", str(reward_path), "--out", str(out))
    assert code == 2 and "already exists; pass --force" in err and err.count("\n") == 1
    (out / "marker").write_text("old")
    code, _, _ = _run(capsys, "label", str(recording), "--reward", str(reward_path), "--out", str(out), "--force")
    assert code == 0 and not (out / "marker").exists() and (out / "ep0.npz").is_file()


@pytest.mark.parametrize(
    "case, message",
    [
        ("missing", "not found"),
        ("corrupt npz", "not a readable .npz episode"),
        ("corrupt info", "not readable JSON"),
        ("empty", "no episodes"),
        ("other task", "was learned on task 'lerobot-fixture', not 'kitchen'"),
        ("other sizes", "with observations of 39 and actions of 4 numbers"),
        ("no reward", "no saved reward"),
        ("out inside", "overlap"),
    ],
)
def test_cli_errors_are_one_line(case, message, recording, reward_path, tmp_path, capsys):
    src, reward, out, extra = recording, reward_path, tmp_path / "out", []
    if case == "missing":
        src = tmp_path / "nowhere"
    elif case == "corrupt npz":
        (recording / "ep1.npz").write_bytes(b"garbage")
    elif case == "corrupt info":
        (recording / "meta").mkdir()
        (recording / "meta" / "info.json").write_text("{not json")
    elif case == "empty":
        src = tmp_path / "empty"
        src.mkdir()
    elif case == "other task":
        extra = ["--task", "kitchen"]
    elif case == "other sizes":
        reward = write_random_reward(tmp_path / "other", 39, 4, task="drawer-open")
    elif case == "no reward":
        reward = tmp_path / "no-reward"
    elif case == "out inside":
        out = recording / "labelled"
    code, stdout, err = _run(capsys, "label", str(src), "--reward", str(reward), "--out", str(out), *extra)
    assert code == 2 and stdout == "" and message in err, err
    line = err.rsplit("\r", 1)[-1].splitlines()[-1]  # after the progress bar, if it started
    assert line.startswith("error: ") and message in line and err.endswith(line + "\n")
    assert not out.exists() and not list(out.parent.glob(f".{out.name}.*"))
