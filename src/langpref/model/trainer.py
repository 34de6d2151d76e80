"""The `Trainer`: the paper's two training stages of the latent space (see `langpref.model.train` for what each
stage learns and what it costs), the frames-alone pretraining of an image model before them, and the pieces both
stages share (phi of a batch, validation, the epoch loop with early stopping)."""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.language.pairs import Pairs, Phrasings, sample_phrasings, sample_subset, tie_thresholds
from langpref.model.checkpoint import build_model
from langpref.model.config import TrainConfig
from langpref.model.encoders import freeze, normalisation_stats
from langpref.model.evaluate import alignment_counts
from langpref.model.inputs import resolve_observations, sees_images
from langpref.model.keep import Anchor, augmented, resolve_augment, resolve_corpus, trainable_lm_params, with_corpus
from langpref.model.latent import DataInfo, LatentModel
from langpref.model.loss import episode_contrastive_loss, latent_loss
from langpref.model.trainset import TrainSplit, load_phrasings
from langpref.model.windows import segment_steps


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise LangprefError("--device cuda was asked for but no CUDA device is available; use --device cpu or auto")
    return torch.device(name)


def _own_params(model: LatentModel) -> list[torch.nn.Parameter]:
    return list(model.traj.parameters()) + list(model.lang.head.parameters())


def _snapshot(model: LatentModel, with_transformer: bool) -> dict[str, torch.Tensor]:
    return {
        k: v.detach().clone()
        for k, v in model.state_dict().items()
        if with_transformer or not k.startswith("lang.transformer.")
    }


class Trainer:
    def __init__(
        self,
        cfg: TrainConfig,
        train_phr: Phrasings | None = None,
        val_phr: Phrasings | None = None,
        progress: bool = True,
    ):
        cfg.validate()
        self.cfg = cfg = cfg.resolved()  # `--lang-model auto` -> the language model of this dataset's task
        self.progress = progress
        self.device = resolve_device(cfg.device)
        self.mixed_precision = cfg.mixed_precision and self.device.type == "cuda"  # bf16: no loss scaling needed
        self.dataset = load_dataset(cfg.data)
        meta = self.dataset.meta
        cfg = self._phrasings(cfg, train_phr, val_phr)
        self.rng = np.random.default_rng(cfg.seed)
        torch.manual_seed(cfg.seed)
        # what the encoder sees, resolved against the dataset; the checkpoint records it
        observations = resolve_observations(cfg.model.observations, meta.frames is not None, str(self.dataset.root))
        self.cfg = cfg = replace(cfg, model=replace(cfg.model, observations=observations)).frames_resolved()

        train_idx = self.dataset.split("train")
        thresholds = tie_thresholds(self.dataset.features[train_idx], cfg.tie_fraction)
        self.train = TrainSplit(self.dataset, "train", thresholds, self.device, cfg.model)
        self.val = TrainSplit(self.dataset, "val", thresholds, self.device, cfg.model)
        if cfg.windows:
            self.train.add_windows(self.dataset, "train")  # never val or test: those are seen whole only
        self.model = self._build_model(thresholds, observations)
        # `frame_contrastive`'s projection of the CNN features; a training aid, not part of the saved model
        self.frame_head: torch.nn.Module | None = None
        if cfg.frame_contrastive or cfg.frame_pretrain_steps:
            width = cfg.model.frame_features
            self.frame_head = torch.nn.Sequential(
                torch.nn.Linear(width, width), torch.nn.ReLU(), torch.nn.Linear(width, 32)
            ).to(self.device)
        self.model.to(self.device)
        self.history: list[dict[str, Any]] = []
        self.samples_seen = {1: 0, 2: 0}
        self.seconds = {0: 0.0, 1: 0.0, 2: 0.0}

    def _phrasings(self, cfg: TrainConfig, train_phr: Phrasings | None, val_phr: Phrasings | None) -> TrainConfig:
        """Set what training reads (the bank's phrasings, with `augment_phrasings` template proposals, with
        `corpus_phrasings` the corpus's sentences of tied concepts) and what the saved prototypes are made of (the
        bank's own train phrasings); the config with both resolved."""
        meta = self.dataset.meta
        names = list(meta.feature_names)
        if train_phr is None or val_phr is None:
            bank_train, bank_val = load_phrasings(cfg, meta.env, names)
            train_phr, val_phr = train_phr or bank_train, val_phr or bank_val
        for p in (train_phr, val_phr):
            if list(p.feature_names) != names:
                raise LangprefError(f"phrasings cover {list(p.feature_names)}, the dataset has features {names}")
        self.bank_train_phr = train_phr
        cfg = replace(
            cfg,
            augment_phrasings=resolve_augment(cfg.augment_phrasings, train_phr),
            corpus_phrasings=resolve_corpus(cfg.corpus_phrasings, meta.env),
        )
        train_aug = augmented(train_phr, val_phr, cfg.augment_phrasings)
        self.train_phr = with_corpus(train_aug, val_phr, cfg.corpus_phrasings, meta.env)
        self.val_phr = val_phr
        return cfg

    def _build_model(self, thresholds: np.ndarray, observations: str) -> LatentModel:
        """A fresh model for this dataset: input normalisation from the train split, fresh layers from the seed."""
        cfg, meta = self.cfg, self.dataset.meta
        train_idx = self.dataset.split("train")
        mean, std = normalisation_stats(self.train.steps.cpu().numpy(), self.train.lengths)
        info = DataInfo(
            env=meta.env,
            feature_names=list(meta.feature_names),
            obs_layout=[dict(x) for x in meta.obs_layout],
            obs_dim=meta.obs_dim,
            action_dim=meta.action_dim,
            horizon=meta.horizon,
            schema_version=meta.schema_version,
            tie_thresholds=thresholds.tolist(),
            feature_std=self.dataset.features[train_idx].std(axis=0).tolist(),
            frames=meta.frames if sees_images(observations) else None,
        )
        model = build_model(cfg.model, info, mean, std)
        torch.manual_seed(cfg.seed)  # whatever loading the transformer drew, the fresh layers start the same
        for m in [*model.traj.modules(), model.lang.head]:
            if isinstance(m, (torch.nn.Linear, torch.nn.Conv2d)):
                m.reset_parameters()
        return model

    # ---- pieces shared by both stages ------------------------------------------------------------------------------

    @property
    def time_samples(self) -> int:
        """Time steps per trajectory in a training step: fewer for a model that sees images (its CNN dominates)."""
        cfg = self.cfg
        return cfg.image_time_samples if sees_images(cfg.model.observations or "state") else cfg.time_samples

    def _time_index(self, n: int, horizon: int, lengths: np.ndarray | None = None) -> torch.Tensor | None:
        """Stratified time steps for a training step: one random step in each of `time_samples` equal segments of
        the horizon (of each trajectory's own length when they differ), drawn afresh per trajectory (None: every
        step). The mean of the per-step embeddings over them is an unbiased estimate of the mean over all steps, at
        a fraction of the cost; evaluation always uses all."""
        k = self.time_samples
        if k <= 0 or (k >= horizon and lengths is None):
            return None
        if lengths is None:
            edges = np.linspace(0, horizon, k + 1)
            lo, width = edges[:-1], np.diff(edges)
            t = np.floor(lo + self.rng.random((n, k)) * width).astype(np.int64)
            return torch.as_tensor(np.minimum(t, horizon - 1), device=self.device)
        frac = (np.arange(k) + self.rng.random((n, k))) / k  # stratified in [0, 1), scaled to each length
        t = np.floor(frac * lengths[:, None]).astype(np.int64)
        return torch.as_tensor(np.minimum(t, lengths[:, None] - 1), device=self.device)

    def _resample_windows(self) -> None:
        """A new epoch's windows of the train episodes (nothing without `windows`)."""
        if self.cfg.windows:
            self.train.resample_windows(self.cfg.windows, self.cfg.window_min_fraction, self.rng)

    def _phi_segments(self, split: TrainSplit, items: np.ndarray) -> torch.Tensor:
        """phi of segments `items` (whole episodes and windows): the sampled steps of each, or all of its steps."""
        assert split.segments is not None
        t = self._time_index(len(items), split.steps.shape[1], split.segments.length[items])
        rows, steps, lens = segment_steps(split.segments, items, None if t is None else t.cpu().numpy())
        r = torch.as_tensor(rows, device=self.device)
        t_all = torch.as_tensor(steps, device=self.device)
        lens_t = None if lens is None else torch.as_tensor(lens, device=self.device)
        return self.model.traj(split.steps[r.unsqueeze(1), t_all], lens_t, **split.frame_args(r, t_all))

    def _phi(self, split: TrainSplit, a: np.ndarray, b: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """phi_A, phi_B of a batch, computing phi once per distinct trajectory (or segment, with windows)."""
        both = np.concatenate([a, b])
        uniq, inv = np.unique(both, return_inverse=True)
        if split.segments is not None:
            phi = self._phi_segments(split, uniq)
        else:
            rows = torch.as_tensor(uniq, device=self.device)
            lengths = None if split.lengths is None else split.lengths[uniq]
            t = self._time_index(len(uniq), split.steps.shape[1], lengths)
            if t is None:
                lens = None if lengths is None else torch.as_tensor(lengths, device=self.device)
                phi = self.model.traj(split.steps[rows], lens, **split.frame_args(rows))
            else:
                phi = self.model.traj(split.steps[rows.unsqueeze(1), t], **split.frame_args(rows, t))
        inv_t = torch.as_tensor(inv, device=self.device)
        return phi[inv_t[: len(a)]], phi[inv_t[len(a) :]]

    @torch.no_grad()
    def _val_accuracy(self, pooled_val: torch.Tensor) -> float:
        lens = None if self.val.lengths is None else torch.as_tensor(self.val.lengths, device=self.device)
        self.model.traj.eval()  # no training-time augmentation of frames
        phi = self.model.traj(self.val.steps, lens, **self.val.frame_args()).double().cpu()
        self.model.traj.train()
        psi = self.model.lang.head(pooled_val).double().cpu()
        correct, total = alignment_counts(
            phi, psi, self.val.pairs, self.val_phr.group_ids, len(self.val_phr.feature_names)
        )
        return float(correct.sum() / max(total.sum(), 1))

    def step_trajectories(self, batch_size: int) -> int:
        """Distinct train trajectories a step draws its pairs among (`image_step_trajectories`): all for a state
        model; for an image model, by default the fewest that hold twice the batch's pairs on average."""
        n, chosen = self.train.num_items, self.cfg.image_step_trajectories
        if not sees_images(self.cfg.model.observations or "state") or chosen == 0:
            return n
        if chosen is None:  # a random m of n trajectories hold about (m / n)^2 of the pairs
            chosen = math.ceil(n * math.sqrt(2 * batch_size / max(len(self.train.pairs), 1)))
        return min(n, max(chosen, 2))

    def _epoch_batches(self, batch_size: int, steps: int):
        """The pair rows of each step of an epoch: a permutation of all pairs cut into batches or, when a step
        draws among fewer trajectories than there are, up to `batch_size` pairs among a fresh random subset."""
        pairs, n = self.train.pairs, self.train.num_items
        m = self.step_trajectories(batch_size)
        if m >= n:
            order = self.rng.permutation(len(pairs))
            yield from (order[i : i + batch_size] for i in range(0, len(order), batch_size))
            return
        chosen = np.zeros(n, dtype=bool)
        for _ in range(steps):
            chosen[:] = False
            chosen[self.rng.choice(n, m, replace=False)] = True
            candidates = np.flatnonzero(chosen[pairs.a] & chosen[pairs.b])
            if len(candidates):
                yield self.rng.choice(candidates, min(batch_size, len(candidates)), replace=False)

    def _bar(self, stage: int, total: int):
        from tqdm import tqdm

        return tqdm(
            total=total,
            desc=f"stage {stage} ({['frames alone', 'frozen LM', 'co-finetune'][stage]})",
            unit="step",
            file=sys.stderr,
            disable=not self.progress,
            dynamic_ncols=True,
            leave=True,
        )

    def _run_stage(
        self,
        stage: int,
        epochs: int,
        batch_size: int,
        optimizer,
        step_fn,
        val_fn,
        init_best: tuple[float, dict] | None,
        with_transformer: bool,
    ) -> tuple[float, dict]:
        """Epoch loop with validation, best-state tracking and early stopping; returns (best val acc, best state)."""
        self._resample_windows()
        steps_per_epoch = math.ceil(len(self.train.pairs) / batch_size)
        best_acc, best_state = init_best if init_best else (-1.0, _snapshot(self.model, with_transformer))
        stale = 0
        bar = self._bar(stage, epochs * steps_per_epoch)  # with windows an estimate: each epoch draws its own
        try:
            for epoch in range(1, epochs + 1):
                t0 = time.perf_counter()
                if epoch > 1:
                    self._resample_windows()
                    steps_per_epoch = math.ceil(len(self.train.pairs) / batch_size)
                sums, n = self._epoch(stage, epoch, batch_size, steps_per_epoch, optimizer, step_fn, bar, best_acc)
                val_acc = val_fn()
                secs = time.perf_counter() - t0
                self.seconds[stage] += secs
                self.history.append(
                    {
                        "stage": stage,
                        "epoch": epoch,
                        "loss": sums[0] / n,
                        "align": sums[1] / n,
                        "norm": sums[2] / n,
                        "train_acc": sums[3] / n,
                        "val_acc": val_acc,
                        "seconds": secs,
                    }
                )
                if val_acc > best_acc:
                    best_acc, best_state, stale = val_acc, _snapshot(self.model, with_transformer), 0
                else:
                    stale += 1
                bar.set_postfix(loss=f"{sums[0] / n:.3f}", acc=f"{sums[3] / n:.3f}", val=f"{best_acc:.3f}")
                if self.cfg.patience and stale >= self.cfg.patience:
                    break
        finally:
            bar.close()
        self.model.load_state_dict(best_state, strict=False)
        return best_acc, best_state

    def _epoch(
        self,
        stage: int,
        epoch: int,
        batch_size: int,
        steps_per_epoch: int,
        optimizer: torch.optim.Optimizer,
        step_fn,
        bar,
        best_acc: float,
    ) -> tuple[np.ndarray, int]:
        """One epoch's optimiser steps; (sums of loss, align, norm and correct over its pairs, number of pairs)."""
        sums = np.zeros(4)
        n = 0
        for rows in self._epoch_batches(batch_size, steps_per_epoch):
            n += len(rows)
            with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.mixed_precision):
                loss, la, ln, correct = step_fn(rows, epoch)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            sums += np.array([loss.item() * len(rows), la.item() * len(rows), ln.item() * len(rows), correct])
            self.samples_seen[stage] += len(rows)
            bar.update(1)
            bar.set_postfix(
                loss=f"{loss.item():.3f}",
                acc=f"{correct / len(rows):.3f}",
                val=f"{max(best_acc, 0):.3f}",
                refresh=False,
            )
        return sums, n

    def _head_params(self) -> list[torch.nn.Parameter]:
        """The trajectory side's parameters that the language loss does not reach: `frame_head`'s."""
        return [] if self.frame_head is None else list(self.frame_head.parameters())

    def _episode_contrastive(self, rows: np.ndarray) -> torch.Tensor:
        """`frame_contrastive`'s loss on trajectories `rows`: one random frame from each half of each."""
        split, encoder = self.train, self.model.traj
        lengths = np.full(len(rows), split.steps.shape[1]) if split.lengths is None else split.lengths[rows]
        t = np.floor((np.arange(2) + self.rng.random((len(rows), 2))) / 2 * lengths[:, None]).astype(np.int64)
        r = torch.as_tensor(rows, device=self.device)[:, None]
        shown = split.frame_index[r, torch.as_tensor(t, device=self.device)]
        z = self.frame_head(encoder.frames(split.frames[r, shown].flatten(0, 1))).reshape(len(rows), 2, -1)
        return episode_contrastive_loss(z[:, 0], z[:, 1])

    def _loss(self, batch: Pairs, psi: torch.Tensor):
        phi_a, phi_b = self._phi(self.train, batch.a, batch.b)
        loss, la, ln = latent_loss(phi_a, phi_b, psi, self.cfg.norm_a, self.cfg.norm_b)
        if self.frame_head is not None and self.cfg.frame_contrastive:
            rows = self.train.episode_rows(np.unique(np.concatenate([batch.a, batch.b])))
            loss = loss + self.cfg.frame_contrastive * self._episode_contrastive(rows)
        with torch.no_grad():
            correct = int(((psi * (phi_b - phi_a)).sum(-1) > 0).sum())
        return loss, la, ln, correct

    # ---- before stage 1: the frame CNN alone ----

    def pretrain_frames(self) -> None:
        """`frame_pretrain_steps` steps of the episode-contrastive loss alone (no language), 64 trajectories each."""
        steps = self.cfg.frame_pretrain_steps
        if not steps:
            return
        params = list(self.model.traj.frames.parameters()) + self._head_params()
        optimizer = torch.optim.Adam(params, lr=self.cfg.stage1_lr)
        n = len(self.train.features)
        t0 = time.perf_counter()
        with self._bar(0, steps) as bar:
            for _ in range(steps):
                loss = self._episode_contrastive(self.rng.choice(n, min(n, 64), replace=False))
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                bar.update(1)
                bar.set_postfix(loss=f"{loss.item():.3f}", refresh=False)
        self.seconds[0] = time.perf_counter() - t0

    # ---- stage 1: language model frozen ----------------------------------------------------------------------------

    def stage1(self) -> float:
        cfg, lang = self.cfg, self.model.lang
        freeze(lang.transformer)
        lang.transformer.eval()
        with torch.no_grad():
            pooled_train = lang.pooled_texts(self.train_phr.texts)
            pooled_val = lang.pooled_texts(self.val_phr.texts)
        optimizer = torch.optim.Adam(
            [
                {"params": list(self.model.traj.parameters()) + self._head_params(), "lr": cfg.stage1_lr},
                {"params": list(lang.head.parameters()), "lr": cfg.stage1_head_lr},
            ],
            weight_decay=cfg.weight_decay,
        )
        epoch_phr: dict[int, np.ndarray] = {}

        def step(rows: np.ndarray, epoch: int):
            if epoch not in epoch_phr:  # one phrasing per pair, drawn afresh each epoch
                epoch_phr.clear()
                epoch_phr[epoch] = sample_phrasings(self.train.pairs.group, self.train_phr, self.rng)
            phr = torch.as_tensor(epoch_phr[epoch][rows], device=self.device)
            return self._loss(self.train.pairs.subset(rows), lang.head(pooled_train[phr]))

        best, _ = self._run_stage(
            1,
            cfg.stage1_epochs,
            cfg.stage1_batch_size,
            optimizer,
            step,
            lambda: self._val_accuracy(pooled_val),
            None,
            False,
        )
        return best

    # ---- stage 2: co-finetuning ------------------------------------------------------------------------------------

    def stage2(self, init_acc: float) -> float:
        cfg, lang = self.cfg, self.model.lang
        lm_params = trainable_lm_params(lang.transformer, cfg.finetune_layers, cfg.finetune_embeddings)
        anchor = Anchor(lm_params, cfg.lm_anchor)
        optimizer = torch.optim.Adam(
            [
                {"params": _own_params(self.model) + self._head_params(), "lr": cfg.stage2_lr},
                {"params": lm_params, "lr": cfg.stage2_lm_lr},
            ],
            weight_decay=cfg.weight_decay,
        )
        tokens = lang.tokenize(self.train_phr.texts)
        val_tokens = lang.tokenize(self.val_phr.texts)
        per_group = max(1, cfg.stage2_phrasings_per_step // self.train_phr.num_groups)

        def encode(tok: dict[str, torch.Tensor], rows: torch.Tensor) -> torch.Tensor:
            ids, mask = tok["input_ids"][rows], tok["attention_mask"][rows]
            width = int(mask.sum(dim=1).max())
            return lang.pooled(ids[:, :width], mask[:, :width])

        def step(rows: np.ndarray, epoch: int):
            batch = self.train.pairs.subset(rows)
            lang.transformer.train()
            subset = sample_subset(self.train_phr, per_group, self.rng)
            phr = sample_phrasings(batch.group, self.train_phr, self.rng, subset)
            uniq, inv = np.unique(phr, return_inverse=True)  # each distinct utterance once
            pooled = encode(tokens, torch.as_tensor(uniq, device=self.device))
            psi = lang.head(pooled)[torch.as_tensor(inv, device=self.device)]
            loss, *rest = self._loss(batch, psi)
            return (loss + anchor.penalty(), *rest)

        @torch.no_grad()
        def val_fn() -> float:
            lang.transformer.eval()
            rows = torch.arange(len(self.val_phr.texts), device=self.device)
            pooled = torch.cat([encode(val_tokens, rows[i : i + 128]) for i in range(0, len(rows), 128)])
            return self._val_accuracy(pooled)

        init = (init_acc, _snapshot(self.model, True))
        best, _ = self._run_stage(2, cfg.stage2_epochs, cfg.stage2_batch_size, optimizer, step, val_fn, init, True)
        freeze(lang.transformer)
        lang.transformer.eval()
        return best
