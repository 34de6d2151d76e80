"""`import --images` of a LeRobotDataset whose cameras are image columns (tests/fixtures/lerobot/tiny-images, written
by lerobot itself with use_videos=False): the stored frames are the images lerobot was given, resized and subsampled
exactly as frames from a video are; they match the video fixture's frames of the same content; `--camera` picks
between cameras; a cell that does not decode is one line naming the file, column, episode and frame.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from test_import import LEROBOT_FIXTURE, run_import, write_task
from test_lerobot import FIXTURE_DIR, _nearest_colour, _square_centre, maker

from langpref.dataset.frames import FrameOptions, box_downsample
from langpref.dataset.inspect import _frames_line
from langpref.dataset.lerobot import read_lerobot
from langpref.dataset.storage import load_dataset
from langpref.dataset.video import small_rgb
from langpref.errors import LangprefError

TINY_IMAGES = FIXTURE_DIR / "tiny-images"
DATA = Path("data/chunk-000/file-000.parquet")
LENGTHS = maker.LENGTHS[: maker.IMAGE_EPISODES]  # 12, 15, 10


def _import(tmp_path: Path, src: Path, size: tuple[int, int], stride: int, **kw) -> tuple[dict, np.ndarray]:
    """Import `src` with --images; (the summary, the stored frames (N, K, H, W, 3) in episode order)."""
    options = FrameOptions(images=True, frame_size=size, frame_stride=stride)
    out = tmp_path / f"ds-{src.name}"
    summary = run_import(src, write_task(tmp_path / "task", name="lerobot-tiny"), out, frames=options, **kw)
    return summary, load_dataset(out).frames()


def _break_cell(src: Path, episode: int, frame: int, data: bytes | None) -> Path:
    """A copy of `src` whose front camera image of (episode, frame) holds `data` instead of its PNG."""
    path = src / DATA
    table = pq.read_table(path)
    column = table.column(maker.CAMERA)
    rows = column.to_pylist()
    hit = np.flatnonzero(
        (table.column("episode_index").to_numpy() == episode) & (table.column("frame_index").to_numpy() == frame)
    )
    rows[int(hit[0])]["bytes"] = data
    fixed = pa.array(rows, type=column.type)
    pq.write_table(table.set_column(table.column_names.index(maker.CAMERA), maker.CAMERA, fixed), path)
    return src


@pytest.fixture
def images_copy(tmp_path: Path) -> Path:
    return Path(shutil.copytree(TINY_IMAGES, tmp_path / "tiny-images"))


def test_image_columns_are_read_only_when_frames_are_wanted():
    plain = read_lerobot(TINY_IMAGES)  # no --images: the image cells are not even read
    assert [len(e.actions) for e in plain] == list(LENGTHS)
    assert all(e.video is None and e.images is None for e in plain)
    np.testing.assert_array_equal(plain[1].observations, maker.episode_state(1))
    episodes = read_lerobot(TINY_IMAGES, images=True)  # the first camera by default, the front one
    for i, episode in enumerate(episodes):
        assert episode.images is not None and len(episode.images.cells) == LENGTHS[i]
        assert f"column '{maker.CAMERA}', episode {i}" in episode.images.where


def test_native_size_frames_are_exactly_the_images_lerobot_was_given(tmp_path: Path):
    summary, frames = _import(tmp_path, TINY_IMAGES, (maker.WIDTH, maker.HEIGHT), 1)
    assert summary["frames"] == {"width": 64, "height": 48, "stride": 1, "source": "image"}
    assert summary["videos"] is False  # an image camera gives frames, not a video to play
    assert frames.shape == (3, 15, 48, 64, 3)
    for i, steps in enumerate(LENGTHS):
        given = np.stack([maker.frame_image(i, t) for t in range(steps)])
        np.testing.assert_array_equal(frames[i, :steps], given)  # PNG: lossless
    assert "decoded from the recorded images" in _frames_line(summary["frames"])


def test_frames_are_resized_and_subsampled_as_frames_from_a_video(tmp_path: Path):
    _, frames = _import(tmp_path, TINY_IMAGES, (32, 24), 3)
    assert frames.shape == (3, 5, 24, 32, 3)  # ceil(15 / 3) for the longest episode, the others padded
    for i, steps in enumerate(LENGTHS):
        kept = np.arange(0, steps, 3)
        given = np.stack([maker.frame_image(i, t) for t in kept])
        # the very resize a video frame gets (PyAV's area averaging), and so the 2x2 box means to within rounding
        same_path = [small_rgb(av.VideoFrame.from_ndarray(g, format="rgb24"), 32, 24) for g in given]
        np.testing.assert_array_equal(frames[i, : len(kept)], np.stack(same_path))
        diff = np.abs(frames[i, : len(kept)].astype(int) - box_downsample(given, 2).astype(int))
        assert diff.max() <= 1


def test_image_and_video_columns_of_the_same_content_give_the_same_frames(tmp_path: Path):
    """tiny (AV1 video) and tiny-images (PNG cells) hold the same pictures: the frames agree up to the video's loss."""
    _, from_images = _import(tmp_path, TINY_IMAGES, (32, 24), 3)
    _, from_video = _import(tmp_path, LEROBOT_FIXTURE, (32, 24), 3)
    for i, steps in enumerate(LENGTHS):
        count = len(range(0, steps, 3))
        for k in range(count):
            a, b = (_square_centre(f[i, k]) for f in (from_images, from_video))
            assert _nearest_colour(a[2]) == _nearest_colour(b[2]) == i
        ax, ay, _ = _square_centre(from_images[i, 0])  # positions: first frames only (the AV1 copy repeats odd frames)
        bx, by, _ = _square_centre(from_video[i, 0])
        assert abs(ax - bx) <= 1 and abs(ay - by) <= 1
        x, y = maker.square_origin(i, 0)
        assert ax == pytest.approx((x + maker.SQUARE / 2 - 0.5) / 2, abs=0.5)
        assert ay == pytest.approx((y + maker.SQUARE / 2 - 0.5) / 2, abs=0.5)


def test_camera_picks_the_image_column(tmp_path: Path):
    size = (maker.WRIST_WIDTH, maker.WRIST_HEIGHT)
    summary, frames = _import(tmp_path, TINY_IMAGES, size, 2, camera=maker.WRIST)
    assert summary["frames"]["source"] == "image"
    for i, steps in enumerate(LENGTHS):
        kept = np.arange(0, steps, 2)
        np.testing.assert_array_equal(frames[i, : len(kept)], np.stack([maker.wrist_image(i, t) for t in kept]))


def test_an_unknown_camera_lists_video_and_image_features():
    with pytest.raises(LangprefError, match=r"info\.json: no camera feature 'top'.*front \(image\).*wrist \(image\)"):
        read_lerobot(TINY_IMAGES, camera="top")


def test_a_corrupt_image_cell_is_one_line_naming_it(images_copy: Path, tmp_path: Path):
    _break_cell(images_copy, episode=1, frame=3, data=b"\x89PNG\r\n\x1a\n but not an image")
    with pytest.raises(LangprefError) as info:
        _import(tmp_path, images_copy, (32, 24), 3)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(images_copy / DATA))
    assert f"column '{maker.CAMERA}', episode 1, frame 3: not a decodable image" in message
    assert not (tmp_path / f"ds-{images_copy.name}").exists()  # nothing half-written
    # frames are decoded only with --images, and only the kept steps': frame 3 is not kept at stride 2
    summary = run_import(images_copy, write_task(tmp_path / "task"), tmp_path / "plain")
    assert summary["frames"] is None and summary["videos"] is False
    assert _import(tmp_path, images_copy, (32, 24), 2)[1].shape == (3, 8, 24, 32, 3)


def test_a_cell_without_image_bytes(images_copy: Path, tmp_path: Path):
    _break_cell(images_copy, episode=2, frame=0, data=None)
    with pytest.raises(LangprefError, match=r"episode 2, frame 0: the cell holds no image bytes"):
        _import(tmp_path, images_copy, (32, 24), 3)
