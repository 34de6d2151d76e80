"""A dataset's checksum: a sha256 of what it holds, so anyone can tell whether their regenerated data is ours.

It hashes the arrays, not the files: every array of every trajectory file (observations, actions, step_features,
success, and simulator state, seed and controller parameters when stored), `features.npy`, the camera frames when the
dataset has some, and meta.json in a canonical form (sorted keys). Each array enters as its name, dtype, shape and
bytes. File timestamps, zip compression and the order files were written in do not enter, nor the parts of meta.json
that say where or how fast the data was made rather than what it is (`PROVENANCE`: wall time, workers, backend, the
paths of a recording and its task file, the numerical stack). Recorded videos (`videos/`) are not hashed; the frames
decoded from them are.

`checksum_parts` also gives one digest per part (meta, features, trajectories, frames), so two datasets that differ
say where.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from langpref.dataset.frames import frames_path
from langpref.dataset.storage import Dataset, trajectory_path
from langpref.errors import LangprefError

PROVENANCE = ("wall_s", "workers", "backend", "ray_address", "source", "task_file", "made_with")
"""Keys of meta.json's `config` that say where, how or how fast a dataset was made, not what it holds."""


def _update_array(h: Any, name: str, value: np.ndarray) -> None:
    a = np.ascontiguousarray(value)
    h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
    h.update(a.tobytes())


def _update_npz(h: Any, path: Path) -> None:
    """Every array of an .npz file, in name order."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            for name in sorted(npz.files):
                _update_array(h, name, npz[name])
    except FileNotFoundError:
        raise LangprefError(f"{path} is missing; the dataset is incomplete, regenerate it") from None
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise LangprefError(f"{path} is truncated or corrupt ({type(exc).__name__}); regenerate the dataset") from None


def canonical_meta(ds: Dataset) -> str:
    """meta.json as JSON with sorted keys, without the provenance keys of its config."""
    raw = asdict(ds.meta)
    raw["config"] = {k: v for k, v in raw["config"].items() if k not in PROVENANCE}
    return json.dumps(raw, sort_keys=True, separators=(",", ":"), default=str)


def checksum_parts(ds: Dataset) -> dict[str, str]:
    """sha256 hex digest of each part of a dataset: meta, features, trajectories, and frames when it has some."""
    parts = {"meta": hashlib.sha256(canonical_meta(ds).encode())}
    parts["features"] = hashlib.sha256()
    _update_array(parts["features"], "features", np.asarray(ds.features, dtype=np.float64))
    parts["trajectories"] = hashlib.sha256()
    for i in range(len(ds)):
        parts["trajectories"].update(f"trajectory {i}|".encode())
        _update_npz(parts["trajectories"], trajectory_path(ds.root, i))
    if ds.meta.frames is not None:
        parts["frames"] = hashlib.sha256()
        for i in range(len(ds)):
            parts["frames"].update(f"frames {i}|".encode())
            _update_npz(parts["frames"], frames_path(ds.root, i))
    return {name: h.hexdigest() for name, h in parts.items()}


def combine(parts: dict[str, str]) -> str:
    """The dataset's checksum: one sha256 over the parts' digests, in name order."""
    return hashlib.sha256("".join(f"{k}={v}\n" for k, v in sorted(parts.items())).encode()).hexdigest()


def dataset_checksum(ds: Dataset) -> str:
    """sha256 of a dataset's content (see the module docstring)."""
    return combine(checksum_parts(ds))
