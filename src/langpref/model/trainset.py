"""What a training run learns from: the phrasings (the bank's, or a user's file) and each split of the dataset on
the device, with its pairs (and, with `windows`, the epoch's windows of the train episodes)."""

from __future__ import annotations

import numpy as np
import torch

from langpref.errors import LangprefError
from langpref.language.pairs import (
    Pairs,
    Phrasings,
    build_pairs,
    merge_phrasings,
    phrasings_from_bank,
    phrasings_from_mapping,
)
from langpref.model.config import ModelConfig, TrainConfig
from langpref.model.inputs import dataset_input
from langpref.model.windows import Segments, sample_windows, whole_episodes


def load_phrasings(cfg: TrainConfig, env: str, feature_names: list[str]) -> tuple[Phrasings, Phrasings]:
    """(train, val) phrasings: the bank's splits, with `cfg.utterances` replacing or extending the train split."""
    from langpref.language.bank import load_bank, load_user_utterances

    bank = load_bank(env)
    val = phrasings_from_bank(bank, "val", feature_names)
    if cfg.utterances:
        user = phrasings_from_mapping(
            load_user_utterances(cfg.utterances, env),
            feature_names,
            require_all=not cfg.extend_bank,
            source=str(cfg.utterances),
        )
        train = merge_phrasings(phrasings_from_bank(bank, "train", feature_names), user) if cfg.extend_bank else user
    else:
        train = phrasings_from_bank(bank, "train", feature_names)
    return train, val


class TrainSplit:
    """One split on the device: raw encoder inputs (N, T, in_dim, see `langpref.model.inputs`), for a model that
    sees images its frames (N, K, h, w, 3) uint8 and the frame of each step, features, pairs."""

    def __init__(self, dataset, name: str, thresholds: np.ndarray, device: torch.device, model_cfg: ModelConfig):
        idx = dataset.split(name)
        if len(idx) < 2:
            raise LangprefError(
                f"split {name!r} of {dataset.root} has {len(idx)} trajectories; training needs at "
                "least 2 in train and val"
            )
        inp = dataset_input(
            dataset, name, model_cfg.observations, model_cfg.observation_deltas, model_cfg.delta_magnitudes
        )
        self.steps = torch.from_numpy(inp.steps).to(device)
        self.lengths = inp.lengths  # None: every trajectory has `horizon` steps
        self.frames = None if inp.frames is None else torch.from_numpy(inp.frames).to(device)
        self.frame_index = None if inp.frame_index is None else torch.from_numpy(inp.frame_index).to(device)
        self.features = dataset.features[idx]
        self.thresholds = thresholds
        self.pairs: Pairs = build_pairs(self.features, thresholds)
        if len(self.pairs) == 0:
            raise LangprefError(f"split {name!r} has no pair of trajectories whose features differ")
        # with windows (train split only): what this epoch trains on, the pairs' indices being rows of it
        self.segments: Segments | None = None
        self.step_features: list[np.ndarray] | None = None
        self.episodes: Segments | None = None

    def add_windows(self, dataset, name: str) -> None:
        """Keep the per-step features of this split's episodes, which windows are cut from."""
        idx = dataset.split(name)
        self.step_features = [dataset.load(i).step_features for i in idx]
        self.episodes = whole_episodes([len(s) for s in self.step_features], self.features)

    def resample_windows(self, per_episode: int, min_fraction: float, rng: np.random.Generator) -> None:
        """This epoch's segments (every whole episode, then `per_episode` fresh windows of each) and their pairs."""
        if self.step_features is None or self.episodes is None:
            raise LangprefError("windows were asked for on a split without per-step features")
        self.segments = self.episodes + sample_windows(self.step_features, per_episode, min_fraction, rng)
        self.pairs = build_pairs(self.segments.features, self.thresholds)

    @property
    def num_items(self) -> int:
        """Trajectories the pairs index: episodes, or episodes and windows."""
        return len(self.features) if self.segments is None else len(self.segments)

    def episode_rows(self, items: np.ndarray) -> np.ndarray:
        """The episodes (rows of this split) that items of the pairs come from."""
        return items if self.segments is None else np.unique(self.segments.row[items])

    def frame_args(self, rows: torch.Tensor | None = None, t: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """The encoder's frame arguments for trajectories `rows` (all when None), at time steps `t` (n, k) when
        given: then only the frames those steps are shown, so the CNN sees no frame it does not need. Empty for a
        model that sees no images."""
        if self.frames is None or self.frame_index is None:
            return {}
        if rows is None:
            return {"frames": self.frames, "frame_index": self.frame_index}
        if t is None:
            return {"frames": self.frames[rows], "frame_index": self.frame_index[rows]}
        shown = self.frame_index[rows.unsqueeze(1), t]
        order = torch.arange(t.shape[1], device=t.device).expand_as(t)
        return {"frames": self.frames[rows.unsqueeze(1), shown], "frame_index": order}
