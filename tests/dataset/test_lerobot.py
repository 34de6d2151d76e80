"""Reading a LeRobotDataset v3 written by lerobot itself (tests/fixtures/lerobot/tiny), and the video helpers.

The fixture's content is recomputed by importing tests/fixtures/lerobot/make_fixture.py (numpy only at import), so
these tests compare against exactly what lerobot was given.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path
from types import ModuleType

import av
import numpy as np
import pyarrow.parquet as pq
import pytest

from langpref.dataset.lerobot import read_lerobot
from langpref.dataset.video import VideoClip, check_video, write_clip
from langpref.errors import LangprefError

FIXTURE_DIR = Path(__file__).resolve().parents[1] / "fixtures" / "lerobot"
TINY = FIXTURE_DIR / "tiny"
CAMERA = "observation.images.front"
VIDEO = TINY / "videos" / CAMERA / "chunk-000" / "file-000.mp4"


def _load_maker() -> ModuleType:
    spec = importlib.util.spec_from_file_location("lerobot_fixture_maker", FIXTURE_DIR / "make_fixture.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


maker = _load_maker()


@pytest.fixture(scope="module")
def episodes():
    return read_lerobot(TINY)


@pytest.fixture
def tiny_copy(tmp_path: Path) -> Path:
    """A writable copy of the fixture, for breaking it."""
    return Path(shutil.copytree(TINY, tmp_path / "tiny"))


def _decode_rgb(path: Path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(container.streams.video[0])]


def _square_centre(image: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(x, y) centroid and mean colour of the pixels far from the grey background."""
    distance = np.abs(image.astype(int) - np.array(maker.BACKGROUND)).sum(axis=2)
    ys, xs = np.nonzero(distance > 90)
    assert len(xs) > 0, "no square in the frame"
    return float(xs.mean()), float(ys.mean()), image[ys, xs].mean(axis=0)


def _nearest_colour(colour: np.ndarray) -> int:
    return int(np.argmin([np.abs(colour - np.array(c)).sum() for c in maker.COLOURS]))


# ---- reading -----------------------------------------------------------------------------------------------------


def test_reads_every_episode_with_the_values_written(episodes):
    assert [e.name for e in episodes] == [f"episode_{i:06d}" for i in range(4)]
    for i, episode in enumerate(episodes):
        length = maker.LENGTHS[i]
        assert episode.observations.shape == (length, 6) and episode.observations.dtype == np.float32
        assert episode.actions.shape == (length, 3) and episode.actions.dtype == np.float32
        np.testing.assert_array_equal(episode.observations, maker.episode_state(i))
        np.testing.assert_array_equal(episode.actions, maker.episode_action(i))
        assert episode.features is None
        assert episode.success is maker.episode_success(i)


def test_clips_are_consecutive_spans_of_one_file(episodes):
    clips = [e.video for e in episodes]
    assert all(c is not None and c.path == VIDEO for c in clips)
    assert clips[0].start_s == 0.0
    for i, clip in enumerate(clips):
        assert clip.end_s - clip.start_s == pytest.approx(maker.LENGTHS[i] / maker.FPS)
        if i:
            assert clip.start_s == pytest.approx(clips[i - 1].end_s)


def test_other_keys_and_no_camera():
    episodes = read_lerobot(TINY, state_key="action", action_key="observation.state", camera="")
    assert episodes[0].observations.shape == (12, 3) and episodes[0].actions.shape == (12, 6)
    assert all(e.video is None for e in episodes)
    assert read_lerobot(TINY, camera=CAMERA)[1].video.start_s == pytest.approx(1.2)


@pytest.mark.parametrize("index", range(4))
def test_each_clip_decodes_to_its_own_episode(episodes, tmp_path: Path, index: int):
    dest = write_clip(episodes[index].video, tmp_path / f"ep{index}.mp4")
    frames, fps = check_video(dest)
    assert abs(frames - maker.LENGTHS[index]) <= 1 and fps == pytest.approx(maker.FPS)
    with av.open(str(dest)) as container:
        assert container.streams.video[0].codec_context.name == "h264"
    images = _decode_rgb(dest)
    for image in images:  # no frame of a neighbouring episode slipped in
        assert _nearest_colour(_square_centre(image)[2]) == index
    x, y, _ = _square_centre(images[0])  # the clip starts at the episode's first frame
    x0, y0 = maker.square_origin(index, 0)
    assert abs(x - (x0 + maker.SQUARE / 2 - 0.5)) < 1.5 and abs(y - (y0 + maker.SQUARE / 2 - 0.5)) < 1.5


# ---- reading errors ------------------------------------------------------------------------------------------------


def test_unknown_state_key_lists_the_available_ones():
    with pytest.raises(LangprefError) as err:
        read_lerobot(TINY, state_key="observation.joints")
    message = str(err.value)
    assert "info.json" in message and "observation.joints" in message
    assert "action" in message and "observation.state" in message and "\n" not in message


def test_unknown_camera_lists_the_video_features():
    with pytest.raises(LangprefError, match=r"info\.json.*'wrist'.*observation\.images\.front"):
        read_lerobot(TINY, camera="wrist")


def test_missing_video_file(tiny_copy: Path):
    (tiny_copy / "videos" / CAMERA / "chunk-000" / "file-000.mp4").unlink()
    with pytest.raises(LangprefError, match=r"file-000\.mp4.*observation\.images\.front"):
        read_lerobot(tiny_copy)
    assert len(read_lerobot(tiny_copy, camera="")) == 4  # without the camera the rest still reads


def test_v2_dataset_is_refused(tiny_copy: Path):
    info_path = tiny_copy / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    info["codebase_version"] = "v2.1"
    info_path.write_text(json.dumps(info))
    with pytest.raises(LangprefError, match=r"info\.json.*v2\.1.*only LeRobotDataset v3"):
        read_lerobot(tiny_copy)


def test_missing_info_json(tiny_copy: Path):
    (tiny_copy / "meta" / "info.json").unlink()
    with pytest.raises(LangprefError, match=r"meta/info\.json"):
        read_lerobot(tiny_copy)


def test_missing_data_file(tiny_copy: Path):
    (tiny_copy / "data" / "chunk-000" / "file-000.parquet").unlink()
    with pytest.raises(LangprefError, match=r"data/chunk-000/file-000\.parquet"):
        read_lerobot(tiny_copy)


def test_missing_episodes_metadata(tiny_copy: Path):
    shutil.rmtree(tiny_copy / "meta" / "episodes")
    with pytest.raises(LangprefError, match=r"meta/episodes"):
        read_lerobot(tiny_copy)


def test_length_mismatch_between_data_and_episodes_metadata(tiny_copy: Path):
    path = tiny_copy / "data" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(path)
    pq.write_table(table.slice(0, table.num_rows - 1), path)  # drop the last frame of episode 3
    with pytest.raises(LangprefError, match=r"file-000\.parquet: episode 3 has 13 frames.*says 14"):
        read_lerobot(tiny_copy)


def test_vector_of_the_wrong_size(tiny_copy: Path):
    info_path = tiny_copy / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    info["features"]["action"]["shape"] = [4]
    info_path.write_text(json.dumps(info))
    with pytest.raises(LangprefError, match=r"file-000\.parquet: column 'action' has 3 values"):
        read_lerobot(tiny_copy)


# ---- video helpers -------------------------------------------------------------------------------------------------


def test_check_video_reads_the_fixture():
    assert check_video(VIDEO) == (sum(maker.LENGTHS), float(maker.FPS))


@pytest.mark.parametrize("keep", [0.0, 0.5])
def test_check_video_refuses_truncated_or_garbage_files(tmp_path: Path, keep: float):
    data = VIDEO.read_bytes()
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(data[: int(len(data) * keep)] if keep else b"not a video at all" * 50)
    with pytest.raises(LangprefError, match=r"broken\.mp4") as err:
        check_video(bad)
    assert "\n" not in str(err.value)


def test_check_video_refuses_a_truncated_h264_file(tmp_path: Path):
    whole = write_clip(VideoClip(VIDEO), tmp_path / "whole.mp4")
    data = whole.read_bytes()
    bad = tmp_path / "cut.mp4"
    bad.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(LangprefError, match=r"cut\.mp4"):
        check_video(bad)


def test_whole_playable_file_is_copied_byte_for_byte(tmp_path: Path):
    h264 = write_clip(VideoClip(VIDEO), tmp_path / "a.mp4")  # AV1 -> H.264: encoded
    assert check_video(h264) == (sum(maker.LENGTHS), float(maker.FPS))
    copy = write_clip(VideoClip(h264), tmp_path / "out" / "b.mp4")
    assert copy.read_bytes() == h264.read_bytes()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["b.mp4"]  # no temp file left behind


def test_webm_destination_and_odd_size_source(tmp_path: Path):
    odd = tmp_path / "odd.mp4"
    with av.open(str(odd), "w") as out:
        stream = out.add_stream("mpeg4", rate=5)
        stream.width, stream.height, stream.pix_fmt = 33, 25, "yuv420p"
        for i in range(6):
            image = np.full((25, 33, 3), 40 * i, dtype=np.uint8)
            out.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        out.mux(stream.encode(None))
    dest = write_clip(VideoClip(odd, start_s=0.2, end_s=1.0), tmp_path / "clip.webm")
    with av.open(str(dest)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name in ("vp9", "libvpx-vp9")
        assert (stream.width % 2, stream.height % 2) == (0, 0)
    assert check_video(dest)[0] == 4  # frames at 0.2, 0.4, 0.6, 0.8 s


def test_write_clip_refusals(tmp_path: Path):
    with pytest.raises(LangprefError, match=r"clip\.avi"):
        write_clip(VideoClip(VIDEO), tmp_path / "clip.avi")
    with pytest.raises(LangprefError, match=r"nowhere\.mp4"):
        write_clip(VideoClip(tmp_path / "nowhere.mp4"), tmp_path / "clip.mp4")
    with pytest.raises(LangprefError, match=r"file-000\.mp4: no video frames between 60s"):
        write_clip(VideoClip(VIDEO, start_s=60.0, end_s=61.0), tmp_path / "clip.mp4")
    assert not list(tmp_path.iterdir())
