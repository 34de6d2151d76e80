"""The two encoders of the shared latent space (paper Sec. 4.1).

Trajectory encoder: an MLP applied to every step's (observation, action), normalised with the train split's mean and
std, averaged over time into phi (as the authors' code: state+action -> 128 -> ReLU -> D, then the mean over steps).
By default each step also carries the change of observation since the previous step (`observation_deltas`): speed is a
property of consecutive states, which a per-step network cannot see in one state unless the observation carries it
(normalised on its own, the small per-step change is no longer drowned by the positions' spread). On Meta-World's
test trajectories with the train phrasings it raised the accuracy on speed from 0.79 to 0.95 (docs/results.md).
With `delta_magnitudes` each step also carries the size of that change, |s_t - s_{t-1}| per dimension: a speed is
the time mean of a magnitude, while the time mean of the signed changes is the net displacement over the episode's
length, which says little about how fast the hand moved; a per-step MLP can learn the magnitude, but a small
recording gives it few steps to (examples/reach/diagnose.py, docs/pending/results-trajectory.md).
The last layer is linear, so the mean is taken before it: mean_t(W h_t + c) = W mean_t(h_t) + c, the same phi for
a D/128-th of the work.

Language encoder: a pretrained Hugging Face encoder, the mean of its last hidden states under the attention mask
(padding never enters the mean), and a linear head into D.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from langpref.language.transformer import SentenceEncoder


class TrajectoryEncoder(nn.Module):
    """phi(tau) = mean over steps of an MLP of the normalised (s_t, a_t). (Models that see camera frames use
    `langpref.model.vision.ImageTrajectoryEncoder`.)"""

    observations = "state"

    def __init__(
        self,
        in_dim: int,
        hidden: Sequence[int],
        latent_dim: int,
        mean: np.ndarray | None = None,
        std: np.ndarray | None = None,
        observation_deltas: bool = False,
        delta_magnitudes: bool = False,
    ):
        super().__init__()
        self.observation_deltas = observation_deltas
        self.delta_magnitudes = delta_magnitudes
        layers: list[nn.Module] = []
        width = in_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(width, latent_dim)
        self.register_buffer("mean", torch.zeros(in_dim) if mean is None else torch.as_tensor(mean).float())
        self.register_buffer("std", torch.ones(in_dim) if std is None else torch.as_tensor(std).float())

    def forward(self, steps: torch.Tensor, lengths: torch.Tensor | None = None) -> torch.Tensor:
        """steps (N, T, in_dim) from `step_inputs`, raw -> phi (N, D). With `lengths` (N,), trajectory i has only
        its first lengths[i] steps (the rest is padding) and phi is the mean over those: episodes of different
        lengths (the paper's footnote 1) embed as the time mean of their own steps."""
        return self.out(time_mean(self.body((steps - self.mean) / self.std), lengths))


def time_mean(h: torch.Tensor, lengths: torch.Tensor | None) -> torch.Tensor:
    """(N, T, H) -> (N, H): the mean over each trajectory's first lengths[i] steps (all T when None)."""
    if lengths is None:
        return h.mean(dim=1)
    mask = (torch.arange(h.shape[1], device=h.device)[None, :] < lengths[:, None]).to(h.dtype)
    return (h * mask[..., None]).sum(dim=1) / lengths[:, None].to(h.dtype)


def step_inputs(
    obs: np.ndarray, actions: np.ndarray, observation_deltas: bool, delta_magnitudes: bool = False
) -> np.ndarray:
    """Per-step encoder inputs (N, T, in_dim) (or (T, in_dim) of one trajectory), float32: observation, [its change
    since the previous step (zero at t = 0)], [the change's absolute value], action. Built on whole trajectories,
    before any subsampling of time steps."""
    parts = [obs]
    if observation_deltas or delta_magnitudes:
        delta = np.diff(obs, axis=-2, prepend=obs[..., :1, :])
        parts += [delta] * observation_deltas + [np.abs(delta)] * delta_magnitudes
    parts.append(actions)
    return np.concatenate(parts, axis=-1).astype(np.float32)


def step_input_dim(obs_dim: int, action_dim: int, observation_deltas: bool, delta_magnitudes: bool = False) -> int:
    return obs_dim * (1 + int(observation_deltas) + int(delta_magnitudes)) + action_dim


def normalisation_stats(steps: np.ndarray, lengths: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-dimension mean and std of the encoder inputs over every step of the given (train) trajectories (only
    the first `lengths[i]` steps of trajectory i when given: padding does not count).

    A dimension that never changes (std below 1e-6) gets std 1, so it normalises to zero instead of blowing up.
    """
    if lengths is not None:
        flat = np.concatenate([s[:n] for s, n in zip(steps, lengths)]).astype(np.float64)
    else:
        flat = steps.reshape(-1, steps.shape[-1]).astype(np.float64)
    mean, std = flat.mean(axis=0), flat.std(axis=0)
    std = np.where(std < 1e-6, 1.0, std)
    return mean.astype(np.float32), std.astype(np.float32)


class LanguageEncoder(SentenceEncoder):
    """psi(l) = head(mean of the transformer's last hidden states over the non-padding tokens)."""

    def __init__(self, tokenizer, transformer: nn.Module, latent_dim: int, max_length: int = 32):
        super().__init__(tokenizer, transformer, max_length)
        self.head = nn.Linear(self.hidden_size, latent_dim)

    @property
    def device(self) -> torch.device:
        return next(self.head.parameters()).device

    def forward(self, texts: Sequence[str]) -> torch.Tensor:
        """psi (P, D) of raw texts."""
        return self.head(self.pooled_texts(texts))


def freeze(module: nn.Module, frozen: bool = True) -> None:
    for p in module.parameters():
        p.requires_grad_(not frozen)


def transformer_state_fingerprint(module: nn.Module) -> float:
    """A cheap checksum of a module's weights (tests use it to check the frozen stage leaves them alone)."""
    with torch.no_grad():
        return float(sum(p.double().sum().item() for p in module.parameters()))
