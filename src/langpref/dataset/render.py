"""A video of a stored trajectory: its recorded camera video (recorded datasets), or a replay of its simulator
states in the task's simulator (simulated datasets; the env is reset with the trajectory's seed first, so scene
layout that is not in qpos, such as Meta-World's button box or robosuite's object placement, is the one it saw).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from langpref.dataset.storage import Dataset, load_dataset
from langpref.errors import LangprefError
from langpref.tasks import make_env
from langpref.tasks.render import VIDEO_CODECS, render_frames, write_video


def replay_video(
    ds: Dataset, index: int, out: Path, env: Any, width: int = 320, height: int = 240, fps: int = 40, stride: int = 1
) -> Path:
    """Render trajectory `index` of a simulated dataset in a live `env` of its task (kept by the caller)."""
    traj = ds.load(index)
    if traj.qpos is None or traj.qvel is None:
        raise LangprefError(f"trajectory {index} of {ds.root} has no simulator state to replay and no recorded video")
    env.reset(traj.seed)
    return write_video(render_frames(env, traj.qpos, traj.qvel, width, height, stride), out, fps)


def recorded_video(ds: Dataset, index: int, out: Path) -> Path:
    """The recorded video of trajectory `index` at `out`: copied when the format is the same (imported videos are
    browser-playable H.264), else transcoded."""
    from langpref.dataset.recording import VideoClip
    from langpref.extras import needs

    with needs("video", "a recorded trajectory's video"):
        from langpref.dataset.video import write_clip

    src = ds.video_path(index)
    if src is None or not src.is_file():
        raise LangprefError(f"trajectory {index} of {ds.root} has no recorded video ({src} is missing)")
    return write_clip(VideoClip(src), out)


def render_trajectory(
    data_dir: str | Path,
    index: int,
    out: str | Path,
    width: int = 320,
    height: int = 240,
    fps: int = 40,
    stride: int = 1,
) -> Path:
    """A .mp4 (H.264) or .webm (VP9) video of trajectory `index` of a dataset."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    out = Path(out)
    if out.suffix not in VIDEO_CODECS:
        raise LangprefError(f"unsupported video format {out.suffix!r} for {out}: use .mp4 or .webm")
    ds = load_dataset(data_dir)
    if not 0 <= index < len(ds):
        raise LangprefError(f"--index {index} is out of range: {data_dir} has trajectories 0..{len(ds) - 1}")
    if ds.meta.videos:
        return recorded_video(ds, index, out)
    env = make_env(ds.env, ds.meta.horizon)
    try:
        return replay_video(ds, index, out, env, width, height, fps, stride)
    finally:
        env.close()
