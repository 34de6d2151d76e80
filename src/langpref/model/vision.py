"""The trajectory encoder of models that see camera frames: a small CNN trained from scratch (the authors' choice
behind their `--use-img-obs`) turns each frame into a feature vector, which joins the step's numeric inputs
(proprioception and action, or the action alone) before the per-step MLP; the time mean and the last linear layer
are the state encoder's (`langpref.model.encoders.TrajectoryEncoder`).

The CNN ends in a spatial soft-argmax (the expected image position of each channel's activation, as in Levine et
al. 2016 and robomimic's visual encoders) beside each channel's mean: where the arm, the button or the pan is, is
what comparative feedback talks about, and a plain global average would throw positions away. No batch norm: a
model behaves the same in training and evaluation, whatever the batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from langpref.errors import LangprefError
from langpref.model.encoders import time_mean

EVAL_CHUNK = 512  # frames per CNN pass without gradients (bounds the activations' memory in evaluation)


class SpatialSoftArgmax(nn.Module):
    """(M, C, H, W) -> (M, 2C): each channel's expected (x, y) in [-1, 1] under the softmax of its activations."""

    def forward(self, maps: torch.Tensor) -> torch.Tensor:
        m, c, h, w = maps.shape
        p = torch.softmax(maps.reshape(m, c, h * w), dim=-1).reshape(m, c, h, w)
        ys = torch.linspace(-1.0, 1.0, h, device=maps.device, dtype=maps.dtype)
        xs = torch.linspace(-1.0, 1.0, w, device=maps.device, dtype=maps.dtype)
        x = (p.sum(dim=2) * xs).sum(dim=-1)
        y = (p.sum(dim=3) * ys).sum(dim=-1)
        return torch.cat([x, y], dim=1)


def random_shift(x: torch.Tensor, pad: int) -> torch.Tensor:
    """Each image of (M, C, H, W) moved by its own random whole-pixel offset in [-pad, pad] along each axis, the
    border repeated into the gap (DrQ, Kostrikov et al. 2021)."""
    m, c, h, w = x.shape
    padded = torch.nn.functional.pad(x, (pad, pad, pad, pad), mode="replicate")
    oy = torch.randint(0, 2 * pad + 1, (m, 1), device=x.device)
    ox = torch.randint(0, 2 * pad + 1, (m, 1), device=x.device)
    rows = (torch.arange(h, device=x.device) + oy)[:, None, :, None]
    cols = (torch.arange(w, device=x.device) + ox)[:, None, None, :]
    return padded[
        torch.arange(m, device=x.device)[:, None, None, None],
        torch.arange(c, device=x.device)[None, :, None, None],
        rows,
        cols,
    ]


class FrameEncoder(nn.Module):
    """uint8 frames (M, H, W, 3) -> features (M, out_dim): 3x3 convolutions of stride 2 (each halves height and
    width), then each channel's soft-argmax position and mean activation, a linear layer and a ReLU. In training,
    each frame is first shifted at random by up to `shift` pixels (0 = never)."""

    def __init__(self, channels: Sequence[int], out_dim: int, shift: int = 0):
        super().__init__()
        self.shift = shift
        layers: list[nn.Module] = []
        width = 3
        for c in channels:
            layers += [nn.Conv2d(width, c, 3, stride=2, padding=1), nn.ReLU()]
            width = c
        self.convs = nn.Sequential(*layers)
        self.keypoints = SpatialSoftArgmax()
        self.head = nn.Linear(3 * width, out_dim)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        x = frames.permute(0, 3, 1, 2).float() / 127.5 - 1.0
        if self.training and self.shift:
            x = random_shift(x, self.shift)
        maps = self.convs(x)
        pooled = torch.cat([self.keypoints(maps), maps.mean(dim=(2, 3))], dim=1)
        return torch.relu(self.head(pooled))


class ImageTrajectoryEncoder(nn.Module):
    """phi(tau) = out(mean over steps of MLP([normalised numeric input_t, CNN(frame shown at t)]))."""

    def __init__(
        self,
        numeric_dim: int,
        hidden: Sequence[int],
        latent_dim: int,
        observations: str,
        frame_channels: Sequence[int],
        frame_features: int,
        mean: np.ndarray | None = None,
        std: np.ndarray | None = None,
        observation_deltas: bool = False,
        frame_shift: int = 0,
        delta_magnitudes: bool = False,
    ):
        super().__init__()
        self.observations = observations
        self.observation_deltas = observation_deltas
        self.delta_magnitudes = delta_magnitudes
        self.frames = FrameEncoder(frame_channels, frame_features, frame_shift)
        layers: list[nn.Module] = []
        width = numeric_dim + frame_features
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(width, latent_dim)
        self.register_buffer("mean", torch.zeros(numeric_dim) if mean is None else torch.as_tensor(mean).float())
        self.register_buffer("std", torch.ones(numeric_dim) if std is None else torch.as_tensor(std).float())

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """CNN features (..., F) of uint8 frames (..., H, W, 3), in chunks when no gradient is kept."""
        lead, flat = frames.shape[:-3], frames.reshape(-1, *frames.shape[-3:])
        if torch.is_grad_enabled() or len(flat) <= EVAL_CHUNK:
            g = self.frames(flat)
        else:
            g = torch.cat([self.frames(flat[i : i + EVAL_CHUNK]) for i in range(0, len(flat), EVAL_CHUNK)])
        return g.reshape(*lead, g.shape[-1])

    def forward(
        self,
        steps: torch.Tensor,
        lengths: torch.Tensor | None = None,
        frames: torch.Tensor | None = None,
        frame_index: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """steps (N, T, d) raw numeric inputs, frames (N, K, H, W, 3) uint8, frame_index (N, T): the frame step t
        is shown -> phi (N, D). Each distinct frame goes through the CNN once. `lengths` as `TrajectoryEncoder`."""
        if frames is None or frame_index is None:
            raise LangprefError(f"this model sees camera frames (observations {self.observations}); none were given")
        g = self.frame_features(frames)
        g = torch.gather(g, 1, frame_index[..., None].expand(-1, -1, g.shape[-1]))
        x = torch.cat([(steps - self.mean) / self.std, g.to(steps.dtype)], dim=-1)
        return self.out(time_mean(self.body(x), lengths))
