"""Camera frames of a dataset's trajectories, for trajectory encoders that see images (the paper's states are images
plus proprioception).

A trajectory of T steps keeps the frame of every `stride`-th step (steps 0, k, 2k, ...: ceil(T / k) frames), each
downscaled to width x height RGB, uint8. Step t is shown the latest kept frame, number t // k. They are stored apart
from the trajectory's numbers, one compressed file per trajectory, so loading observations never decompresses
images and a dataset's frames are read only when a model that sees images asks for them:

    frames/000123.npz      frames (K, height, width, 3) uint8, K = ceil(T / stride)

`meta.json` records the frames' size, stride and source (`render`: replayed in the simulator; `video`: decoded from
the recorded camera video; `image`: decoded from a LeRobotDataset's per-step images) under "frames". Simulated
frames are rendered as `langpref render` renders its videos (MuJoCo's renderer without shadows or reflections), at
twice the size and box-averaged down, which keeps thin parts such as the gripper visible at 64x64.
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError

FRAMES_DIR = "frames"
MIN_SIZE, MAX_SIZE = 16, 512
SUPERSAMPLE = 2  # simulated frames are rendered at this multiple of their size and box-averaged down


@dataclass(frozen=True)
class FrameOptions:
    """Whether and how a new dataset stores camera frames (`langpref generate`, `langpref import`)."""

    images: bool = False
    """Store per-step camera frames (downscaled, every `--frame-stride`-th step) for models that see images (`langpref
    train --observations images|images+state`); simulated tasks render them, a recording decodes its videos (or a
    LeRobotDataset's image column)."""
    frame_size: tuple[int, int] = (64, 64)
    """WIDTH,HEIGHT of the stored frames in pixels (each 16 to 512)."""
    frame_stride: int = 5
    """Keep the frame of every k-th step (steps 0, k, 2k, ...); a step is shown the latest kept frame."""

    def validate(self) -> None:
        """Fail with one line on a size or stride that cannot make frames."""
        size = tuple(self.frame_size)
        if len(size) != 2 or any(not MIN_SIZE <= int(s) <= MAX_SIZE for s in size):
            raise LangprefError(
                f"--frame-size {','.join(map(str, size))} must be WIDTH,HEIGHT with each between {MIN_SIZE} and "
                f"{MAX_SIZE} pixels, e.g. 64,64"
            )
        if self.frame_stride < 1:
            raise LangprefError(f"--frame-stride must be at least 1, got {self.frame_stride}")

    def spec(self, source: str) -> FrameSpec | None:
        """What the dataset records about its frames, or None without --images."""
        if not self.images:
            return None
        self.validate()
        width, height = (int(s) for s in self.frame_size)
        return FrameSpec(width=width, height=height, stride=int(self.frame_stride), source=source)


@dataclass(frozen=True)
class FrameSpec:
    """The frames a dataset holds (meta.json's "frames"): size, stride, and where they came from."""

    width: int
    height: int
    stride: int
    source: str
    """`render` (replayed in the simulator), `video` (decoded from the recorded camera video) or `image` (decoded
    from a LeRobotDataset's per-step images)."""

    @property
    def shape(self) -> tuple[int, int, int]:
        """(height, width, 3): one frame's array shape."""
        return (self.height, self.width, 3)

    def count(self, steps: int) -> int:
        """Frames kept of a trajectory of `steps` steps."""
        return math.ceil(steps / self.stride)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any], where: str) -> FrameSpec:
        try:
            spec = cls(int(raw["width"]), int(raw["height"]), int(raw["stride"]), str(raw["source"]))
        except (KeyError, TypeError, ValueError):
            raise LangprefError(f"{where}: 'frames' must give width, height, stride and source") from None
        if spec.stride < 1 or spec.width < 1 or spec.height < 1:
            raise LangprefError(f"{where}: 'frames' has a size or stride below 1")
        return spec


def frame_steps(steps: int, stride: int) -> np.ndarray:
    """The steps whose frames are kept: 0, stride, 2 stride, ... below `steps`."""
    return np.arange(0, steps, stride)


def frame_index(lengths: np.ndarray, horizon: int, stride: int) -> np.ndarray:
    """(N, horizon) int64: the frame each step is shown (t // stride), kept within trajectory i's own frames
    (padding steps past lengths[i] point at its last frame; the encoder masks them anyway)."""
    last = np.ceil(np.asarray(lengths) / stride).astype(np.int64) - 1
    return np.minimum((np.arange(horizon) // stride)[None, :], last[:, None])


def frames_path(root: Path, index: int) -> Path:
    return Path(root) / FRAMES_DIR / f"{index:06d}.npz"


def save_frames(root: Path, index: int, frames: np.ndarray) -> Path:
    """Write one trajectory's frames atomically (a temp file renamed into place), compressed."""
    path = frames_path(root, index)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, frames=np.ascontiguousarray(frames, dtype=np.uint8))
    tmp.replace(path)
    return path


def load_frames(root: Path, index: int, spec: FrameSpec, steps: int) -> np.ndarray:
    """Trajectory `index`'s frames (K, height, width, 3) uint8, checked against `spec` and its length."""
    path = frames_path(root, index)
    if not path.is_file():
        raise LangprefError(f"dataset {root} is incomplete: {FRAMES_DIR}/{path.name} is missing; regenerate it")
    try:
        with np.load(path, allow_pickle=False) as npz:
            frames = npz["frames"]
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise LangprefError(f"{path} is truncated or corrupt ({type(exc).__name__}); regenerate the dataset") from None
    expected = (spec.count(steps), *spec.shape)
    if frames.shape != expected or frames.dtype != np.uint8:
        raise LangprefError(
            f"{path} holds {frames.dtype} frames {frames.shape}, meta.json says {expected} uint8; regenerate it"
        )
    return frames


def stack_frames(per_trajectory: list[np.ndarray]) -> np.ndarray:
    """(N, K, height, width, 3): trajectories' frames stacked, the shorter ones padded with their last frame. Works on
    any arrays that differ only in their first axis (`storage.stack_steps` stacks per-step arrays with it)."""
    most = max(len(f) for f in per_trajectory)
    return np.stack(
        [f if len(f) == most else np.concatenate([f, np.repeat(f[-1:], most - len(f), axis=0)]) for f in per_trajectory]
    )


def box_downsample(frames: np.ndarray, factor: int) -> np.ndarray:
    """(N, f*H, f*W, 3) uint8 -> (N, H, W, 3): the mean of each f x f block, rounded."""
    if factor == 1:
        return frames
    n, h, w, c = frames.shape
    blocks = frames.reshape(n, h // factor, factor, w // factor, factor, c).astype(np.float32)
    return np.rint(blocks.mean(axis=(2, 4))).astype(np.uint8)


def render_trajectory_frames(env: Any, traj: Any, spec: FrameSpec) -> np.ndarray:
    """The frames of a simulated trajectory (a `Trajectory` with qpos, qvel and seed), replayed in a live `env` of
    its task: reset with the trajectory's seed (scene layout not in qpos), then the kept steps' states rendered."""
    from langpref.tasks.render import render_frames

    if traj.qpos is None or traj.qvel is None or traj.seed is None:
        raise LangprefError(f"trajectory {traj.index} has no simulator state to render frames from")
    env.reset(traj.seed)
    keep = frame_steps(len(traj.qpos), spec.stride)
    big = render_frames(env, traj.qpos[keep], traj.qvel[keep], spec.width * SUPERSAMPLE, spec.height * SUPERSAMPLE)
    return box_downsample(big, SUPERSAMPLE)
