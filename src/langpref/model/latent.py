"""`LatentModel`: both encoders and the facts of the data they were trained on; what downstream code uses.

model = load_model("runs/mw")                   # langpref.model.checkpoint
phi = model.encode_dataset(dataset, "test")     # (N, D) trajectory embeddings
phi = model.encode_rollouts([traj])             # (1, D) of trajectories in memory (new rollouts)
psi = model.encode_texts(["Move faster."])       # (1, D) language embeddings
psi = model.encode_texts(["Don't go so fast."])  # with model.negation on: -psi("Go so fast.")
model.check_dataset(dataset)                    # LangprefError if env or observation layout differ

A model that sees camera frames (`model.sees_images`) embeds a dataset's stored frames, and renders those of new
simulated rollouts; every path goes through `encode_input` (see `langpref.model.inputs`).

With `model.negation` on (`ModelConfig.negation`, saved in the checkpoint, overridable when loading), a text that
`langpref.language.negation.detect` finds to be a scoped negation of a request is read as the opposite of the request
without its cue: the two directions of a feature lie opposite each other in this space.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from langpref.errors import LangprefError
from langpref.language.bank import DIRECTIONS
from langpref.language.negation import detect_all
from langpref.model.encoders import LanguageEncoder, TrajectoryEncoder
from langpref.model.inputs import EncoderInput, dataset_input, sees_images, trajectories_input
from langpref.model.vision import ImageTrajectoryEncoder


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
    frames: dict[str, Any] | None = None
    """The dataset's camera frames (width, height, stride, source) for a model that sees images; else None."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class LatentModel(nn.Module):
    """Trajectory encoder + language encoder + the data facts; `prototypes` are the mean psi of each meaning;
    `negation`: read a negated request as the opposite of the request (module docstring)."""

    def __init__(
        self,
        traj: TrajectoryEncoder | ImageTrajectoryEncoder,
        lang: LanguageEncoder,
        info: DataInfo,
        lang_model_name: str,
        negation: bool = False,
    ):
        super().__init__()
        self.traj = traj
        self.lang = lang
        self.info = info
        self.lang_model_name = lang_model_name
        self.negation = negation
        num_groups = 2 * len(info.feature_names)
        self.register_buffer("prototypes", torch.zeros(num_groups, traj.out.out_features))

    @property
    def device(self) -> torch.device:
        return self.traj.out.weight.device

    @property
    def feature_names(self) -> list[str]:
        return list(self.info.feature_names)

    @property
    def observations(self) -> str:
        """What the trajectory encoder sees: state, images or images+state."""
        return self.traj.observations

    @property
    def sees_images(self) -> bool:
        return sees_images(self.observations)

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
        same_layout = [dict(x) for x in meta.obs_layout] == [dict(x) for x in self.info.obs_layout]
        if not same_layout or meta.action_dim != self.info.action_dim:
            raise LangprefError(
                f"{where} has a different observation layout or action size (obs {meta.obs_dim}, "
                f"action {meta.action_dim}) than the model was trained on (obs {self.info.obs_dim}, "
                f"action {self.info.action_dim}); regenerate the data or retrain the model"
            )
        if self.sees_images:
            self._check_frames(dataset)

    def _check_frames(self, dataset) -> None:
        spec, want = dataset.frame_spec, self.info.frames or {}
        if spec is None:
            raise LangprefError(
                f"the model sees camera frames (observations {self.observations}) and dataset {dataset.root} has "
                "none; use a dataset made with `langpref generate --images` (or `import --images`) or a state model"
            )
        if (spec.width, spec.height) != (want.get("width"), want.get("height")):
            raise LangprefError(
                f"dataset {dataset.root} has {spec.width}x{spec.height} frames, the model was trained on "
                f"{want.get('width')}x{want.get('height')}; regenerate the data with --frame-size "
                f"{want.get('width')},{want.get('height')} or retrain the model"
            )

    @torch.no_grad()
    def encode_input(self, inp: EncoderInput, batch_size: int = 64) -> torch.Tensor:
        """phi (N, D) of trajectories made into encoder input (`langpref.model.inputs`), `batch_size` at a time."""
        was_training = self.training
        self.eval()
        out = [self._encode_rows(inp.rows(i, i + batch_size)) for i in range(0, len(inp), batch_size)]
        self.train(was_training)
        return torch.cat(out) if out else torch.zeros(0, self.prototypes.shape[1], device=self.device)

    def _encode_rows(self, inp: EncoderInput) -> torch.Tensor:
        lens = None if inp.lengths is None else torch.as_tensor(inp.lengths, device=self.device)
        steps = torch.from_numpy(inp.steps).to(self.device)
        if inp.frames is None:
            return self.traj(steps, lens)
        return self.traj(
            steps,
            lens,
            frames=torch.from_numpy(inp.frames).to(self.device),
            frame_index=torch.from_numpy(inp.frame_index).to(self.device),
        )

    def encode_trajectories(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        batch_size: int = 64,
        lengths: np.ndarray | None = None,
        frames: np.ndarray | list[np.ndarray] | None = None,
    ) -> torch.Tensor:
        """phi (N, D) of raw observations (N, T, obs_dim) and actions (N, T, A); with `lengths`, trajectory i has
        lengths[i] real steps and padding after them (`Dataset.arrays`). A model that sees images also needs the
        trajectories' `frames` (N, K, h, w, 3), one every `info.frames["stride"]` steps."""
        if obs.shape[-1] != self.info.obs_dim or actions.shape[-1] != self.info.action_dim:
            raise LangprefError(
                f"trajectories have obs {obs.shape[-1]} / action {actions.shape[-1]} dims, the model "
                f"expects {self.info.obs_dim} / {self.info.action_dim}"
            )
        want = self.info.frames or {}
        stride = want.get("stride")
        if frames is not None and self.sees_images:
            shape = tuple(frames[0].shape[-3:-1]) if len(frames) else ()
            if shape != (want.get("height"), want.get("width")):
                raise LangprefError(
                    f"frames of height x width {shape} given, the model was trained on "
                    f"{want.get('height')} x {want.get('width')}"
                )
        inp = trajectories_input(
            obs,
            actions,
            self.observations,
            self.traj.observation_deltas,
            lengths,
            frames,
            frame_stride=stride,
            delta_magnitudes=self.traj.delta_magnitudes,
        )
        return self.encode_input(inp, batch_size)

    def encode_dataset(self, dataset, split: str | None = None) -> torch.Tensor:
        """phi of the trajectories of one split (all of them when `split` is None), in dataset order."""
        self.check_dataset(dataset)
        traj = self.traj
        return self.encode_input(
            dataset_input(dataset, split, self.observations, traj.observation_deltas, traj.delta_magnitudes)
        )

    def encode_rollouts(self, trajs: Sequence[Any], env: Any = None) -> torch.Tensor:
        """phi (N, D) of `Trajectory` objects in memory (new rollouts, as `langpref improve` makes). A model that
        sees images renders their frames from their simulator states, as `generate --images` does, in `env` (a live
        env of the task, kept by the caller) or in one made and closed here."""
        from langpref.dataset.storage import stack_steps

        obs, act = stack_steps([t.observations for t in trajs]), stack_steps([t.actions for t in trajs])
        lens = np.array([t.horizon for t in trajs])
        lengths = None if (lens == obs.shape[1]).all() else lens
        if not self.sees_images:
            return self.encode_trajectories(obs, act, lengths=lengths)
        return self.encode_trajectories(obs, act, lengths=lengths, frames=self._render(trajs, env))

    def _render(self, trajs: Sequence[Any], env: Any) -> list[np.ndarray]:
        from langpref.dataset.frames import FrameSpec, render_trajectory_frames
        from langpref.tasks import make_env

        spec = FrameSpec.from_dict(self.info.frames or {}, "the model's config.json")
        if spec.source != "render":
            raise LangprefError(
                f"the model saw frames decoded from a recording ({self.info.env}); new trajectories need their "
                "own frames: pass them to encode_trajectories(..., frames=...)"
            )
        own = env is None
        env = make_env(self.info.env, max(t.horizon for t in trajs)) if own else env
        try:
            return [render_trajectory_frames(env, t, spec) for t in trajs]
        finally:
            if own:
                env.close()

    @torch.no_grad()
    def encode_texts(self, texts: Sequence[str]) -> torch.Tensor:
        """psi (P, D) of utterances; with `negation` on, psi = -psi(request without its cue) for each text that
        `langpref.language.negation.detect` flags (one batch through the encoder either way)."""
        if not self.negation:
            return self._read(texts)
        found = detect_all(texts)
        psi = self._read([n.text if n.flip else t for n, t in zip(found, texts)])
        sign = torch.tensor([-1.0 if n.flip else 1.0 for n in found], device=psi.device, dtype=psi.dtype)
        return psi * sign.unsqueeze(1)

    def _read(self, texts: Sequence[str]) -> torch.Tensor:
        """psi (P, D) of texts as the language encoder reads them, nothing flipped."""
        was_training = self.training
        self.eval()
        psi = self.lang(list(texts))
        self.train(was_training)
        return psi

    @torch.no_grad()
    def set_prototypes(self, phrasings) -> None:
        """Mean psi of each (feature, direction) group of a `Phrasings` table (the training phrasings), as the
        encoder reads them, never flipped: the prototypes are what training made of the bank, and stay the same
        whichever `negation` setting later reads with them."""
        psi = self._read(phrasings.texts)
        for g, ids in enumerate(phrasings.group_ids):
            if len(ids):
                self.prototypes[g] = psi[torch.as_tensor(ids, device=self.device)].mean(dim=0)
