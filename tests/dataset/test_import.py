"""`langpref import`: both recording layouts into a dataset, features from a function or from the files, and every
kind of bad input as one line naming the file and the key, with nothing half-written left behind."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from langpref.dataset.importer import ImportConfig, import_recording
from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.language.bank import check_bank, load_bank, split_bank
from langpref.tasks import get_task
from langpref.tasks.taskfile import read_task_file

LEROBOT_FIXTURE = Path(__file__).parents[1] / "fixtures" / "lerobot" / "tiny"
BANK = {
    "reach": {
        "increase": [
            "Reach further.",
            "Stretch out more.",
            "Extend your arm more.",
            "Go further out.",
            "Reach out farther.",
        ],
        "decrease": ["Reach less.", "Stay closer in.", "Keep your arm in.", "Don't reach so far.", "Pull back more."],
    },
    "effort": {
        "increase": ["Push harder.", "Use more force.", "Put more effort in.", "Be more forceful."],
        "decrease": ["Push softer.", "Use less force.", "Be gentler.", "Go easy."],
    },
}
FEATURES_PY = """import numpy as np


def step_features(observations, actions):
    return np.stack([observations[:, 0], np.abs(actions).sum(axis=1)], axis=1)


def wrong_shape(observations, actions):
    return observations[:, :1]


def broken(observations, actions):
    raise RuntimeError("sensor table missing")
"""


def write_task(
    root: Path,
    features_from: str | None = "features.py:step_features",
    bank: dict | None = None,
    name: str = "toy-reach",
) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "features.py").write_text(FEATURES_PY)
    (root / "bank.json").write_text(json.dumps(bank or BANK))
    line = f'features_from = "{features_from}"\n' if features_from else ""
    (root / "task.toml").write_text(
        f'name = "{name}"\ndescription = "A robot reaches for a cup."\nfeatures = ["reach", "effort"]\n{line}'
        'utterances = "bank.json"\nexamples = ["Reach further."]\n'
        '[feature_descriptions]\nreach = "how far it reaches"\n'
    )
    return root / "task.toml"


def write_plain(root: Path, n: int = 8, with_features: bool = False, seed: int = 0) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i in range(n):
        steps = 10 + 3 * i  # every episode a different length
        extra = {"features": rng.normal(size=2)} if with_features else {}
        np.savez(
            root / f"ep{i:02d}.npz",
            observations=rng.normal(size=(steps, 5)).astype(np.float32),
            actions=rng.normal(size=(steps, 2)).astype(np.float32),
            success=np.array(i % 2 == 0),
            **extra,
        )
    (root / "notes.txt").write_text("other files are ignored")
    return root


def run_import(src: Path, task_file: Path, out: Path, **kw):
    task = read_task_file(task_file)
    bank = split_bank(task.utterances, task.features, seed=kw.get("seed", 0))
    check_bank(bank, task.name, task.features, str(task.utterances))
    return import_recording(ImportConfig(src=src, task=task_file, out=out, **kw), task, bank, progress=False)


def test_plain_folder_with_feature_function(tmp_path):
    summary = run_import(write_plain(tmp_path / "rec"), write_task(tmp_path / "task"), tmp_path / "ds")
    assert summary["num_trajectories"] == 8 and summary["layout"] == "plain" and not summary["videos"]
    ds = load_dataset(tmp_path / "ds")
    assert ds.env == "toy-reach" and ds.feature_names == ["reach", "effort"]
    assert sorted(i for s in ds.meta.splits.values() for i in s) == list(range(8))
    assert all(len(ds.split(s)) >= 2 for s in ("train", "val", "test"))
    traj = ds.load(3)
    assert traj.horizon == 19 and traj.qpos is None and traj.source == "ep03"
    expected = np.stack([traj.observations[:, 0], np.abs(traj.actions).sum(axis=1)], axis=1).mean(axis=0)
    np.testing.assert_allclose(ds.features[3], expected, rtol=1e-5)
    assert ds.meta.lengths == [10 + 3 * i for i in range(8)] and ds.meta.horizon == 31
    obs, act = ds.arrays("train")
    assert obs.shape[1] == 31 and ds.lengths("train").max() <= 31
    # the task and its split bank travel with the dataset
    task = get_task("toy-reach")
    assert task.simulator is None and task.feature_descriptions[0] == "how far it reaches"
    bank = load_bank("toy-reach")
    for feature in ("reach", "effort"):
        for direction in ("increase", "decrease"):
            assert all(bank.get(split, feature, direction) for split in ("train", "val", "test"))


def test_plain_folder_with_features_in_the_files(tmp_path):
    run_import(write_plain(tmp_path / "rec", with_features=True), write_task(tmp_path / "task", None), tmp_path / "ds")
    ds = load_dataset(tmp_path / "ds")
    with np.load(tmp_path / "rec" / "ep02.npz") as npz:
        np.testing.assert_allclose(ds.features[2], npz["features"], rtol=1e-6)


def test_a_split_bank_is_used_as_given(tmp_path):
    split = {
        s: {
            f: {d: [f"{s} {f} {d} {k}." for k in range(2)] for d in ("increase", "decrease")}
            for f in ("reach", "effort")
        }
        for s in ("train", "val", "test")
    }
    run_import(
        write_plain(tmp_path / "rec"), write_task(tmp_path / "task", bank=split, name="split-bank"), tmp_path / "ds"
    )
    load_dataset(tmp_path / "ds")
    assert load_bank("split-bank").get("val", "reach", "increase") == ("val reach increase 0.", "val reach increase 1.")


def test_the_same_seed_gives_the_same_dataset(tmp_path):
    rec, task = write_plain(tmp_path / "rec"), write_task(tmp_path / "task")
    run_import(rec, task, tmp_path / "a", seed=3)
    run_import(rec, task, tmp_path / "b", seed=3)
    for name in ("meta.json", "features.npy", "utterances.json", "trajectories/000005.npz"):
        if name == "meta.json":
            a, b = (json.loads((tmp_path / d / name).read_text()) for d in "ab")
            assert a["splits"] == b["splits"]
        else:
            assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_lerobot_fixture_written_by_lerobot(tmp_path):
    """The committed fixture, written by lerobot's own LeRobotDataset writer: 4 episodes, one camera (AV1)."""
    from langpref.dataset.video import check_video

    summary = run_import(LEROBOT_FIXTURE, write_task(tmp_path / "task", name="lerobot-tiny"), tmp_path / "ds")
    assert (
        summary["layout"] == "lerobot" and summary["videos"] and summary["splits"] == {"train": 2, "val": 1, "test": 1}
    )
    ds = load_dataset(tmp_path / "ds")
    assert [ds.load(i).horizon for i in range(4)] == [12, 15, 10, 14]
    assert ds.meta.obs_dim == 6 and ds.meta.action_dim == 3
    assert [ds.load(i).source for i in range(4)] == [f"episode_{i:06d}" for i in range(4)]
    for i, steps in enumerate([12, 15, 10, 14]):
        frames, _ = check_video(ds.video_path(i))  # cut out of the shared file and made browser-playable
        assert abs(frames - steps) <= 1


BAD_CASES = [
    ("truncated", "ep00.npz", "not a readable .npz"),
    ("missing_key", "ep01.npz", "missing key 'actions'"),
    ("mismatch", "ep02.npz", "'observations' has 12 steps but 'actions' has 11"),
    ("dims", "ep03.npz", "dims, earlier episodes"),
    ("nan", "ep04.npz", "NaN"),
]


@pytest.mark.parametrize("case,file,message", BAD_CASES)
def test_bad_episodes_name_the_file_and_leave_nothing(tmp_path, case, file, message):
    rec = write_plain(tmp_path / "rec")
    path = rec / file
    if case == "truncated":
        path.write_bytes(path.read_bytes()[:100])
    elif case == "missing_key":
        np.savez(path, observations=np.zeros((5, 5), np.float32))
    elif case == "mismatch":
        np.savez(path, observations=np.zeros((12, 5), np.float32), actions=np.zeros((11, 2), np.float32))
    elif case == "dims":
        np.savez(path, observations=np.zeros((12, 6), np.float32), actions=np.zeros((12, 2), np.float32))
    elif case == "nan":
        obs = np.zeros((12, 5), np.float32)
        obs[3, 1] = np.nan
        np.savez(path, observations=obs, actions=np.zeros((12, 2), np.float32))
    with pytest.raises(LangprefError) as info:
        run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    msg = str(info.value)
    assert "\n" not in msg and file in msg and message in msg, msg
    assert not (tmp_path / "ds").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".ds")]


@pytest.mark.parametrize(
    "ref,message",
    [
        ("nofile.py:step_features", "nofile.py not found"),
        ("features.py:nothing", "has no function 'nothing'"),
        ("features.py:wrong_shape", "returned shape (10, 1), expected (10, 2)"),
        ("features.py:broken", "sensor table missing"),
    ],
)
def test_bad_feature_functions(tmp_path, ref, message):
    with pytest.raises(LangprefError, match=message.replace("(", r"\(").replace(")", r"\)")):
        run_import(write_plain(tmp_path / "rec"), write_task(tmp_path / "task", ref), tmp_path / "ds")
    assert not (tmp_path / "ds").exists()


def test_no_features_anywhere(tmp_path):
    with pytest.raises(LangprefError, match="no features"):
        run_import(write_plain(tmp_path / "rec"), write_task(tmp_path / "task", None), tmp_path / "ds")


def test_a_video_that_does_not_decode(tmp_path):
    rec = write_plain(tmp_path / "rec", n=6)
    import imageio.v2 as imageio

    for i in range(6):
        frames = np.full((4, 32, 32, 3), 40 * i, np.uint8)
        imageio.mimwrite(rec / f"ep{i:02d}.mp4", frames, fps=10, codec="libx264", macro_block_size=8)
    (rec / "ep04.mp4").write_bytes(b"not a video at all")
    with pytest.raises(LangprefError, match="ep04.mp4"):
        run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    assert not (tmp_path / "ds").exists()


def test_videos_are_imported(tmp_path):
    import imageio.v2 as imageio

    rec = write_plain(tmp_path / "rec", n=6)
    for i in range(6):
        imageio.mimwrite(
            rec / f"ep{i:02d}.mp4",
            np.full((4, 32, 32, 3), 40 * i, np.uint8),
            fps=10,
            codec="libx264",
            macro_block_size=8,
        )
    summary = run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    assert summary["videos"]
    ds = load_dataset(tmp_path / "ds")
    assert ds.video_path(2).read_bytes() == (rec / "ep02.mp4").read_bytes()  # browser-playable: copied as is
    # `langpref render` of a recorded trajectory is its recording, never a simulator replay
    from langpref.dataset.render import render_trajectory
    from langpref.dataset.video import check_video

    assert render_trajectory(tmp_path / "ds", 2, tmp_path / "a.mp4").read_bytes() == ds.video_path(2).read_bytes()
    frames, _ = check_video(render_trajectory(tmp_path / "ds", 3, tmp_path / "b.webm"))
    assert frames == 4


@pytest.mark.parametrize(
    "toml,message",
    [
        ('description = "x"\nfeatures = ["a"]\nutterances = "bank.json"\n', "'name'"),
        ('name = "Bad Name"\ndescription = "x"\nfeatures = ["a"]\nutterances = "bank.json"\n', "must be lowercase"),
        ('name = "t"\ndescription = "x"\nfeatures = []\nutterances = "bank.json"\n', "at least one feature"),
        ('name = "t"\ndescription = "x"\nfeatures = ["a"]\nutterances = "missing.json"\n', "missing.json not found"),
        ('name = "t"\ndescription = "x"\nfeatures = ["a"]\nutterances = "bank.json"\ncolour = 1\n', "unknown key"),
        ('name = "t"\ndescription = "x"\nfeatures = ["a"\n', "not valid TOML"),
        ('name = "metaworld"\ndescription = "x"\nfeatures = ["a"]\nutterances = "bank.json"\n', None),
    ],
)
def test_bad_task_files(tmp_path, toml, message):
    (tmp_path / "bank.json").write_text(json.dumps(BANK))
    (tmp_path / "task.toml").write_text(toml)
    if message is None:  # a recorded task may not take a built-in task's name
        task = read_task_file(tmp_path / "task.toml")
        from langpref.tasks import register_task

        with pytest.raises(LangprefError, match="built-in"):
            register_task(task.task(5, 2, tmp_path / "bank.json"))
        return
    with pytest.raises(LangprefError, match=message) as info:
        read_task_file(tmp_path / "task.toml")
    assert "task.toml" in str(info.value)


def test_an_unsplit_bank_needs_three_phrasings(tmp_path):
    bank = {
        "reach": {"increase": ["Reach further.", "Go further."], "decrease": ["a.", "b.", "c."]},
        "effort": BANK["effort"],
    }
    task = read_task_file(write_task(tmp_path / "task", bank=bank))
    with pytest.raises(LangprefError, match="reach.increase has 2 distinct"):
        split_bank(task.utterances, task.features)


def test_cli_import_and_errors(tmp_path):
    rec, task = write_plain(tmp_path / "rec"), write_task(tmp_path / "task")
    cmd = [
        sys.executable,
        "-m",
        "langpref.cli",
        "import",
        str(rec),
        "--task",
        str(task),
        "--out",
        str(tmp_path / "ds"),
        "--json",
    ]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["num_trajectories"] == 8
    assert "bank check of toy-reach" in out.stderr and "bank_check" in json.loads(out.stdout)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and again.stderr.startswith("error:") and "already exists" in again.stderr
    typo = subprocess.run([*cmd[:4], str(tmp_path / "recc"), *cmd[5:]], capture_output=True, text=True, timeout=120)
    assert typo.returncode == 2 and "not found" in typo.stderr and len(typo.stderr.strip().splitlines()) == 1


def test_cli_import_warns_on_a_weak_meaning(tmp_path, capsys):
    """A meaning read as another feature is warned about; one read as its own opposite direction (near-copies of
    the opposite here, as a frozen general model reads most directions before training) is explained in a note
    that says what to look at after `train`, not a warning."""
    from langpref.cli import main

    bank = json.loads(json.dumps(BANK))
    bank["effort"]["decrease"] = [t.replace(".", ", please.") for t in bank["effort"]["increase"]]  # near-copies
    bank["reach"]["increase"] = [t.replace(".", " now.") for t in BANK["effort"]["increase"]] + ["Push on."]
    rec, task = write_plain(tmp_path / "rec"), write_task(tmp_path / "task", bank=bank)
    assert main(["import", str(rec), "--task", str(task), "--out", str(tmp_path / "ds"), "--json"]) == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    summary = [line for line in lines if line.startswith("bank check of toy-reach")]
    assert len(summary) == 1 and "meanings weak" in summary[0]
    assert any(line.startswith("chance: 1/4 = 0.25") and "good: 0.80" in line for line in lines), lines
    assert any(line.startswith("warning: weak meaning reach/increase") for line in lines), lines
    assert not any(line.startswith("warning: weak meaning effort/decrease") for line in lines), lines
    note = [line for line in lines if line.startswith("note:")]
    assert len(note) == 1 and "effort/decrease" in note[0] and "expected" in note[0] and "evaluate" in note[0]
    checked = json.loads(captured.out)["bank_check"]
    assert "effort/decrease" in checked["weak"] and "effort/decrease" in checked["weak_opposite_direction"]
    assert "reach/increase" not in checked["weak_opposite_direction"]
    assert main(["import", str(rec), "--task", str(task), "--out", str(tmp_path / "ds2"), "--no-bank-check"]) == 0
    assert "bank check" not in capsys.readouterr().err


def test_every_bad_episode_is_named_in_one_error(tmp_path):
    """Three bad episodes of eight: one error names all three, so the lab fixes them in one go."""
    rec = write_plain(tmp_path / "rec")
    (rec / "ep01.npz").write_bytes(b"truncated")
    np.savez(rec / "ep04.npz", observations=np.zeros((5, 5), np.float32))
    np.savez(rec / "ep06.npz", observations=np.zeros((12, 5), np.float32), actions=np.zeros((11, 2), np.float32))
    with pytest.raises(LangprefError) as info:
        run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    msg = str(info.value)
    assert msg.startswith("3 of 8 episodes are bad"), msg
    assert all(name in msg for name in ("ep01.npz", "ep04.npz", "ep06.npz")), msg
    assert "missing key 'actions'" in msg and "has 12 steps but 'actions' has 11" in msg
    assert not (tmp_path / "ds").exists()


def test_many_bad_episodes_are_named_up_to_a_limit(tmp_path):
    from langpref.dataset.importer import MAX_NAMED

    rec = write_plain(tmp_path / "rec", n=MAX_NAMED + 5)
    for path in sorted(rec.glob("*.npz")):
        np.savez(path, observations=np.zeros((5, 5), np.float32))
    with pytest.raises(LangprefError) as info:
        run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    msg = str(info.value)
    assert msg.startswith(f"{MAX_NAMED + 5} of {MAX_NAMED + 5} episodes are bad") and "and 5 more" in msg, msg
    assert f"ep{MAX_NAMED - 1:02d}.npz" in msg and f"ep{MAX_NAMED:02d}.npz" not in msg


def test_an_orphan_video_is_warned_about(tmp_path):
    import imageio.v2 as imageio

    rec = write_plain(tmp_path / "rec", n=6)
    for i in range(7):  # ep06.mp4: its episode is gone
        frames = np.full((4, 32, 32, 3), 30 * i, np.uint8)
        imageio.mimwrite(rec / f"ep{i:02d}.mp4", frames, fps=10, codec="libx264", macro_block_size=8)
    summary = run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds")
    orphans = [w for w in summary["warnings"] if "ep06.mp4" in w]
    assert len(orphans) == 1 and "no episode" in orphans[0], summary["warnings"]


def test_a_small_recording_is_warned_about_with_its_size(tmp_path):
    from langpref.dataset.importer import MIN_EPISODES

    small = run_import(write_plain(tmp_path / "rec", n=7), write_task(tmp_path / "task"), tmp_path / "ds")
    warned = [w for w in small["warnings"] if "7 episodes" in w]
    assert len(warned) == 1 and "train 3, val 2, test 2" in warned[0] and str(MIN_EPISODES) in warned[0], warned
    enough = run_import(write_plain(tmp_path / "rec2", n=MIN_EPISODES), write_task(tmp_path / "task"), tmp_path / "ds2")
    assert enough["warnings"] == []


def test_cli_import_prints_the_warnings(tmp_path, capsys):
    from langpref.cli import main

    rec, task = write_plain(tmp_path / "rec", n=7), write_task(tmp_path / "task")
    assert main(["import", str(rec), "--task", str(task), "--out", str(tmp_path / "ds"), "--no-bank-check"]) == 0
    err = capsys.readouterr().err
    assert any(line.startswith("warning: only 7 episodes") for line in err.splitlines()), err


def test_an_unwritable_out_is_one_line_and_writes_nothing(tmp_path, capsys):
    from langpref.cli import main

    rec, task = write_plain(tmp_path / "rec"), write_task(tmp_path / "task")
    blocker = tmp_path / "file"
    blocker.write_text("a file where a folder should be")
    assert main(["import", str(rec), "--task", str(task), "--out", str(blocker / "ds"), "--no-bank-check"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "--out" in err and len(err.splitlines()) == 1, err
    assert blocker.read_text() == "a file where a folder should be"


def test_inspect_prints_the_range_of_episode_lengths(tmp_path):
    from langpref.dataset.inspect import describe, format_description

    run_import(write_plain(tmp_path / "rec"), write_task(tmp_path / "task"), tmp_path / "ds")
    d = describe(tmp_path / "ds")
    assert d["lengths"] == {"min": 10, "max": 31, "mean": 20.5}
    assert "8 trajectories of 10-31 steps (mean 20)" in format_description(d).splitlines()[0]
