"""`LatentModel`: both encoders and the facts of the data they were trained on; what downstream code uses.

model = load_model("runs/mw")                   # langpref.model.checkpoint
phi = model.encode_dataset(dataset, "test")     # (N, D) trajectory embeddings
psi = model.encode_texts(["Move faster."])       # (1, D) language embeddings
model.check_dataset(dataset)                    # LangprefError if env or observation layout differ
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from langpref.errors import LangprefError
from langpref.language.pairs import DIRECTIONS
from langpref.model.encoders import LanguageEncoder, TrajectoryEncoder, step_inputs


@dataclass
class DataInfo:
    """What a model was trained on; a dataset used with it must match env, observation layout and action size."""

    env: str
    feature_names: list[str]
    obs_layout: list[dict[str, Any]]
    obs_dim: int
    action_dim: int
    horizon: int
    schema_version: int
    tie_thresholds: list[float]
    """Absolute per-feature tie thresholds (tie_fraction * train std): evaluation uses the same ones."""
    feature_std: list[float] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class LatentModel(nn.Module):
    """Trajectory encoder + language encoder + the data facts; `prototypes` are the mean psi of each meaning."""

    def __init__(self, traj: TrajectoryEncoder, lang: LanguageEncoder, info: DataInfo, lang_model_name: str):
        super().__init__()
        self.traj = traj
        self.lang = lang
        self.info = info
        self.lang_model_name = lang_model_name
        num_groups = 2 * len(info.feature_names)
        self.register_buffer("prototypes", torch.zeros(num_groups, traj.out.out_features))

    @property
    def device(self) -> torch.device:
        return self.traj.out.weight.device

    @property
    def feature_names(self) -> list[str]:
        return list(self.info.feature_names)

    @property
    def meanings(self) -> list[tuple[str, str]]:
        """(feature, direction) of each prototype row, group g = 2 * feature + direction."""
        return [(f, d) for f in self.info.feature_names for d in DIRECTIONS]

    def check_dataset(self, dataset) -> None:
        """Fail with one line when `dataset` is not the kind of data this model was trained on."""
        meta = dataset.meta
        where = f"dataset {dataset.root}"
        if meta.env != self.info.env:
            raise LangprefError(
                f"the model was trained on {self.info.env} data but {where} is {meta.env}; "
                f"use a {self.info.env} dataset or a model trained on {meta.env}"
            )
        if list(meta.feature_names) != list(self.info.feature_names):
            raise LangprefError(
                f"{where} has features {list(meta.feature_names)}, the model was trained on {self.info.feature_names}"
            )
        if [dict(x) for x in meta.obs_layout] != [
            dict(x) for x in self.info.obs_layout
        ] or meta.action_dim != self.info.action_dim:
            raise LangprefError(
                f"{where} has a different observation layout or action size (obs {meta.obs_dim}, "
                f"action {meta.action_dim}) than the model was trained on (obs {self.info.obs_dim}, "
                f"action {self.info.action_dim}); regenerate the data or retrain the model"
            )

    @torch.no_grad()
    def encode_trajectories(
        self, obs: np.ndarray, actions: np.ndarray, batch_size: int = 64, lengths: np.ndarray | None = None
    ) -> torch.Tensor:
        """phi (N, D) of raw observations (N, T, obs_dim) and actions (N, T, A); with `lengths`, trajectory i has
        lengths[i] real steps and padding after them (`Dataset.arrays`)."""
        if obs.shape[-1] != self.info.obs_dim or actions.shape[-1] != self.info.action_dim:
            raise LangprefError(
                f"trajectories have obs {obs.shape[-1]} / action {actions.shape[-1]} dims, the model "
                f"expects {self.info.obs_dim} / {self.info.action_dim}"
            )
        was_training = self.training
        self.eval()
        steps = step_inputs(obs, actions, self.traj.observation_deltas)
        lens = None if lengths is None else torch.as_tensor(lengths, device=self.device)
        out = [
            self.traj(
                torch.from_numpy(steps[i : i + batch_size]).to(self.device),
                None if lens is None else lens[i : i + batch_size],
            )
            for i in range(0, len(steps), batch_size)
        ]
        self.train(was_training)
        return torch.cat(out) if out else torch.zeros(0, self.prototypes.shape[1], device=self.device)

    def encode_dataset(self, dataset, split: str | None = None) -> torch.Tensor:
        """phi of the trajectories of one split (all of them when `split` is None), in dataset order."""
        self.check_dataset(dataset)
        obs, act = dataset.arrays(split)
        return self.encode_trajectories(obs, act, lengths=dataset.lengths(split))

    @torch.no_grad()
    def encode_texts(self, texts: Sequence[str]) -> torch.Tensor:
        """psi (P, D) of utterances."""
        was_training = self.training
        self.eval()
        psi = self.lang(list(texts))
        self.train(was_training)
        return psi

    @torch.no_grad()
    def set_prototypes(self, phrasings) -> None:
        """Mean psi of each (feature, direction) group of a `Phrasings` table (the training phrasings)."""
        psi = self.encode_texts(phrasings.texts)
        for g, ids in enumerate(phrasings.group_ids):
            if len(ids):
                self.prototypes[g] = psi[torch.as_tensor(ids, device=self.device)].mean(dim=0)
