"""Robot recordings read into memory, whatever their source layout."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from langpref.errors import LangprefError


@dataclass(frozen=True)
class VideoClip:
    """A span of a video file: frames with timestamps in [start_s, end_s); None means the file's start or end."""

    path: Path
    start_s: float | None = None
    end_s: float | None = None


@dataclass(frozen=True)
class ImageCells:
    """An episode's camera frames stored as still images, one encoded image (PNG, JPEG, ...) per step in step order,
    as a LeRobotDataset's image column holds them. A cell is None where the file has no image bytes. `where` names
    the file, column and episode, for a one-line error on a cell that does not decode."""

    cells: list[bytes | None]
    where: str


@dataclass
class RecordedEpisode:
    """One recorded episode, as every source reader returns it before `langpref import` stores it.

    `observations` and `actions` are float32 with one row per recorded step. `features` is either per step (T, F)
    or per episode (F,), or None when the source has none (the task file's `features_from` then computes them).
    `video` is the episode's camera footage, possibly a time span inside a longer file; `images` is its camera as
    one still image per step instead (a LeRobotDataset's image column), read only when frames are imported.
    """

    name: str
    observations: np.ndarray
    actions: np.ndarray
    features: np.ndarray | None
    success: bool | None
    video: VideoClip | None
    images: ImageCells | None = None


VIDEO_SUFFIXES = (".mp4", ".webm")
LEROBOT_INFO = Path("meta/info.json")
"""The file that marks a folder as a LeRobotDataset (v3)."""


def _npz_arrays(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise LangprefError(f"{path}: not a readable .npz episode ({type(exc).__name__}: {exc})") from None


def _matrix(data: dict[str, np.ndarray], key: str, path: Path) -> np.ndarray:
    if key not in data:
        raise LangprefError(
            f"{path}: missing key {key!r} (an episode has 'observations' (T, obs_dim) and "
            f"'actions' (T, A); it has {', '.join(sorted(data)) or 'nothing'})"
        )
    value = data[key]
    if value.ndim != 2 or not np.issubdtype(value.dtype, np.number):
        raise LangprefError(f"{path}: {key!r} must be a 2-D numeric array (T, dim), got {value.dtype} {value.shape}")
    if not np.isfinite(value).all():
        raise LangprefError(f"{path}: {key!r} holds NaN or infinite values")
    return value.astype(np.float32)


def read_plain_episode(path: Path) -> RecordedEpisode:
    """One `NAME.npz` episode of a plain recording folder, with `NAME.mp4`/`NAME.webm` beside it as its video."""
    data = _npz_arrays(path)
    obs, act = _matrix(data, "observations", path), _matrix(data, "actions", path)
    if len(obs) != len(act):
        raise LangprefError(f"{path}: 'observations' has {len(obs)} steps but 'actions' has {len(act)}")
    features = data.get("features")
    if features is not None:
        features = np.asarray(features, dtype=np.float64)
    success = data.get("success")
    if success is not None and success.size != 1:
        raise LangprefError(f"{path}: 'success' must be one boolean, got shape {success.shape}")
    videos = [path.with_suffix(s) for s in VIDEO_SUFFIXES if path.with_suffix(s).is_file()]
    return RecordedEpisode(
        name=path.stem,
        observations=obs,
        actions=act,
        features=features,
        success=None if success is None else bool(success.reshape(())),
        video=VideoClip(videos[0]) if videos else None,
    )


def is_lerobot(src: Path) -> bool:
    """Whether `src` looks like a LeRobotDataset (it has meta/info.json), else it is read as a plain recording. Here,
    not beside the LeRobot reader, so that telling the layouts apart needs no pyarrow."""
    return (Path(src) / LEROBOT_INFO).is_file()


def plain_episode_files(src: Path) -> list[Path]:
    """The episodes of a plain recording folder, in name order (other files in it are ignored)."""
    files = sorted(p for p in src.iterdir() if p.suffix == ".npz" and p.is_file() and not p.name.startswith("."))
    if not files:
        raise LangprefError(
            f"{src}: no episodes (NAME.npz files) in the folder, and it is not a LeRobotDataset (no meta/info.json)"
        )
    return files


def orphan_videos(src: Path) -> list[str]:
    """The videos of a plain recording folder whose episode (the NAME.npz of its NAME.mp4/.webm) is not there, by
    name: footage that an import would otherwise pass over without a word."""
    return sorted(
        p.name
        for p in src.iterdir()
        if p.suffix in VIDEO_SUFFIXES
        and p.is_file()
        and not p.name.startswith(".")
        and not p.with_suffix(".npz").is_file()
    )
