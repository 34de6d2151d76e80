"""Render simulator states into videos by replaying them offscreen (for tasks with a MuJoCo simulator).

Uses MuJoCo's own renderer on EGL (works on a CPU through Mesa), with the expensive extras off (no shadows,
reflections or multisampling): about 5x faster than the simulators' default settings and fine for study videos.
The env is reset with the trajectory's seed first, so scene layout that is not in qpos (Meta-World's button box,
robosuite's object placement) is the one the trajectory saw.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from langpref.errors import LangprefError

VIDEO_CODECS = {".mp4": ("libx264", "yuv420p"), ".webm": ("libvpx-vp9", "yuv420p")}


def _camera(mujoco, model, spec: dict):
    cam = mujoco.MjvCamera()
    if "name" in spec:
        cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        cam.fixedcamid = model.camera(spec["name"]).id
    else:
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = spec["lookat"]
        cam.distance, cam.azimuth, cam.elevation = spec["distance"], spec["azimuth"], spec["elevation"]
    return cam


def render_frames(
    env, qpos: np.ndarray, qvel: np.ndarray, width: int = 320, height: int = 240, stride: int = 1
) -> np.ndarray:
    """Frames (N, height, width, 3) uint8, upright, of the states `qpos/qvel[::stride]` in a live env."""
    import mujoco

    model, data = env.mujoco_handles()
    model.vis.quality.shadowsize = 0
    model.vis.quality.offsamples = 0
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    renderer = mujoco.Renderer(model, height=height, width=width)
    try:
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        cam = _camera(mujoco, model, env.camera())
        frames = []
        for t in range(0, len(qpos), stride):
            env.set_state(qpos[t], qvel[t])
            renderer.update_scene(data, camera=cam)
            frames.append(renderer.render().copy())  # mujoco.Renderer already returns rows top-first
        return np.stack(frames)
    finally:
        renderer.close()


def write_video(frames: np.ndarray, out: Path, fps: int) -> Path:
    import imageio.v2 as imageio

    out = Path(out)
    if out.suffix not in VIDEO_CODECS:
        raise LangprefError(f"unsupported video format {out.suffix!r} for {out}: use .mp4 or .webm")
    codec, pix = VIDEO_CODECS[out.suffix]
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.partial{out.suffix}")
    writer = imageio.get_writer(
        tmp, fps=fps, codec=codec, pixelformat=pix, macro_block_size=8, ffmpeg_log_level="error", output_params=["-an"]
    )
    try:
        for frame in frames:
            writer.append_data(frame)
    finally:
        writer.close()
    tmp.replace(out)
    return out
