"""`langpref label` on a LeRobotDataset v3 (tests/fixtures/lerobot, written by lerobot itself), checked without
lerobot: the label columns sum to the learned reward, the original columns keep their bytes, meta/ lists the new
columns as lerobot does, and langpref's own reader reads the copy as it read the original. `make lerobot-check`
shows LeRobot's `LeRobotDataset` loading the same copies."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from benchmarks.lerobot_check import write_random_reward
from langpref.dataset.label import LabelConfig, label_dataset
from langpref.dataset.label_columns import COLUMNS, EPISODE, PROGRESS, SHARE
from langpref.dataset.lerobot import read_lerobot
from langpref.errors import LangprefError
from langpref.reward.api import load

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "lerobot"
TINY, IMAGES = FIXTURES / "tiny", FIXTURES / "tiny-images"
DATA = Path("data/chunk-000/file-000.parquet")
EPISODES = Path("meta/episodes/chunk-000/file-000.parquet")
VIDEO = Path("videos/observation.images.front/chunk-000/file-000.mp4")


@pytest.fixture(scope="module", params=["linear", "mlp"])
def reward_path(request, tmp_path_factory) -> Path:
    """A saved reward for the fixture's sizes (6 state, 3 action numbers); the mlp's shares depend on the history."""
    return write_random_reward(tmp_path_factory.mktemp(f"reward-{request.param}"), 6, 3, kind=request.param)


@pytest.fixture(scope="module")
def labelled(reward_path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("labelled") / "tiny"
    summary = label_dataset(LabelConfig(dataset=TINY, reward=reward_path, out=out), load(reward_path), progress=False)
    assert (summary["episodes"], summary["frames"], summary["format"]) == (4, 51, "lerobot")
    return out


def _ipc_bytes(column: pa.ChunkedArray) -> bytes:
    """A column's values as Arrow IPC bytes: equal bytes, equal column (type, chunks and every value)."""
    sink = pa.BufferOutputStream()
    table = pa.table({"c": column})
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue().to_pybytes()


def _label_frames(out: Path) -> dict[int, dict[str, np.ndarray]]:
    """{episode_index: {column: values in frame order}} of the label columns of the copy's data file."""
    table = pq.read_table(out / DATA)
    episode, frame = table.column("episode_index").to_numpy(), table.column("frame_index").to_numpy()
    result = {}
    for index in np.unique(episode):
        rows = np.flatnonzero(episode == index)
        rows = rows[np.argsort(frame[rows])]
        result[int(index)] = {name: table.column(name).to_numpy()[rows] for name in COLUMNS}
    return result


def test_per_frame_rewards_sum_to_the_trajectory_reward(labelled, reward_path):
    reward = load(reward_path)
    frames = _label_frames(labelled)
    for index, episode in enumerate(read_lerobot(TINY, camera="")):
        cols = frames[index]
        total = reward.trajectory_reward(episode.observations, episode.actions)
        assert cols[SHARE].dtype == np.float32
        assert float(cols[SHARE].astype(np.float64).sum()) == pytest.approx(total, rel=1e-5, abs=1e-5)
        assert cols[PROGRESS][-1] == pytest.approx(total, rel=1e-6, abs=1e-6)
        assert np.all(cols[EPISODE] == np.float32(total))
        assert np.allclose(cols[PROGRESS], reward.progress(episode.observations, episode.actions), rtol=1e-6)


def test_every_original_column_keeps_its_bytes(labelled):
    for rel in (DATA, EPISODES):
        original, copy = pq.read_table(TINY / rel), pq.read_table(labelled / rel)
        assert copy.column_names[: original.num_columns] == original.column_names
        for name in original.column_names:
            assert _ipc_bytes(copy.column(name)) == _ipc_bytes(original.column(name)), (rel, name)
    before, after = pq.ParquetFile(TINY / DATA).metadata, pq.ParquetFile(labelled / DATA).metadata
    assert [before.row_group(i).num_rows for i in range(before.num_row_groups)] == [
        after.row_group(i).num_rows for i in range(after.num_row_groups)
    ]
    assert (labelled / "meta/tasks.parquet").read_bytes() == (TINY / "meta/tasks.parquet").read_bytes()
    assert (labelled / VIDEO).read_bytes() == (TINY / VIDEO).read_bytes()
    assert (labelled / VIDEO).stat().st_ino == (TINY / VIDEO).stat().st_ino or (labelled / VIDEO).stat().st_nlink == 1


def test_info_and_stats_list_the_new_columns(labelled):
    info = json.loads((labelled / "meta/info.json").read_text())
    original = json.loads((TINY / "meta/info.json").read_text())
    assert {k: v for k, v in info.items() if k != "features"} == {k: v for k, v in original.items() if k != "features"}
    assert {k: info["features"][k] for k in original["features"]} == original["features"]
    for name in COLUMNS:
        assert info["features"][name] == {"dtype": "float32", "shape": [1], "names": None}
    stats = json.loads((labelled / "meta/stats.json").read_text())
    assert {k: stats[k] for k in json.loads((TINY / "meta/stats.json").read_text())} == json.loads(
        (TINY / "meta/stats.json").read_text()
    )
    frames = np.concatenate([cols[SHARE] for cols in _label_frames(labelled).values()]).astype(np.float64)
    share = stats[SHARE]
    assert set(share) == {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
    assert share["count"] == [51] and share["min"] == [frames.min()] and share["max"] == [frames.max()]
    assert share["mean"][0] == pytest.approx(frames.mean()) and share["q50"][0] == pytest.approx(np.median(frames))
    schema = pq.read_schema(labelled / DATA)
    hf = json.loads(schema.metadata[b"huggingface"])["info"]["features"]
    assert all(hf[name] == {"dtype": "float32", "_type": "Value"} for name in COLUMNS)
    episodes = pq.read_table(labelled / EPISODES)
    assert episodes.column(f"stats/{EPISODE}/count").to_pylist() == [[12], [15], [10], [14]]
    totals = [cols[EPISODE][0] for cols in _label_frames(labelled).values()]
    assert np.allclose([m[0] for m in episodes.column(f"stats/{EPISODE}/mean").to_pylist()], totals)


def test_lerobots_reward_and_rabc_progress_are_written(labelled):
    """LeRobot's `next.reward` holds r_t; the RA-BC sidecar's progress rises by each frame's reward, on [0, 1]."""
    info = json.loads((labelled / "meta/info.json").read_text())
    assert info["features"]["next.reward"] == {"dtype": "float32", "shape": [1], "names": None}
    data = pq.read_table(labelled / DATA)
    assert np.array_equal(data.column("next.reward").to_numpy(), data.column(SHARE).to_numpy())
    side = pq.read_table(labelled / "sarm_progress.parquet")
    assert side.column_names == ["index", "episode_index", "frame_index", "progress_sparse"]
    assert side.column("index").to_pylist() == data.column("index").to_pylist()
    progress = side.column("progress_sparse").to_numpy().astype(np.float64)
    assert progress.min() == pytest.approx(0.0) and progress.max() == pytest.approx(1.0)
    episode = side.column("episode_index").to_numpy()
    share = data.column(SHARE).to_numpy().astype(np.float64)
    for ep in np.unique(episode):
        rows = episode == ep
        rises = np.diff(progress[rows])
        scale = rises[np.argmax(np.abs(share[rows][1:]))] / share[rows][1:][np.argmax(np.abs(share[rows][1:]))]
        assert scale > 0 and np.allclose(rises, share[rows][1:] * scale, atol=1e-5)


def test_langprefs_reader_reads_the_copy_as_the_original(labelled):
    before, after = read_lerobot(TINY), read_lerobot(labelled)
    assert [e.name for e in after] == [e.name for e in before]
    for a, b in zip(before, after):
        assert np.array_equal(a.observations, b.observations) and np.array_equal(a.actions, b.actions)
        assert a.success == b.success
        assert (b.video.start_s, b.video.end_s) == (a.video.start_s, a.video.end_s)
        assert b.video.path == labelled / VIDEO


def test_an_image_dataset_is_labelled_and_reads_back(reward_path, tmp_path):
    out = tmp_path / "images"
    label_dataset(LabelConfig(dataset=IMAGES, reward=reward_path, out=out), load(reward_path), progress=False)
    before, after = read_lerobot(IMAGES, images=True), read_lerobot(out, images=True)
    assert [b.images.cells for b in after] == [a.images.cells for a in before]
    original = pq.read_table(IMAGES / DATA)
    copy = pq.read_table(out / DATA)
    for name in original.column_names:
        assert _ipc_bytes(copy.column(name)) == _ipc_bytes(original.column(name)), name


def test_a_labelled_copy_is_not_labelled_again(labelled, reward_path, tmp_path):
    with pytest.raises(LangprefError, match="labelled before"):
        label_dataset(
            LabelConfig(dataset=labelled, reward=reward_path, out=tmp_path / "again"), load(reward_path), progress=False
        )
    assert not (tmp_path / "again").exists() and not list(tmp_path.glob(".again.*"))


def test_a_reward_for_other_sizes_is_refused(tmp_path):
    other = write_random_reward(tmp_path / "other", 39, 4, task="drawer-open")
    with pytest.raises(LangprefError, match=r"task 'drawer-open' with observations of 39 .* has 6 and 3"):
        label_dataset(LabelConfig(dataset=TINY, reward=other, out=tmp_path / "out"), load(other), progress=False)
    assert not (tmp_path / "out").exists()


def test_a_corrupt_data_file_is_one_line(reward_path, tmp_path):
    import shutil

    broken = Path(shutil.copytree(TINY, tmp_path / "broken"))
    (broken / DATA).write_bytes(b"not parquet")
    with pytest.raises(LangprefError, match="not a readable parquet file") as err:
        label_dataset(
            LabelConfig(dataset=broken, reward=reward_path, out=tmp_path / "out"), load(reward_path), progress=False
        )
    assert "\n" not in str(err.value) and not (tmp_path / "out").exists()
