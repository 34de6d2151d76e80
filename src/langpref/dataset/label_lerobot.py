"""The labelled copy of a LeRobotDataset (v3), written with pyarrow alone (no lerobot, no torch).

What changes, against the layout `langpref.dataset.lerobot` describes:

    data/chunk-*/file-*.parquet      the label columns (`langpref.dataset.label_columns.COLUMNS`) appended after the
                                     original ones, row group by row group as the original is cut, with the same
                                     compression; the schema's Hugging Face metadata lists them (float32 `Value`s)
    meta/info.json                   each label column as a feature {"dtype": "float32", "shape": [1], "names": null}
    meta/stats.json                  each label column's min, max, mean, std, count and q01/q10/q50/q90/q99 over all
                                     frames (exact quantiles; lerobot estimates them from histograms)
    meta/episodes/chunk-*/*.parquet  the same statistics per episode, as `stats/<column>/<stat>` columns
    meta/langpref_label.json         what was labelled with which reward
    sarm_progress.parquet            per frame `index`, `episode_index`, `frame_index`, `progress_sparse`: the sidecar
                                     LeRobot's reward-aligned behaviour cloning reads (`lerobot-train --use_rabc=true`)

LeRobot names a frame's reward `next.reward` (float32, shape (1,)): the copy has it, r_t (the reward share), unless
the dataset has its own, which is kept. RA-BC weighs a frame by how much its progress rises over the next action
chunk; `progress_sparse` is the episode's learned reward earned so far (the running sum of r_t), scaled to [0, 1]
over the whole dataset, so a chunk's rise is the reward its frames earn over the dataset's range of such sums.

Videos are hard-linked (copied where that fails) and every other file is copied as it is. Original columns are not
rewritten value by value: the copy's table is the original Arrow table with columns appended, so their bytes are
the original's.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from langpref.dataset.label_columns import (
    COLUMNS,
    EPISODE,
    PROGRESS,
    SHARE,
    bar,
    check_sizes,
    episode_columns,
    link_or_copy,
)
from langpref.dataset.lerobot import (
    EPISODES_DIR,
    INFO_PATH,
    _check_vector_feature,
    _read_episodes_meta,
    _read_info,
    _read_parquet,
    _template,
    _to_matrix,
)
from langpref.errors import LangprefError

NEXT_REWARD = "next.reward"
"""LeRobot's name of a frame's reward."""
PROGRESS_SIDECAR = "sarm_progress.parquet"
"""The per-frame progress file LeRobot's RA-BC reads beside a dataset."""
STATS_PATH = Path("meta/stats.json")
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
"""The quantiles lerobot 0.4 keeps in its statistics, as q01, q10, q50, q90, q99."""
FEATURE = {"dtype": "float32", "shape": [1], "names": None}
"""A label column as a feature of meta/info.json: one float32 per frame, as lerobot declares `next.reward`."""


def label_lerobot(
    src: Path, out: Path, reward: Any, state_key: str, action_key: str, progress: bool = True
) -> dict[str, Any]:
    """Write the labelled copy of the LeRobotDataset `src` into the empty folder `out`; {frames, episode_rewards,
    curves (episode name -> its v_t), columns, progress_sidecar}."""
    info = _read_info(src)
    features = info["features"]
    for key in (state_key, action_key):
        _check_vector_feature(features, key, src / INFO_PATH)
    taken = [name for name in COLUMNS if name in features]
    if taken:
        raise LangprefError(f"{src / INFO_PATH}: feature {taken[0]!r} exists (labelled before): label the original")
    sizes = [int(np.prod(features[k].get("shape") or [1])) for k in (state_key, action_key)]
    check_sizes(reward, sizes[0], sizes[1], f"{src}'s {state_key} and {action_key}")
    written = {name: name for name in COLUMNS} | ({} if NEXT_REWARD in features else {NEXT_REWARD: SHARE})
    episodes = _read_episodes_meta(src, "")
    template = _template(info, "data_path", src / INFO_PATH)
    by_file: dict[Path, list[dict[str, Any]]] = {}
    for ep in episodes:
        rel = Path(template.format(chunk_index=ep["data/chunk_index"], file_index=ep["data/file_index"]))
        by_file.setdefault(rel, []).append(ep)
    labels: dict[int, dict[str, np.ndarray]] = {}
    ticks = bar(None, f"label {src.name}", len(episodes), progress)
    for rel, eps in sorted(by_file.items()):
        labels.update(_label_data_file(src / rel, out / rel, eps, reward, (state_key, action_key), features, written))
        ticks.update(len(eps))
    ticks.close()
    _copy_rest(src, out, set(by_file))
    _write_info(info, out / INFO_PATH, list(written))
    _write_stats(src / STATS_PATH, out / STATS_PATH, labels, list(written))
    _write_episode_stats(src, out, labels, list(written))
    _write_progress(out / PROGRESS_SIDECAR, labels)
    frames = sum(len(cols[EPISODE]) for cols in labels.values())
    return {
        "frames": frames,
        "episode_rewards": [float(labels[ep["episode_index"]][EPISODE][0]) for ep in episodes],
        "curves": {f"episode {ep['episode_index']}": labels[ep["episode_index"]][PROGRESS] for ep in episodes},
        "columns": list(written),
        "progress_sidecar": PROGRESS_SIDECAR,
    }


# ---- data files ----------------------------------------------------------------------------------------------------


def _label_data_file(
    src: Path,
    dst: Path,
    episodes: list[dict[str, Any]],
    reward: Any,
    keys: tuple[str, str],
    features: dict,
    written: dict[str, str],
) -> dict[int, dict[str, np.ndarray]]:
    """Write `dst`: the data file `src` with the label columns of its `episodes` (`written`: column -> the label it
    holds); returns the labels per episode (in frame order) and each frame's `index`. Every row of the file must
    belong to one of them."""
    table = _read_parquet(src, None, "data file")
    for key in ("index", "episode_index", "frame_index", *keys):
        if key not in table.column_names:
            raise LangprefError(f"{src}: column '{key}' missing from the data file")
    obs, act = (_to_matrix(table.column(k), src, k, features.get(k)) for k in keys)
    episode = table.column("episode_index").to_numpy()
    frame = table.column("frame_index").to_numpy()
    frame_ids = table.column("index").to_numpy()
    columns = {name: np.full(table.num_rows, np.nan, dtype=np.float32) for name in written}
    covered = np.zeros(table.num_rows, dtype=bool)
    out: dict[int, dict[str, np.ndarray]] = {}
    for ep in episodes:
        index = ep["episode_index"]
        rows = np.flatnonzero(episode == index)
        if len(rows) != ep["length"] or len(rows) == 0:
            raise LangprefError(
                f"{src}: episode {index} has {len(rows)} frames, the episodes metadata says {ep['length']}"
            )
        rows = rows[np.argsort(frame[rows], kind="stable")]
        labels = episode_columns(reward, obs[rows], act[rows])
        for name, label in written.items():
            columns[name][rows] = labels[label]
        out[index] = {**labels, NEXT_REWARD: labels[SHARE], "index": frame_ids[rows]}
        covered[rows] = True
    if not covered.all():
        stray = int(episode[np.flatnonzero(~covered)[0]])
        raise LangprefError(f"{src}: rows of episode {stray}, which the episodes metadata does not list")
    _write_with_columns(src, dst, columns)
    return out


def _write_with_columns(src: Path, dst: Path, columns: dict[str, np.ndarray]) -> None:
    """`dst`: the parquet file `src`, row group by row group, with `columns` (float32, one value per row) appended
    and listed in the schema's Hugging Face metadata; the same compression as `src`'s first column."""
    reader = pq.ParquetFile(src)
    compression = _compression(reader)
    schema = reader.schema_arrow
    for name in columns:
        schema = schema.append(pa.field(name, pa.float32()))
    schema = schema.with_metadata(_hf_metadata(schema.metadata or {}, list(columns)))
    dst.parent.mkdir(parents=True, exist_ok=True)
    start = 0
    with pq.ParquetWriter(dst, schema, compression=compression) as writer:
        for i in range(reader.num_row_groups):
            group = reader.read_row_group(i)
            stop = start + group.num_rows
            for name, values in columns.items():
                group = group.append_column(pa.field(name, pa.float32()), pa.array(values[start:stop]))
            writer.write_table(group.replace_schema_metadata(schema.metadata), row_group_size=max(group.num_rows, 1))
            start = stop


def _compression(reader: pq.ParquetFile) -> str:
    """The codec of a parquet file's first column chunk, as pyarrow's writer names it (snappy where it has none)."""
    meta = reader.metadata
    if not meta.num_row_groups or not meta.num_columns:
        return "snappy"
    codec = meta.row_group(0).column(0).compression.lower()
    return "none" if codec == "uncompressed" else codec


def _hf_metadata(metadata: dict[bytes, bytes], names: list[str]) -> dict[bytes, bytes]:
    """The schema metadata with each of `names` added to the Hugging Face features (a float32 `Value`), so the
    datasets library reads the new columns as lerobot's writer would have declared them."""
    metadata = dict(metadata)
    raw = metadata.get(b"huggingface")
    if raw is None:
        return metadata
    try:
        doc = json.loads(raw)
        feats = doc["info"]["features"]
    except (ValueError, KeyError, TypeError):
        return metadata  # not the layout we know: leave it, the readers take the features from meta/info.json
    for name in names:
        feats[name] = {"dtype": "float32", "_type": "Value"}
    metadata[b"huggingface"] = json.dumps(doc).encode()
    return metadata


# ---- meta ----------------------------------------------------------------------------------------------------------


def _copy_rest(src: Path, out: Path, written: set[Path]) -> None:
    """Every file of `src` that is not rewritten here: videos hard-linked (or copied), the others copied."""
    rewritten = written | {INFO_PATH, STATS_PATH}
    for path in sorted(src.rglob("*")):
        rel = path.relative_to(src)
        if path.is_dir() or rel in rewritten or (rel.parts[:2] == EPISODES_DIR.parts and path.suffix == ".parquet"):
            continue
        dst = out / rel
        if rel.parts[0] == "videos":
            link_or_copy(path, dst)
        else:
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, dst)


def _write_info(info: dict[str, Any], path: Path, names: list[str]) -> None:
    """meta/info.json with the label columns `names` as features (indented as lerobot writes it)."""
    info = dict(info, features={**info["features"], **{name: dict(FEATURE) for name in names}})
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(info, indent=4, ensure_ascii=False), encoding="utf-8")


def column_stats(values: np.ndarray) -> dict[str, list]:
    """lerobot's statistics of one float column: min, max, mean, std, count and the quantiles, each a 1-list."""
    v = np.asarray(values, dtype=np.float64)
    stats: dict[str, list] = {
        "min": [float(v.min())],
        "max": [float(v.max())],
        "mean": [float(v.mean())],
        "std": [float(v.std())],
        "count": [int(len(v))],
    }
    for q, value in zip(QUANTILES, np.quantile(v, QUANTILES)):
        stats[f"q{round(q * 100):02d}"] = [float(value)]
    return stats


def _write_stats(src: Path, dst: Path, labels: dict[int, dict[str, np.ndarray]], names: list[str]) -> None:
    """meta/stats.json with the label columns' statistics over all frames (written even when `src` had none)."""
    stats: dict[str, Any] = {}
    if src.is_file():
        try:
            stats = json.loads(src.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise LangprefError(f"{src}: not readable JSON ({' '.join(str(exc).split())})") from exc
    for name in names:
        stats[name] = column_stats(np.concatenate([cols[name] for cols in labels.values()]))
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text(json.dumps(stats, indent=4, ensure_ascii=False), encoding="utf-8")


def _write_episode_stats(src: Path, out: Path, labels: dict[int, dict[str, np.ndarray]], names: list[str]) -> None:
    """Each meta/episodes parquet file with `stats/<column>/<stat>` columns of the label columns, per episode."""
    for path in sorted((src / EPISODES_DIR).glob("chunk-*/file-*.parquet")):
        table = _read_parquet(path, None, "episodes metadata")
        indices = table.column("episode_index").to_pylist()
        for name in names:
            per_episode = [column_stats(labels[i][name]) for i in indices]
            for stat in per_episode[0]:
                kind = pa.list_(pa.int64() if stat == "count" else pa.float64())
                table = table.append_column(f"stats/{name}/{stat}", pa.array([s[stat] for s in per_episode], kind))
        dst = out / path.relative_to(src)
        dst.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, dst, compression=_compression(pq.ParquetFile(path)))


def _write_progress(path: Path, labels: dict[int, dict[str, np.ndarray]]) -> None:
    """The RA-BC sidecar (module docstring): per frame its `index`, `episode_index`, `frame_index` and
    `progress_sparse`, the running sum of r_t scaled to [0, 1] over every frame of the dataset."""
    order = sorted(labels)
    earned = {i: np.cumsum(labels[i][SHARE].astype(np.float64)) for i in order}
    low = min(float(v.min()) for v in earned.values())
    span = max(max(float(v.max()) for v in earned.values()) - low, 1e-12)
    table = pa.table(
        {
            "index": pa.array(np.concatenate([labels[i]["index"] for i in order]).astype(np.int64)),
            "episode_index": pa.array(np.concatenate([np.full(len(earned[i]), i) for i in order]).astype(np.int64)),
            "frame_index": pa.array(np.concatenate([np.arange(len(earned[i])) for i in order]).astype(np.int64)),
            "progress_sparse": pa.array(np.concatenate([(earned[i] - low) / span for i in order]).astype(np.float32)),
        }
    )
    pq.write_table(table, path)
