"""What a trajectory encoder reads, made in one place from a dataset split or from trajectories in memory.

A model sees one of three observation kinds (`ModelConfig.observations`, `langpref.model.config.OBSERVATIONS`):

    state          each step's proprioception [its change since the previous step] [that change's size], action
                   (the default without frames; the encoder of the paper's authors' code)
    images         each step's camera frame and action: what a robot without object state has
    images+state   both: the paper's states (images and proprioception), and the default when a dataset has frames

`EncoderInput` holds them as arrays: numeric per-step inputs (N, T, d) float32, the real length of each trajectory,
and for models that see images the frames (N, K, height, width, 3) uint8 with the frame each step is shown. Training,
evaluation, embedding, improvement and reward learning all make it through `dataset_input` or `trajectories_input`,
so what an encoder is fed is decided here only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from langpref.dataset.frames import frame_index, stack_frames
from langpref.errors import LangprefError
from langpref.model.config import check_observations
from langpref.model.encoders import step_input_dim, step_inputs


def sees_images(observations: str) -> bool:
    return observations in ("images", "images+state")


def sees_state(observations: str) -> bool:
    return observations in ("state", "images+state")


def resolve_observations(asked: str | None, has_frames: bool, where: str) -> str:
    """The observation kind a model trains on: the one asked for, else images+state when the dataset has frames
    and state when it has none; one that needs frames the dataset lacks is a one-line error."""
    if asked is None:
        return "images+state" if has_frames else "state"
    check_observations(asked)
    if sees_images(asked) and not has_frames:
        raise LangprefError(
            f"--observations {asked} needs camera frames and dataset {where} has none; make it with "
            "`langpref generate --images` (or `langpref import --images`) or train with --observations state"
        )
    return asked


def numeric_dim(
    observations: str, obs_dim: int, action_dim: int, observation_deltas: bool, delta_magnitudes: bool = False
) -> int:
    """Width of the numeric per-step input: see `numeric_inputs`."""
    if not sees_state(observations):
        return action_dim
    return step_input_dim(obs_dim, action_dim, observation_deltas, delta_magnitudes)


def numeric_inputs(
    obs: np.ndarray, actions: np.ndarray, observations: str, observation_deltas: bool, delta_magnitudes: bool = False
) -> np.ndarray:
    """Numeric per-step inputs (N, T, d) float32: `step_inputs` when the model sees the state, else the actions."""
    if sees_state(observations):
        return step_inputs(obs, actions, observation_deltas, delta_magnitudes)
    return np.asarray(actions, dtype=np.float32)


@dataclass
class EncoderInput:
    """Trajectories as an encoder reads them (see the module docstring)."""

    steps: np.ndarray
    """(N, T, d) float32 numeric inputs, raw (the encoder normalises them); padded past each length."""
    lengths: np.ndarray | None = None
    """(N,) real steps of each trajectory; None when all have T."""
    frames: np.ndarray | None = None
    """(N, K, height, width, 3) uint8 camera frames, for models that see images."""
    frame_index: np.ndarray | None = None
    """(N, T) int64: the frame each step is shown."""

    def __len__(self) -> int:
        return len(self.steps)

    def rows(self, start: int, stop: int) -> EncoderInput:
        """Trajectories start..stop-1."""

        def cut(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[start:stop]

        return EncoderInput(self.steps[start:stop], cut(self.lengths), cut(self.frames), cut(self.frame_index))


def trajectories_input(
    obs: np.ndarray,
    actions: np.ndarray,
    observations: str,
    observation_deltas: bool,
    lengths: np.ndarray | None = None,
    frames: np.ndarray | list[np.ndarray] | None = None,
    frame_stride: int | None = None,
    delta_magnitudes: bool = False,
) -> EncoderInput:
    """Encoder input of trajectories in memory: obs (N, T, obs_dim), actions (N, T, A), and for a model that sees
    images their frames (N, K, h, w, 3), or one (K_i, h, w, 3) array per trajectory, one every `frame_stride` steps.
    `observation_deltas` and `delta_magnitudes` as `ModelConfig`'s."""
    steps = numeric_inputs(obs, actions, observations, observation_deltas, delta_magnitudes)
    if not sees_images(observations):
        return EncoderInput(steps, lengths)
    if frames is None or frame_stride is None:
        raise LangprefError(
            "this model sees camera frames (observations images or images+state): give the trajectories' frames "
            "and their stride, or use a dataset with frames"
        )
    stacked = stack_frames(list(frames)) if isinstance(frames, list) else np.asarray(frames)
    n, horizon = steps.shape[:2]
    lens = np.full(n, horizon) if lengths is None else np.asarray(lengths)
    needed = -(-int(lens.max(initial=1)) // frame_stride)
    wrong_shape = stacked.ndim != 5 or stacked.shape[-1] != 3 or stacked.shape[0] != n or stacked.shape[1] < needed
    if stacked.dtype != np.uint8 or wrong_shape:
        raise LangprefError(
            f"frames must be uint8 (N, K, height, width, 3) with N = {n} and K >= {needed} (one every "
            f"{frame_stride} steps), got {stacked.dtype} {stacked.shape}"
        )
    return EncoderInput(steps, lengths, stacked, frame_index(lens, horizon, frame_stride))


def dataset_input(
    dataset, split: str | None, observations: str, observation_deltas: bool, delta_magnitudes: bool = False
) -> EncoderInput:
    """Encoder input of one split of a dataset (every trajectory when `split` is None), in dataset order."""
    obs, act = dataset.arrays(split)
    lengths = dataset.lengths(split)
    if not sees_images(observations):
        magnitudes = delta_magnitudes
        return trajectories_input(obs, act, observations, observation_deltas, lengths, delta_magnitudes=magnitudes)
    spec = dataset.frame_spec
    if spec is None:
        raise LangprefError(
            f"this model sees camera frames (observations {observations}) and dataset {dataset.root} has none; "
            "use a dataset made with `langpref generate --images` or `langpref import --images`"
        )
    return trajectories_input(
        obs,
        act,
        observations,
        observation_deltas,
        lengths,
        dataset.frames(split),
        frame_stride=spec.stride,
        delta_magnitudes=delta_magnitudes,
    )
