"""Camera frames from still images: `langpref import --images` of a LeRobotDataset whose camera is an image column
(one PNG or JPEG per step in the data files) rather than a video.

The frames are the same as from a video (`langpref.dataset.frames`): the image of every `stride`-th step, resized by
`video.small_rgb` (area averaging), so a model cannot tell which kind of recording its frames came from. Only the
kept steps' images are decoded, each through PyAV (the `video` extra, as for videos: import this module inside
`extras.needs("video", ...)`), which reads every image format FFmpeg does. A cell that does not decode is a
`LangprefError` naming the file, column, episode and frame.
"""

from __future__ import annotations

import io

import av
import av.error
import numpy as np

from langpref.dataset.frames import FrameSpec, frame_steps
from langpref.dataset.recording import ImageCells
from langpref.dataset.video import one_line, small_rgb
from langpref.errors import LangprefError


def decode_image(data: bytes, where: str) -> av.VideoFrame:
    """The picture encoded in `data` (PNG, JPEG, or any other image FFmpeg reads); `where` names it in the error."""
    try:
        with av.open(io.BytesIO(data)) as container:
            if not container.streams.video:
                raise LangprefError(f"{where}: not an image (no picture in the cell)")
            for frame in container.decode(container.streams.video[0]):
                return frame
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise LangprefError(f"{where}: not a decodable image ({one_line(exc)})") from None
    raise LangprefError(f"{where}: not a decodable image (no picture in the cell)")


def image_frames(images: ImageCells, steps: int, spec: FrameSpec) -> np.ndarray:
    """Frames (ceil(steps / stride), height, width, 3) uint8 of an episode of `steps` steps recorded as one image
    per step: the images of steps 0, stride, 2 stride, ..., each resized to the spec's size."""
    if len(images.cells) != steps:
        raise LangprefError(f"{images.where}: {len(images.cells)} images for {steps} steps")
    frames = []
    for t in frame_steps(steps, spec.stride):
        where = f"{images.where}, frame {t}"
        data = images.cells[t]
        if not data:
            raise LangprefError(f"{where}: the cell holds no image bytes (an image kept only as a file path)")
        frames.append(small_rgb(decode_image(data, where), spec.width, spec.height))
    return np.stack(frames).astype(np.uint8)
