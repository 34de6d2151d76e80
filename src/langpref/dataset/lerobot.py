"""Read a LeRobotDataset (v3 layout) from disk into `RecordedEpisode`s, with pyarrow and no lerobot or torch.

The v3 layout, as lerobot 0.4 writes it:

    meta/info.json                              codebase_version "v3.x", fps, features {key: {dtype, shape}},
                                                data_path and video_path templates
    meta/episodes/chunk-000/file-000.parquet    one row per episode: episode_index, length, data/chunk_index,
                                                data/file_index, videos/<key>/{chunk_index, file_index,
                                                from_timestamp, to_timestamp}
    data/chunk-000/file-000.parquet             one row per frame of many episodes: episode_index, frame_index,
                                                and one column per non-video feature (vectors as list columns;
                                                an image feature as a struct of the encoded image's `bytes`
                                                (PNG, JPEG, ...) and its original `path`)
    videos/<key>/chunk-000/file-000.mp4         many episodes back to back; an episode is [from, to) in seconds

Every problem is a `LangprefError` with one line naming the file and the key, since these files come from
elsewhere and the person importing them needs to know which one to fix.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from langpref.dataset.recording import LEROBOT_INFO, ImageCells, RecordedEpisode, VideoClip
from langpref.errors import LangprefError

INFO_PATH = LEROBOT_INFO
EPISODES_DIR = Path("meta/episodes")
SUCCESS_KEY = "next.success"
# Columns lerobot adds to every dataset; not robot signals a user would pick as state or action.
_BOOKKEEPING = {"timestamp", "frame_index", "episode_index", "index", "task_index"}


def read_lerobot(
    src: Path,
    *,
    state_key: str = "observation.state",
    action_key: str = "action",
    camera: str | None = None,
    images: bool = False,
) -> list[RecordedEpisode]:
    """Every episode of the LeRobotDataset v3 at `src`, in episode order.

    `state_key` and `action_key` name the features read as observations and actions. `camera` names the camera
    feature: a video feature is attached as each episode's clip; an image feature (one encoded image per frame in the
    data files) as each episode's `images`, and only when `images` is true, since those cells are the bulk of the
    data files and only `import --images` decodes them. None takes the first video feature in meta/info.json, else
    the first image feature (no camera if there is neither); "" takes none. An episode's `success` is whether
    `next.success` was ever true, when the dataset records it; `features` is None (LeRobot has no task features; the
    task file computes them).
    """
    src = Path(src)
    info_path = src / INFO_PATH
    info = _read_info(src)
    features: dict[str, Any] = info["features"]
    for key in (state_key, action_key):
        _check_vector_feature(features, key, info_path)
    camera_key = _pick_camera(features, camera, info_path)
    is_image = bool(camera_key) and features[camera_key].get("dtype") == "image"
    video_key = "" if is_image else camera_key
    image_key = camera_key if is_image and images else ""
    episodes = _read_episodes_meta(src, video_key)
    columns = [state_key, action_key] + ([SUCCESS_KEY] if SUCCESS_KEY in features else [])
    data_template = _template(info, "data_path", info_path)
    frames, cells = _read_frames(src, data_template, episodes, columns, features, image_key)
    video_template = _template(info, "video_path", info_path) if video_key else ""
    result = []
    for episode in episodes:
        index = episode["episode_index"]
        data = frames[index]
        success = bool(np.any(data[SUCCESS_KEY])) if SUCCESS_KEY in data else None
        clip = _episode_clip(src, video_template, video_key, episode) if video_key else None
        result.append(
            RecordedEpisode(
                name=f"episode_{index:06d}",
                observations=data[state_key],
                actions=data[action_key],
                features=None,
                success=success,
                video=clip,
                images=cells.get(index),
            )
        )
    return result


# ---- meta/info.json ----------------------------------------------------------------------------------------------


def _read_info(src: Path) -> dict[str, Any]:
    """meta/info.json, checked to be a v3 dataset with a features table."""
    path = src / INFO_PATH
    if not path.is_file():
        what = "folder not found" if not src.is_dir() else "not a LeRobotDataset"
        raise LangprefError(f"{path}: file not found ({src}: {what}; a LeRobotDataset v3 has meta/info.json)")
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LangprefError(f"{path}: not readable JSON ({' '.join(str(exc).split())})") from exc
    if not isinstance(info, dict):
        raise LangprefError(f"{path}: expected a JSON object")
    _check_version(info.get("codebase_version"), path)
    if not isinstance(info.get("features"), dict) or not info["features"]:
        raise LangprefError(f"{path}: key 'features' missing or empty")
    return info


def _check_version(version: Any, path: Path) -> None:
    """Only the v3 layout is read: v2 keeps one file per episode and jsonl metadata, which this reader does not."""
    if not isinstance(version, str) or not version:
        raise LangprefError(f"{path}: key 'codebase_version' missing; only LeRobotDataset v3 (v3.x) is supported")
    major = version.lstrip("vV").split(".")[0]
    if major != "3":
        raise LangprefError(
            f"{path}: codebase_version {version} is not supported; only LeRobotDataset v3 (v3.x) is "
            "(convert it with lerobot's lerobot.datasets.v30.convert_dataset_v21_to_v30)"
        )


def _template(info: dict[str, Any], key: str, path: Path) -> str:
    value = info.get(key)
    if not isinstance(value, str) or not value:
        raise LangprefError(f"{path}: key '{key}' missing (the path template of the dataset's files)")
    return value


def _vector_keys(features: dict[str, Any]) -> list[str]:
    """Features stored as numbers in the data parquet files (candidates for state and action)."""
    return sorted(
        key
        for key, ft in features.items()
        if key not in _BOOKKEEPING and isinstance(ft, dict) and ft.get("dtype") not in ("video", "image", "string")
    )


def _check_vector_feature(features: dict[str, Any], key: str, path: Path) -> None:
    if key in _vector_keys(features):
        return
    available = ", ".join(_vector_keys(features)) or "none"
    if key in features:
        raise LangprefError(
            f"{path}: feature '{key}' is not numeric (dtype {features[key].get('dtype')}); "
            f"numeric features: {available}"
        )
    raise LangprefError(f"{path}: no feature '{key}'; available: {available}")


def _features_of(features: dict[str, Any], dtype: str) -> list[str]:
    return [key for key, ft in features.items() if isinstance(ft, dict) and ft.get("dtype") == dtype]


def _pick_camera(features: dict[str, Any], camera: str | None, path: Path) -> str:
    """The camera feature to take ("" for none): `camera` when it names a video or image feature, by default the
    first video feature (a clip the study can play), else the first image feature."""
    videos, images = _features_of(features, "video"), _features_of(features, "image")
    if camera is None:
        return (videos + images)[0] if videos or images else ""
    if camera == "" or camera in videos or camera in images:
        return camera
    cameras = [f"{key} (video)" for key in videos] + [f"{key} (image)" for key in images]
    raise LangprefError(f"{path}: no camera feature '{camera}'; camera features: {', '.join(cameras) or 'none'}")


# ---- meta/episodes -----------------------------------------------------------------------------------------------


def _episode_columns(video_key: str) -> list[str]:
    cols = ["episode_index", "length", "data/chunk_index", "data/file_index"]
    if video_key:
        cols += [f"videos/{video_key}/{c}" for c in ("chunk_index", "file_index", "from_timestamp", "to_timestamp")]
    return cols


def _read_episodes_meta(src: Path, video_key: str) -> list[dict[str, Any]]:
    """One dict per episode (the columns this reader needs), sorted by episode_index."""
    files = sorted((src / EPISODES_DIR).glob("chunk-*/file-*.parquet"))
    if not files:
        raise LangprefError(f"{src / EPISODES_DIR}: no episodes metadata (chunk-*/file-*.parquet) found")
    wanted = _episode_columns(video_key)
    rows: list[dict[str, Any]] = []
    for path in files:
        rows.extend(_read_parquet(path, wanted, "episodes metadata").to_pylist())
    for row in rows:
        if any(row[c] is None for c in wanted):
            column = next(c for c in wanted if row[c] is None)
            raise LangprefError(f"{src / EPISODES_DIR}: episode {row['episode_index']} has no '{column}'")
    rows.sort(key=lambda r: r["episode_index"])
    indices = [r["episode_index"] for r in rows]
    if len(set(indices)) != len(indices):
        raise LangprefError(f"{src / EPISODES_DIR}: an episode_index appears twice in the episodes metadata")
    return rows


def _read_parquet(path: Path, columns: list[str] | None = None, what: str = "file") -> pa.Table:
    """The table at `path`, or only `columns` of it (each checked to exist first; `what` names the file in that
    error), so a data file's image cells are not read unless they are wanted."""
    if not path.is_file():
        raise LangprefError(f"{path}: parquet file not found")
    try:
        if columns is not None:
            names = pq.read_schema(path).names
            missing = [c for c in columns if c not in names]
            if missing:
                raise LangprefError(f"{path}: column '{missing[0]}' missing from the {what}")
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError) as exc:
        raise LangprefError(f"{path}: not a readable parquet file ({' '.join(str(exc).split())})") from exc


# ---- data/*.parquet ----------------------------------------------------------------------------------------------


def _read_frames(
    src: Path,
    data_template: str,
    episodes: list[dict[str, Any]],
    columns: list[str],
    features: dict[str, Any],
    image_key: str = "",
) -> tuple[dict[int, dict[str, np.ndarray]], dict[int, ImageCells]]:
    """({episode_index: {column: (T, D) array}}, {episode_index: its cells of the image column `image_key`}) for the
    listed episodes, rows in frame_index order; the second is empty without an `image_key`."""
    by_file: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for ep in episodes:
        by_file.setdefault((ep["data/chunk_index"], ep["data/file_index"]), []).append(ep)
    out: dict[int, dict[str, np.ndarray]] = {}
    cells: dict[int, ImageCells] = {}
    for (chunk, file), eps in sorted(by_file.items()):
        path = src / data_template.format(chunk_index=chunk, file_index=file)
        wanted = ["episode_index", "frame_index", *columns] + ([image_key] if image_key else [])
        table = _read_parquet(path, wanted, "data file")
        arrays = {col: _to_matrix(table.column(col), path, col, features.get(col)) for col in columns}
        images = _image_cells(table.column(image_key), path, image_key) if image_key else []
        episode = table.column("episode_index").to_numpy()
        frame = table.column("frame_index").to_numpy()
        for ep in eps:
            index, length = ep["episode_index"], ep["length"]
            rows = np.flatnonzero(episode == index)
            if len(rows) != length:
                raise LangprefError(
                    f"{path}: episode {index} has {len(rows)} frames, the episodes metadata says {length}"
                )
            rows = rows[np.argsort(frame[rows], kind="stable")]
            out[index] = {col: arr[rows] for col, arr in arrays.items()}
            if image_key:
                where = f"{path}: column '{image_key}', episode {index}"
                cells[index] = ImageCells(cells=[images[r] for r in rows], where=where)
    return out, cells


def _image_cells(column: pa.ChunkedArray, path: Path, key: str) -> list[bytes | None]:
    """Every row's encoded image in an image column: the `bytes` of lerobot's (Hugging Face datasets') struct
    {bytes, path}, or a plain binary column; None where a row has no bytes (decoding it is the error)."""
    arr = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    if pa.types.is_struct(arr.type):
        if arr.type.get_field_index("bytes") < 0:
            raise LangprefError(f"{path}: column '{key}' is {arr.type}, not images (a struct with 'bytes')")
        arr = arr.flatten()[arr.type.get_field_index("bytes")]  # flatten() keeps the rows that are null as a whole
    if not (pa.types.is_binary(arr.type) or pa.types.is_large_binary(arr.type)):
        raise LangprefError(f"{path}: column '{key}' is {arr.type}, not encoded images")
    return arr.to_pylist()


def _to_matrix(column: pa.ChunkedArray, path: Path, key: str, feature: dict[str, Any] | None) -> np.ndarray:
    """A numeric column (scalars, or lists of equal length, nested or not) as a (rows, D) float32 array."""
    arr = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    rows = len(arr)
    if arr.null_count:
        raise LangprefError(f"{path}: column '{key}' has {arr.null_count} empty rows")
    while pa.types.is_list(arr.type) or pa.types.is_large_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        inner = arr.flatten()
        if inner.null_count:
            raise LangprefError(f"{path}: column '{key}' has empty values inside its vectors")
        arr = inner
    if not (pa.types.is_floating(arr.type) or pa.types.is_integer(arr.type) or pa.types.is_boolean(arr.type)):
        raise LangprefError(f"{path}: column '{key}' is {arr.type}, not numbers")
    values = arr.to_numpy(zero_copy_only=False).astype(np.float32)
    if rows == 0:
        return values.reshape(0, 0)
    if values.size % rows:
        raise LangprefError(f"{path}: column '{key}' has vectors of different lengths")
    matrix = values.reshape(rows, -1)
    shape = feature.get("shape") if isinstance(feature, dict) else None
    if shape is not None and matrix.shape[1] != int(np.prod(shape)):
        raise LangprefError(
            f"{path}: column '{key}' has {matrix.shape[1]} values per frame, meta/info.json says shape {shape}"
        )
    return matrix


# ---- videos ------------------------------------------------------------------------------------------------------


def _episode_clip(src: Path, template: str, video_key: str, episode: dict[str, Any]) -> VideoClip:
    """The episode's span of its camera's video file, which must exist."""
    prefix = f"videos/{video_key}/"
    path = src / template.format(
        video_key=video_key, chunk_index=episode[prefix + "chunk_index"], file_index=episode[prefix + "file_index"]
    )
    if not path.is_file():
        raise LangprefError(f"{path}: video file not found (camera '{video_key}', episode {episode['episode_index']})")
    start, end = float(episode[prefix + "from_timestamp"]), float(episode[prefix + "to_timestamp"])
    if not end > start:
        raise LangprefError(
            f"{src / EPISODES_DIR}: episode {episode['episode_index']} has an empty span of '{video_key}' "
            f"({start:g}s to {end:g}s)"
        )
    return VideoClip(path=path, start_s=start, end_s=end)
