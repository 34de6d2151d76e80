"""The labelled copy of a plain recording folder (NAME.npz episodes): each episode's file byte for byte with the
label arrays appended, so its own arrays keep their bytes; videos linked, everything else copied."""

from __future__ import annotations

import io
import shutil
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from langpref.dataset.label_columns import EPISODE, PROGRESS, bar, check_sizes, episode_columns, link_or_copy
from langpref.dataset.recording import VIDEO_SUFFIXES, plain_episode_files, read_plain_episode
from langpref.errors import LangprefError


def label_plain(src: Path, out: Path, reward: Any, progress: bool = True) -> dict[str, Any]:
    """Label every NAME.npz of the plain recording `src` into `out` (the original file with the label arrays
    appended, so its own arrays keep their bytes); videos linked, other files and folders copied. Returns
    {frames, episode_rewards, curves (episode name -> its v_t)}."""
    files = plain_episode_files(src)
    frames, rewards, curves = 0, [], {}
    for path in bar(files, f"label {src.name}", len(files), progress):
        episode = read_plain_episode(path)
        check_sizes(reward, episode.observations.shape[1], episode.actions.shape[1], str(path))
        columns = episode_columns(reward, episode.observations, episode.actions)
        _append_arrays(path, out / path.name, columns)
        frames += len(episode.observations)
        rewards.append(float(columns[EPISODE][0]))
        curves[path.stem] = columns[PROGRESS]
    labelled = {p.name for p in files}
    for entry in sorted(src.iterdir()):
        if entry.name in labelled:
            continue
        if entry.is_dir():
            shutil.copytree(entry, out / entry.name)
        elif entry.suffix in VIDEO_SUFFIXES:
            link_or_copy(entry, out / entry.name)
        else:
            shutil.copy2(entry, out / entry.name)
    return {"frames": frames, "episode_rewards": rewards, "curves": curves}


def _append_arrays(src: Path, dst: Path, arrays: dict[str, np.ndarray]) -> None:
    """`dst`: the .npz `src` byte for byte, with `arrays` added as members KEY.npy (compressed as `src`'s first
    member is); a one-line error if `src` already holds one of them (a labelled copy: label the original)."""
    shutil.copy2(src, dst)
    try:
        with zipfile.ZipFile(dst, "a") as npz:
            names = set(npz.namelist())
            taken = [key for key in arrays if f"{key}.npy" in names]
            if taken:
                raise LangprefError(f"{src} already has {taken[0]!r} (it was labelled before): label the original")
            infos = npz.infolist()
            compression = infos[0].compress_type if infos else zipfile.ZIP_STORED
            for key, value in arrays.items():
                buffer = io.BytesIO()
                np.lib.format.write_array(buffer, np.ascontiguousarray(value), allow_pickle=False)
                npz.writestr(f"{key}.npy", buffer.getvalue(), compress_type=compression)
    except zipfile.BadZipFile as exc:
        raise LangprefError(f"{src}: not a readable .npz episode ({exc})") from None
