"""`langpref import`: a robot recording (a plain folder of episodes, or a LeRobotDataset) into a langpref dataset.

The recording brings observations, actions, and optionally features, success and a camera video per episode; the
task file (`langpref.tasks.taskfile`) brings the task's name, features, text and bank. Features come from the task
file's `features_from` function when it names one, else from the episodes' own `features`. Episodes may differ in
length. Videos are copied when a browser plays them as they are, else cut and transcoded once, here. With
`--images`, small camera frames are decoded from every episode's video too (`langpref.dataset.frames`), or, for a
LeRobotDataset whose camera is an image column, from its per-step images (`langpref.dataset.images`).

Everything is written into a temporary folder beside `out` and renamed into place at the end, so a bad episode
(one line naming its file and key) never leaves half a dataset.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from langpref.dataset.frames import FrameOptions, FrameSpec, save_frames
from langpref.dataset.recording import (
    VIDEO_SUFFIXES,
    ImageCells,
    RecordedEpisode,
    is_lerobot,
    orphan_videos,
    plain_episode_files,
    read_plain_episode,
)
from langpref.dataset.storage import (
    DatasetMeta,
    Trajectory,
    save_trajectory,
    shuffle_into_splits,
    video_path,
    write_meta,
)
from langpref.errors import LangprefError
from langpref.extras import needs, require
from langpref.tasks.taskfile import TaskFile, save_task

DEFAULT_SPLITS = (0.8, 0.1, 0.1)  # the paper's simulated datasets: 260/32/32
MAX_NAMED = 20
"""Bad episodes named one per line in an import's error; the rest are counted."""
MIN_EPISODES = 30
"""Below this many episodes an import is warned about (`small_recording`): with the default shares, validation and
test then hold 2 or 3 trajectories each, at most 6 ordered pairs per feature, so one pair moves their accuracy by a
sixth or more and the epoch `train` keeps is chosen on noise. From 30 on each holds 3 or more."""


@dataclass(frozen=True)
class ImportConfig:
    src: Path
    """A plain recording folder (NAME.npz episodes, NAME.mp4/.webm videos) or a LeRobotDataset (v3)."""
    task: Path
    """The task file (TOML) naming the task, its features, its bank and where its features come from."""
    out: Path
    """Dataset directory to create."""
    seed: int = 0
    """Seed of the trajectory split (and of the bank's split, for an unsplit bank)."""
    splits: tuple[float, float, float] = DEFAULT_SPLITS
    """Shares of train/val/test trajectories."""
    state_key: str = "observation.state"
    """LeRobotDataset: the feature read as observations."""
    action_key: str = "action"
    """LeRobotDataset: the feature read as actions."""
    camera: str | None = None
    """LeRobotDataset: the camera feature, a video (kept as each episode's video) or an image column (frames for
    --images only); default the first video feature, else the first image feature; '' for none."""
    force: bool = False
    """Overwrite an existing dataset in `out`."""
    bank_check: bool = True
    """After the import, read the bank's train phrasings leave-one-out with the pretrained language model (`langpref
    bank check`), print its one-line summary and warn on weak meanings (a few seconds)."""
    frames: FrameOptions = field(default_factory=FrameOptions)
    """Camera frames (--images, --frame-size, --frame-stride), decoded from every episode's video or images."""


def split_counts(n: int, shares: tuple[float, float, float]) -> dict[str, int]:
    """Trajectories per split: `shares` of n, with at least two in val and test once there are six or more
    (training validates on pairs, and the synthetic humans compare trajectories within a split), else one."""
    if n < 3:
        raise LangprefError(f"the recording has {n} episode(s); a dataset needs at least 3 (one per split)")
    least = 2 if n >= 6 else 1
    total = sum(shares)
    n_val = max(least, round(n * shares[1] / total))
    n_test = max(least, round(n * shares[2] / total))
    if n - n_val - n_test < 1:
        raise LangprefError(f"--splits {shares} leaves no episode of {n} for train")
    return {"train": n - n_val - n_test, "val": n_val, "test": n_test}


def _step_features(ep: RecordedEpisode, task: TaskFile, fn: Any, where: str) -> np.ndarray:
    """Per-step features (T, F) of one episode, from the task's function or from the episode itself."""
    n_feat, steps = len(task.features), len(ep.actions)
    if fn is not None:
        try:
            out = fn(ep.observations.copy(), ep.actions.copy())
        except Exception as exc:
            raise LangprefError(
                f"{where}: the feature function {task.features_from} failed: {type(exc).__name__}: {exc}"
            ) from None
        out = np.asarray(out, dtype=np.float64)
        if out.shape != (steps, n_feat):
            raise LangprefError(
                f"{where}: the feature function {task.features_from} returned shape {out.shape}, "
                f"expected ({steps}, {n_feat}): one row per step, one column per feature"
            )
    elif ep.features is not None:
        out = np.asarray(ep.features, dtype=np.float64)
        if out.shape == (n_feat,):
            out = np.broadcast_to(out, (steps, n_feat))  # per-episode features: their time mean is themselves
        elif out.shape != (steps, n_feat):
            raise LangprefError(
                f"{where}: 'features' has shape {out.shape}, expected ({steps}, {n_feat}) per step "
                f"or ({n_feat},) per episode, in the task file's order ({', '.join(task.features)})"
            )
    else:
        raise LangprefError(
            f"{where}: no features: give 'features' in every episode or features_from in the task file {task.path}"
        )
    if not np.isfinite(out).all():
        raise LangprefError(f"{where}: the features hold NaN or infinite values")
    return out.astype(np.float32)


def _still_frames(images: ImageCells, steps: int, spec: FrameSpec) -> np.ndarray:
    """The frames of an episode recorded as one still image per step (PyAV decodes them: the video extra, as for
    frames from videos)."""
    with needs("video", "--images from a LeRobotDataset's image column"):
        from langpref.dataset.images import image_frames
    return image_frames(images, steps, spec)


def _episodes(cfg: ImportConfig) -> tuple[str, list[Any]]:
    """(layout name, a list of zero-argument loaders, one per episode, each returning (where, RecordedEpisode))."""
    if is_lerobot(cfg.src):
        with needs("lerobot", "importing a LeRobotDataset"):
            from langpref.dataset.lerobot import read_lerobot

        eps = read_lerobot(
            cfg.src, state_key=cfg.state_key, action_key=cfg.action_key, camera=cfg.camera, images=cfg.frames.images
        )
        return "lerobot", [lambda ep=ep: (f"{cfg.src} {ep.name}", ep) for ep in eps]
    files = plain_episode_files(cfg.src)
    if any(f.with_suffix(s).is_file() for f in files for s in VIDEO_SUFFIXES):
        require("video", "importing a recording's camera videos")  # before any work, not after reading every episode
    return "plain", [lambda f=f: (str(f), read_plain_episode(f)) for f in files]


def _prepare(cfg: ImportConfig) -> Path:
    src, out = Path(cfg.src), Path(cfg.out)
    if not src.is_dir():
        raise LangprefError(f"recording {src} not found" if not src.exists() else f"recording {src} is not a folder")
    if out.exists() and not cfg.force:
        raise LangprefError(f"{out} already exists; pass --force to overwrite it or choose another --out")
    if out.resolve() == src.resolve() or src.resolve() in out.resolve().parents:
        raise LangprefError(f"--out {out} lies inside the recording {src}; choose a folder outside it")
    tmp = out.parent / f".{out.name}.importing-{os.getpid()}"
    try:
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
    except OSError as exc:
        raise LangprefError(f"cannot write --out {out} ({exc.strerror or exc}); choose another folder") from None
    return tmp


def small_recording(counts: dict[str, int]) -> str | None:
    """A warning when a recording is below the size that trains sensibly (`MIN_EPISODES`), with its size, its
    splits and why; None from `MIN_EPISODES` on."""
    n, val, test = sum(counts.values()), counts["val"], counts["test"]
    if n >= MIN_EPISODES:
        return None
    pairs = min(val * (val - 1), test * (test - 1))
    noise = f"one pair moves their accuracy by {1 / pairs:.2f}" if pairs else "there is no pair to score"
    return (
        f"only {n} episodes (train {counts['train']}, val {val}, test {test}): validation and test hold at most "
        f"{pairs} ordered pairs per feature, so {noise} and the epoch `train` keeps is chosen on noise; "
        f"record {MIN_EPISODES} or more episodes (3 or more each in val and test)"
    )


def _warnings(cfg: ImportConfig, layout: str, counts: dict[str, int]) -> list[str]:
    """What the import did but a lab should know: videos without their episode, and a recording too small."""
    out = []
    orphans = orphan_videos(Path(cfg.src)) if layout == "plain" else []
    if orphans:
        shown = ", ".join(orphans[:MAX_NAMED]) + (
            f" and {len(orphans) - MAX_NAMED} more" if len(orphans) > MAX_NAMED else ""
        )
        out.append(
            f"{len(orphans)} video(s) in {cfg.src} have no episode beside them and were not imported: {shown} "
            "(an episode is NAME.npz, its video NAME.mp4 or NAME.webm)"
        )
    small = small_recording(counts)
    return out + ([small] if small else [])


@dataclass
class _Episodes:
    """What the import learnt of the episodes while storing them, in episode order."""

    obs_dim: int | None = None
    action_dim: int | None = None
    lengths: list[int] = field(default_factory=list)
    features: list[np.ndarray] = field(default_factory=list)
    success: list[bool | None] = field(default_factory=list)
    videos: list[Any] = field(default_factory=list)
    wheres: list[str] = field(default_factory=list)
    imaged: list[bool] = field(default_factory=list)
    """Whose frames came from its still images (a LeRobotDataset's image column)."""


def _episode(i: int, where: str, ep: RecordedEpisode, task: TaskFile, fn: Any, seen: _Episodes) -> Trajectory:
    """Episode `i` as a trajectory, its shapes checked against the first good episode's (a `LangprefError` naming
    `where` otherwise)."""
    if len(ep.actions) < 2:
        raise LangprefError(f"{where}: the episode has {len(ep.actions)} step(s); it needs at least 2")
    if seen.obs_dim is None:
        seen.obs_dim, seen.action_dim = ep.observations.shape[1], ep.actions.shape[1]
    elif (ep.observations.shape[1], ep.actions.shape[1]) != (seen.obs_dim, seen.action_dim):
        raise LangprefError(
            f"{where}: observations/actions have {ep.observations.shape[1]}/"
            f"{ep.actions.shape[1]} dims, earlier episodes {seen.obs_dim}/{seen.action_dim}"
        )
    return Trajectory(
        index=i,
        observations=ep.observations,
        actions=ep.actions,
        step_features=_step_features(ep, task, fn, where),
        qpos=None,
        qvel=None,
        success=bool(ep.success),
        seed=None,
        source=ep.name,
    )


def bad_episodes(problems: list[str], total: int, what: str = "episodes are bad") -> str:
    """One error for every bad episode: a single one as its own line, several as a head line and one line each (the
    first `MAX_NAMED`, then how many more), so a lab fixes them all in one go instead of one per import."""
    if len(problems) == 1:
        return problems[0]
    lines = [f"{len(problems)} of {total} {what} (fix them all, then import again):"]
    lines += [f"  {p}" for p in problems[:MAX_NAMED]]
    if len(problems) > MAX_NAMED:
        lines.append(f"  and {len(problems) - MAX_NAMED} more")
    return "\n".join(lines)


def _store_episodes(tmp: Path, loaders: list[Any], task: TaskFile, spec: FrameSpec | None, progress: bool) -> _Episodes:
    """Read every episode, check its shapes against the first, and store it (with its still frames, if any). A bad
    episode does not stop the reading: every one is checked and all the bad ones are named in one error."""
    fn = task.step_features()
    seen = _Episodes()
    problems: list[str] = []
    for i, load in enumerate(
        tqdm(loaders, desc=f"import {task.name}", unit="episode", disable=not progress, dynamic_ncols=True)
    ):
        try:
            where, ep = load()
            traj = _episode(i, where, ep, task, fn, seen)
        except LangprefError as exc:
            problems.append(str(exc))
            continue
        if problems:  # the import fails anyway: check the rest, store nothing more
            continue
        save_trajectory(tmp, traj)
        seen.imaged.append(spec is not None and ep.images is not None)
        if spec is not None and ep.images is not None:
            save_frames(tmp, i, _still_frames(ep.images, traj.horizon, spec))
        seen.lengths.append(traj.horizon)
        seen.features.append(traj.features)
        seen.success.append(ep.success)
        seen.videos.append(ep.video)
        seen.wheres.append(where)
    if problems:
        raise LangprefError(bad_episodes(problems, len(loaders)))
    return seen


def _check_videos(seen: _Episodes, spec: FrameSpec | None) -> FrameSpec | None:
    """Refuse a recording where only some episodes have a video, or `--images` where an episode has no camera;
    the frame spec as stored (its source the image column when an episode's frames came from there)."""
    with_video = [v is not None for v in seen.videos]
    if any(with_video) and not all(with_video):
        missing = [f"episode {w} has no video" for w, v in zip(seen.wheres, with_video) if not v]
        if len(missing) == 1:
            missing[0] += " while others have one"
        raise LangprefError(
            bad_episodes(missing, len(with_video), "episodes have no video while others have one")
            + ("; " if len(missing) == 1 else "\n")
            + "give every episode its video (NAME.mp4 or NAME.webm) or none"
        )
    bare = [w for w, v, m in zip(seen.wheres, with_video, seen.imaged) if not (v or m)]
    if spec is not None and bare:
        raise LangprefError(
            f"--images takes each episode's camera frames from its video (or a LeRobotDataset's image column), "
            f"and {bare[0]} has none; give every episode its video (NAME.mp4 or NAME.webm) or import without "
            "--images"
        )
    if spec is not None and any(seen.imaged):
        spec = replace(spec, source="image")
    return spec


def _store_videos(tmp: Path, seen: _Episodes, spec: FrameSpec | None, progress: bool) -> None:
    """Copy or transcode every episode's video, and decode its frames where they did not come from images."""
    from langpref.dataset.video import decode_frames, write_clip  # the video extra: checked by _episodes

    for i, clip in enumerate(tqdm(seen.videos, desc="videos", unit="video", disable=not progress, dynamic_ncols=True)):
        write_clip(clip, video_path(tmp, i))
        if spec is not None and not seen.imaged[i]:
            frames = decode_frames(clip, seen.lengths[i], spec.stride, spec.width, spec.height)
            save_frames(tmp, i, frames)


def _meta(
    cfg: ImportConfig,
    task: TaskFile,
    task_obj: Any,
    layout: str,
    splits: dict[str, list[int]],
    seen: _Episodes,
    with_video: bool,
    spec: FrameSpec | None,
) -> DatasetMeta:
    """The imported dataset's meta.json: its task, shapes, splits, where it came from, lengths, videos and frames."""
    horizon = max(seen.lengths)
    return DatasetMeta(
        env=task.name,
        horizon=horizon,
        obs_layout=[asdict(f) for f in task_obj.obs_layout],
        action_dim=seen.action_dim,
        feature_names=list(task.features),
        splits=splits,
        num_trajectories=len(seen.lengths),
        config={
            "source": str(cfg.src),
            "layout": layout,
            "task_file": str(task.path),
            "seed": cfg.seed,
            "splits": list(cfg.splits),
            "features_from": task.features_from or "recording",
            "success_known": all(s is not None for s in seen.success),
        },
        lengths=None if min(seen.lengths) == horizon else seen.lengths,
        videos=with_video,
        frames=None if spec is None else spec.to_dict(),
    )


def import_recording(cfg: ImportConfig, task: TaskFile, bank: dict[str, Any], progress: bool = True) -> dict[str, Any]:
    """Import the recording `cfg.src` as a dataset of `task`, storing `bank` (split, checked) as its bank."""
    start = time.time()
    spec = cfg.frames.spec("video")
    tmp = _prepare(cfg)
    try:
        layout, loaders = _episodes(cfg)
        n = len(loaders)
        counts = split_counts(n, cfg.splits)
        seen = _store_episodes(tmp, loaders, task, spec, progress)
        spec = _check_videos(seen, spec)
        with_video = all(v is not None for v in seen.videos)
        if with_video:
            _store_videos(tmp, seen, spec, progress)
        splits = shuffle_into_splits(n, counts, cfg.seed)
        task_obj = task.task(seen.obs_dim, seen.action_dim, tmp / "utterances.json")
        save_task(task_obj, tmp, bank)
        meta = _meta(cfg, task, task_obj, layout, splits, seen, with_video, spec)
        write_meta(tmp, meta, np.array(seen.features, dtype=np.float64).reshape(n, len(task.features)))
        out = Path(cfg.out)
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    wall = time.time() - start
    return {
        "out": str(cfg.out),
        "task": task.name,
        "layout": layout,
        "num_trajectories": n,
        "splits": {k: len(v) for k, v in splits.items()},
        "horizon": meta.horizon,
        "min_length": min(seen.lengths),
        "videos": meta.videos,
        "frames": meta.frames,
        "features_from": meta.config["features_from"],
        "wall_s": wall,
        "episodes_per_s": n / wall if wall > 0 else None,
        "warnings": _warnings(cfg, layout, counts),
    }
