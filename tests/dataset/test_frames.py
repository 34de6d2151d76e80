"""Camera frames in datasets: rendered by `generate --images`, decoded from recorded videos by `import --images`,
stored compressed apart from the numbers and read only when asked; datasets without them stay as they were."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from test_import import run_import, write_plain, write_task

from langpref.dataset.checksum import checksum_parts
from langpref.dataset.frames import FrameOptions, FrameSpec, frame_index, render_trajectory_frames, save_frames
from langpref.dataset.generate import GenerateConfig, generate
from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError

IMAGES = FrameOptions(images=True, frame_size=(32, 24), frame_stride=4)


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    root = tmp_path_factory.mktemp("frames") / "mw"
    cfg = GenerateConfig(env="metaworld", out=root, num_trajectories=3, horizon=10, workers=1, seed=2, frames=IMAGES)
    generate(cfg)
    return root


def test_generate_images_stores_small_frames_of_every_kth_step(generated):
    ds = load_dataset(generated)
    assert ds.meta.schema_version == 3
    assert ds.frame_spec == FrameSpec(width=32, height=24, stride=4, source="render")
    frames = ds.frames()
    assert frames.shape == (3, 3, 24, 32, 3) and frames.dtype == np.uint8  # steps 0, 4, 8 of 10
    assert frames[0, 0].std() > 10  # a real scene, not a blank image
    assert not np.array_equal(frames[0, 0], frames[0, 2])  # the arm moved
    # the stored frames are the replay of the stored states: new rollouts get the same ones
    from langpref.tasks import make_env

    env = make_env("metaworld", 10)
    try:
        again = render_trajectory_frames(env, ds.load(1), ds.frame_spec)
    finally:
        env.close()
    np.testing.assert_array_equal(again, frames[1])
    config = json.loads((generated / "generate_config.json").read_text())
    assert config["frames"] == ds.meta.frames
    parts = checksum_parts(ds)
    assert set(parts) == {"meta", "features", "trajectories", "frames"}  # the frames enter the checksum


def test_a_dataset_without_frames_is_written_as_before(tmp_path):
    root = tmp_path / "plain"
    generate(GenerateConfig(env="metaworld", out=root, num_trajectories=3, horizon=4, workers=1))
    meta = json.loads((root / "meta.json").read_text())
    assert meta["schema_version"] == 2 and "frames" not in meta and not (root / "frames").exists()
    assert "frames" not in json.loads((root / "generate_config.json").read_text())
    ds = load_dataset(root)
    assert ds.frame_spec is None
    with pytest.raises(LangprefError, match="no camera frames.*--images"):
        ds.frames("train")


@pytest.mark.parametrize(
    "options, message",
    [
        (FrameOptions(images=True, frame_size=(8, 64)), "--frame-size 8,64 must be WIDTH,HEIGHT"),
        (FrameOptions(images=True, frame_size=(64,)), "--frame-size 64 must be WIDTH,HEIGHT"),
        (FrameOptions(images=True, frame_size=(64, 1024)), "between 16 and 512"),
        (FrameOptions(images=True, frame_stride=0), "--frame-stride must be at least 1"),
    ],
)
def test_a_bad_frame_size_or_stride_is_one_line(tmp_path, options, message):
    with pytest.raises(LangprefError, match=message) as info:
        GenerateConfig(env="metaworld", out=tmp_path / "d", frames=options).resolved()
    assert "\n" not in str(info.value)
    assert not (tmp_path / "d").exists()


def test_a_damaged_frames_file_is_one_line(generated, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(generated, copy)
    (copy / "frames" / "000001.npz").write_bytes(b"not a zip")
    with pytest.raises(LangprefError, match="000001.npz is truncated or corrupt"):
        load_dataset(copy).frames()
    save_frames(copy, 1, np.zeros((2, 24, 32, 3), np.uint8))  # one frame short
    with pytest.raises(LangprefError, match=r"meta.json says \(3, 24, 32, 3\)"):
        load_dataset(copy).frames()


def test_frame_index_holds_each_kept_frame_and_stays_within_a_trajectory():
    idx = frame_index(np.array([7, 3]), 7, 3)
    np.testing.assert_array_equal(idx, [[0, 0, 0, 1, 1, 1, 2], [0, 0, 0, 0, 0, 0, 0]])


def _videos(rec, n, lengths):
    """One mp4 per episode, a frame per step; frame t of episode i is grey level 20 + 5 t + 10 i."""
    import imageio.v2 as imageio

    for i in range(n):
        frames = np.stack([np.full((48, 64, 3), 20 + 5 * t + 10 * i, np.uint8) for t in range(lengths[i])])
        imageio.mimwrite(rec / f"ep{i:02d}.mp4", frames, fps=10, codec="libx264", macro_block_size=8)


def test_import_images_decodes_every_kth_frame_of_the_recorded_videos(tmp_path):
    rec = write_plain(tmp_path / "rec", n=6)  # episode i has 10 + 3 i steps
    lengths = [10 + 3 * i for i in range(6)]
    _videos(rec, 6, lengths)
    options = FrameOptions(images=True, frame_size=(16, 16), frame_stride=3)
    summary = run_import(rec, write_task(tmp_path / "task"), tmp_path / "ds", frames=options)
    assert summary["frames"] == {"width": 16, "height": 16, "stride": 3, "source": "video"}
    ds = load_dataset(tmp_path / "ds")
    assert ds.meta.schema_version == 3 and ds.meta.lengths == lengths
    frames = ds.frames()
    assert frames.shape == (6, 9, 16, 16, 3)  # ceil(25 / 3) frames for the longest, the others padded
    for i in (0, 5):
        kept = np.arange(0, lengths[i], 3)
        grey = frames[i, : len(kept)].mean(axis=(1, 2, 3))
        np.testing.assert_allclose(grey, 20 + 5 * kept + 10 * i, atol=4)  # lossy video: within a few levels


def test_import_images_needs_a_video_per_episode(tmp_path):
    with pytest.raises(LangprefError, match="--images takes each episode's camera frames from its video") as info:
        run_import(write_plain(tmp_path / "rec", n=6), write_task(tmp_path / "task"), tmp_path / "ds", frames=IMAGES)
    assert "\n" not in str(info.value) and not (tmp_path / "ds").exists()


def test_the_frame_options_become_flags():
    """The CLI derives its flags from the config dataclasses: the nested frame options appear unprefixed."""
    from langpref.cli_config import add_config, from_args

    parser = argparse.ArgumentParser()
    add_config(parser, GenerateConfig)
    args = parser.parse_args(["--env", "metaworld", "--out", "d", "--images", "--frame-size", "96,96"])
    cfg = from_args(GenerateConfig, args)
    assert cfg.frames == FrameOptions(images=True, frame_size=(96, 96), frame_stride=5)


def test_import_images_from_a_lerobot_video_column(tmp_path):
    """Each episode's frames come from its span of the LeRobotDataset's shared (AV1) camera video."""
    from test_import import LEROBOT_FIXTURE

    options = FrameOptions(images=True, frame_size=(16, 16), frame_stride=2)
    run_import(LEROBOT_FIXTURE, write_task(tmp_path / "task", name="lerobot-tiny"), tmp_path / "ds", frames=options)
    ds = load_dataset(tmp_path / "ds")
    assert ds.frames().shape == (4, 8, 16, 16, 3)  # ceil(15 / 2) for the longest episode
    assert ds.frames("train").std() > 0
