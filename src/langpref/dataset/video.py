"""Recorded camera videos: check that they decode, cut an episode's span into a file a browser plays, and take
small camera frames from it for models that see images (`decode_frames`, used by `langpref import --images`).

A recording's video may hold one episode or several back to back (LeRobotDataset v3 packs episodes into one mp4,
often AV1, which not every browser plays). The study serves H.264 mp4 or VP8/VP9 webm, so `write_clip` copies a
file that is already one of those and otherwise decodes the clip's frames and encodes them again. Everything runs
through PyAV (the `video` extra: import this module inside `extras.needs("video", ...)`); a file that does not
decode is a `LangprefError` naming it.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path

import av
import av.error
import numpy as np

from langpref.dataset.frames import frame_steps
from langpref.dataset.recording import VideoClip
from langpref.errors import LangprefError

# Codecs each container may hold for the file to play in current browsers as is.
_PLAYABLE = {".mp4": {"h264"}, ".webm": {"vp8", "vp9"}}
# Encoders tried in turn when a clip must be encoded for a container (PyAV's wheels may lack libx264).
_ENCODERS = {".mp4": ("libx264", "h264", "libopenh264"), ".webm": ("libvpx-vp9", "libvpx")}
_FORMATS = {".mp4": "mp4", ".webm": "webm"}
# An mp4's index goes first so a browser can start playing before the whole file has arrived.
_MUX_OPTIONS: dict[str, dict[str, str]] = {".mp4": {"movflags": "faststart"}, ".webm": {}}


def one_line(exc: BaseException) -> str:
    """An exception's message on one line, for a `LangprefError` (FFmpeg's own words, without its errno)."""
    text = getattr(exc, "strerror", None) if isinstance(exc, av.error.FFmpegError) else None
    return " ".join(str(text or exc).split()) or type(exc).__name__


def _video_stream(container: av.container.InputContainer, path: Path) -> av.video.stream.VideoStream:
    if not container.streams.video:
        raise LangprefError(f"{path}: no video stream in the file")
    return container.streams.video[0]


def _stream_fps(stream: av.video.stream.VideoStream) -> Fraction:
    """The stream's frame rate (average, else guessed, else base rate); 0 when the file does not say."""
    for rate in (stream.average_rate, stream.guessed_rate, stream.base_rate):
        if rate:
            return Fraction(rate)
    return Fraction(0)


def check_video(path: Path) -> tuple[int, float]:
    """Decode every frame of `path` and return (frame count, fps); a file that does not fully decode raises.

    Decoding the whole file (not only reading its header) is what catches a truncated upload or copy: FFmpeg
    stops quietly at the end of the data, so fewer frames than the container's index lists is an error too.
    """
    path = Path(path)
    if not path.is_file():
        raise LangprefError(f"{path}: video file not found")
    try:
        with av.open(str(path)) as container:
            stream = _video_stream(container, path)
            fps = float(_stream_fps(stream))
            declared = stream.frames  # from the container's index; 0 when it does not say
            frames = sum(1 for _ in container.decode(stream))
    except LangprefError:
        raise
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise LangprefError(f"{path}: video does not decode ({one_line(exc)})") from exc
    if frames == 0:
        raise LangprefError(f"{path}: video has no frames that decode")
    if declared and frames < declared:
        raise LangprefError(f"{path}: video is truncated or damaged ({frames} of {declared} frames decode)")
    return frames, fps


def _is_whole_file(clip: VideoClip, duration_s: float | None, frame_s: float) -> bool:
    """Whether the clip covers the whole file (its span, if any, reaches both ends to within half a frame)."""
    starts_at_zero = clip.start_s is None or clip.start_s <= frame_s / 2
    if clip.end_s is None:
        return starts_at_zero
    return starts_at_zero and duration_s is not None and clip.end_s >= duration_s - frame_s / 2


def _probe(path: Path) -> tuple[str, Fraction, float | None]:
    """(codec name, fps, duration in seconds or None) of the file's first video stream."""
    try:
        with av.open(str(path)) as container:
            stream = _video_stream(container, path)
            duration = None
            if stream.duration is not None and stream.time_base is not None:
                duration = float(stream.duration * stream.time_base)
            elif container.duration is not None:
                duration = container.duration / av.time_base
            return stream.codec_context.name, _stream_fps(stream), duration
    except LangprefError:
        raise
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise LangprefError(f"{path}: video does not open ({one_line(exc)})") from exc


def _clip_frames(container: av.container.InputContainer, clip: VideoClip, frame_s: float) -> Iterator[av.VideoFrame]:
    """The decoded frames whose timestamps lie in [start_s, end_s), with half a frame of slack for rounding.

    Seeks to the keyframe before `start_s` first, so a clip late in a long file does not decode all before it.
    """
    stream = _video_stream(container, clip.path)
    start = clip.start_s or 0.0
    end = clip.end_s if clip.end_s is not None else float("inf")
    slack = frame_s / 2
    if start > slack and stream.time_base is not None:
        container.seek(int(start / stream.time_base), stream=stream, backward=True, any_frame=False)
    for frame in container.decode(stream):
        t = frame.time
        if t is None or t < start - slack:
            continue
        if t >= end - slack:
            break
        yield frame


def _open_encoder(
    out: av.container.OutputContainer, suffix: str, fps: Fraction, width: int, height: int
) -> av.video.stream.VideoStream:
    """A video stream in `out` with the first encoder this PyAV build has for the container."""
    for name in _ENCODERS[suffix]:
        try:
            av.codec.Codec(name, "w")
        except (av.error.FFmpegError, ValueError):
            continue
        stream = out.add_stream(name, rate=fps)
        assert isinstance(stream, av.video.stream.VideoStream)  # every name in _ENCODERS is a video encoder
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.codec_context.time_base = Fraction(1) / fps
        return stream
    raise LangprefError(f"no {suffix} video encoder in this PyAV build (tried {', '.join(_ENCODERS[suffix])})")


def _encode(clip: VideoClip, tmp: Path, suffix: str, fps: Fraction, frame_s: float) -> int:
    """Decode the clip's frames and encode them into `tmp` (yuv420p, even size); returns the frame count."""
    count = 0
    with (
        av.open(str(clip.path)) as src,
        av.open(str(tmp), "w", format=_FORMATS[suffix], options=_MUX_OPTIONS[suffix]) as out,
    ):
        stream = None
        for frame in _clip_frames(src, clip, frame_s):
            if stream is None:
                width, height = max(2, frame.width - frame.width % 2), max(2, frame.height - frame.height % 2)
                stream = _open_encoder(out, suffix, fps, width, height)
            image = frame.reformat(width=stream.width, height=stream.height, format="yuv420p")
            image.pts, image.time_base = count, stream.codec_context.time_base  # one tick per frame at `fps`
            out.mux(stream.encode(image))
            count += 1
        if stream is not None:
            out.mux(stream.encode(None))
    return count


def write_clip(clip: VideoClip, dest: Path) -> Path:
    """Write the clip to `dest` (.mp4: H.264, .webm: VP9) as a file browsers play; returns `dest`.

    A clip that is the whole file, already in `dest`'s container with a codec browsers play, is copied byte for
    byte; anything else is decoded and encoded again. The file appears at `dest` only once it is complete.
    """
    dest = Path(dest)
    suffix = dest.suffix.lower()
    if suffix not in _PLAYABLE:
        raise LangprefError(f"{dest}: a clip is written as .mp4 or .webm, not {dest.suffix or 'no suffix'}")
    if not clip.path.is_file():
        raise LangprefError(f"{clip.path}: video file not found")
    codec, fps, duration = _probe(clip.path)
    if not fps:
        raise LangprefError(f"{clip.path}: the video does not say its frame rate")
    frame_s = float(1 / fps)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=dest.parent, prefix=f".{dest.stem}.", suffix=suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        copy = clip.path.suffix.lower() == suffix and codec in _PLAYABLE[suffix]
        if copy and _is_whole_file(clip, duration, frame_s):
            shutil.copyfile(clip.path, tmp)
        else:
            try:
                count = _encode(clip, tmp, suffix, fps, frame_s)
            except (av.error.FFmpegError, OSError, ValueError) as exc:
                raise LangprefError(f"{clip.path}: video does not decode or encode ({one_line(exc)})") from exc
            if count == 0:
                raise LangprefError(
                    f"{clip.path}: no video frames between {clip.start_s or 0.0:g}s and "
                    f"{'the end' if clip.end_s is None else f'{clip.end_s:g}s'}"
                )
        tmp.chmod(0o644)  # mkstemp makes it private; the study server and others read these files
        os.replace(tmp, dest)
    finally:
        tmp.unlink(missing_ok=True)
    return dest


def small_rgb(frame: av.VideoFrame, width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8 RGB of a decoded picture, resized by area averaging (the aspect ratio is not kept):
    the one resize of every recorded camera frame `import --images` stores, from a video or from still images."""
    return frame.reformat(width=width, height=height, format="rgb24", interpolation="AREA").to_ndarray()


def decode_frames(clip: VideoClip, steps: int, stride: int, width: int, height: int) -> np.ndarray:
    """Frames (ceil(steps / stride), height, width, 3) uint8 of a recorded clip, one for every `stride`-th step of
    its episode of `steps` steps, resized (area averaging; the aspect ratio is not kept).

    The clip's F frames span the episode: step t shows frame floor(t * F / steps) (frame t when the camera
    recorded once per step). Every frame is decoded and shrunk as it comes, so a long clip costs little memory.
    """
    path = Path(clip.path)
    if not path.is_file():
        raise LangprefError(f"{path}: video file not found")
    codec, fps, _ = _probe(path)
    frame_s = float(1 / fps) if fps else 0.0
    small: list[np.ndarray] = []
    try:
        with av.open(str(path)) as container:
            for frame in _clip_frames(container, clip, frame_s):
                small.append(small_rgb(frame, width, height))
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise LangprefError(f"{path}: video does not decode ({one_line(exc)})") from exc
    if not small:
        raise LangprefError(f"{path}: no video frames to take the episode's camera frames from ({codec})")
    kept = frame_steps(steps, stride)
    return np.stack([small[i] for i in (kept * len(small)) // steps]).astype(np.uint8)
