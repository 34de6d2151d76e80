"""phi of new trajectories, the trajectory side of a latent space beside its text encoder (`LatentSpace.phi_of`):

    encode = model_trajectory_encoder(model)          # a trained model's trajectory encoder
    encode = oracle_trajectory_encoder(features, phi)  # the perfect space's: phi = (normalised features, offset)
    phi = encode([traj])                               # (1, D) of rollouts in memory (`Trajectory` objects)

A space carries one so that whoever makes new trajectories (`langpref.propose`) embeds them as the space embeds the
dataset, from the space alone, without opening the dataset or the model again. Each encoder is a closure over what it
needs, never over the space: a proposer holding it reaches no synthetic human's view (the space's theta).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError

TrajectoryEncoder = Callable[[Sequence[Any]], np.ndarray]
"""`Trajectory` objects (new rollouts) -> their phi (n, D)."""


@dataclass(frozen=True)
class AffineScale:
    """theta_f = a_f feature_f + b_f per feature, fitted exactly on a dataset: how a space turned the dataset's
    features into its theta (standardised, or the paper's sum over steps), applied to a new rollout's features."""

    a: np.ndarray
    b: np.ndarray

    @classmethod
    def fit(cls, features: np.ndarray, target: np.ndarray) -> AffineScale:
        a, b = np.ones(features.shape[1]), np.zeros(features.shape[1])
        for f in range(features.shape[1]):
            a[f], b[f] = np.polyfit(features[:, f], target[:, f], 1)
        if not np.allclose(features * a + b, target, rtol=1e-6, atol=1e-6 * (1 + np.abs(target).max())):
            raise LangprefError(
                "the space's theta is not a per-feature affine map of the dataset's features (one "
                "horizon); generated trajectories cannot be scored on its scale"
            )
        return cls(a, b)

    def __call__(self, features: np.ndarray) -> np.ndarray:
        return np.asarray(features, dtype=np.float64) * self.a + self.b


def model_trajectory_encoder(model) -> TrajectoryEncoder:
    """phi of rollouts from a trained `LatentModel`'s trajectory encoder (as `encode_dataset` embeds the dataset; a
    model that sees images renders the rollouts' frames from their simulator states, in the process's live env of
    the task (`langpref.tasks.live_env`), not a new one per rollout)."""

    def encode(trajs: Sequence[Any]) -> np.ndarray:
        from langpref.tasks import live_env

        trajs = list(trajs)
        env = live_env(model.info.env, max(t.horizon for t in trajs)) if model.sees_images else None
        phi = model.encode_rollouts(trajs, env=env)
        return phi.detach().cpu().numpy().astype(np.float64)

    return encode


def oracle_trajectory_encoder(features: np.ndarray, phi: np.ndarray) -> TrajectoryEncoder:
    """phi of rollouts in the perfect latent space (ORACLE: phi = (normalised features, offset), for the oracle upper
    bound only): the per-feature affine map from the dataset's `features` to the first columns of its `phi`, fitted
    on first use (so a space that never embeds a new trajectory never fits it), and phi's constant last column."""
    fitted: list[AffineScale] = []

    def encode(trajs: Sequence[Any]) -> np.ndarray:
        if not fitted:
            fitted.append(AffineScale.fit(np.asarray(features, dtype=np.float64), phi[:, :-1]))
        offset = float(phi[0, -1])
        return np.stack([np.append(fitted[0](t.features), offset) for t in trajs])

    return encode
