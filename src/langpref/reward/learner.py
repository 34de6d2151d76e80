"""The reward model r_xi on the frozen trajectory embedding phi, fit to weighted Bradley-Terry pairs (paper Eq. 5-9,
Eq. 11): the paper's learner (`--learner paper`).

Every answer, of any kind, becomes weighted Bradley-Terry pairs (winner embedding, loser embedding) by its kind's
`pairs` (`langpref.feedback.kind`): language feedback by L_Explicit and L_Implicit (Eq. 7, 9;
`langpref.feedback.language`), a comparison by one pair, preferred beats rejected (Eq. 11).

L = sum_pairs weight * BT-loss / sum_pairs weight + (weight_decay / 2) |xi|^2, the weighted mean over every pair so
far plus a Gaussian prior. A language query of L_Explicit + L_Implicit weighs 2 (its explicit pair, and k implicit
pairs of weight 1/k); one of either loss alone, or a comparison, weighs 1. Eq. 9 divides by the number of queries
instead, which for `both` is our loss times 2: the same minimiser without a prior. With one, dividing by the total
weight lets the prior weigh the same against every loss term of every method; divided by the queries, `both` would
meet a prior half as strong as a comparison fit does, and be overconfident after one query.

After every query the model is refit on all feedback so far with full-batch L-BFGS, warm-started from the last fit.
The default r_xi is linear, r = xi . phi, as in the authors' code; then the loss is convex and the L2 term makes its
minimum unique, so the result does not depend on optimiser details; `model="mlp"` gives a small network instead.
With a linear r, r(phi + psi_l) - r(phi) = xi . psi_l: what language teaches does not depend on the shown trajectory
(the blind spot `langpref.reward.answer_model` removes).
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback import bradley_terry
from langpref.feedback.bradley_terry import PairBatch

Loss = Literal["both", "explicit", "implicit"]
Negatives = Literal["other_meaning", "any"]
Model = Literal["linear", "mlp"]
LOSSES: tuple[str, ...] = get_args(Loss)
NEGATIVES: tuple[str, ...] = get_args(Negatives)
MODELS: tuple[str, ...] = get_args(Model)
DEFAULT_WEIGHT_DECAY = {"linear": 1.0, "mlp": 0.25}


@dataclass
class RewardConfig:
    """The reward model r_xi and how it is fit."""

    model: Model = "linear"
    """`linear` (r = xi . phi, the authors' choice) or `mlp` (one hidden layer of `hidden` ReLU units)."""
    hidden: int = 32
    """Hidden units of the `mlp` model."""
    weight_decay: float | None = None
    """L2 penalty (weight_decay / 2) |xi|^2 added to the weighted mean loss over pairs: a Gaussian prior on xi. It
    fixes the reward's scale, which language feedback alone leaves open (its explicit pairs are separable), and so
    matters for the cross-entropy. None: the model's default in `DEFAULT_WEIGHT_DECAY`. For the linear model, 1.0 is
    what language, comparisons and L_Explicit alone each pick by their own mean cross-entropy on the val split, with
    humans the test experiments never see, in both envs (L_Implicit alone picks 0.5, by 0.002); `langpref experiment
    prior --env ENV` reruns that choice. On the mlp's two layers the same L2 acts as a stronger penalty on the
    function: at 1.0 it stays at the flat reward, hence its weaker default."""
    loss: Loss = "both"
    """`both` (L_Explicit + L_Implicit, Eq. 9), `explicit` or `implicit` (the ablation)."""
    num_negatives: int = 20
    """k, other utterances per language query for L_Implicit."""
    negatives: Negatives = "other_meaning"
    """`other_meaning`: negatives of other (feature, direction) meanings than the model's reading of l;
    `any`: any pool utterance with another text (the paper's wording)."""
    negative_split: str = "train"
    """Bank split the robot draws implicit negatives from."""
    max_iter: int = 100
    """L-BFGS iterations per refit."""

    def __post_init__(self) -> None:
        if self.weight_decay is None:
            self.weight_decay = DEFAULT_WEIGHT_DECAY.get(self.model, DEFAULT_WEIGHT_DECAY["linear"])

    def validate(self) -> None:
        if self.model not in MODELS:
            raise LangprefError(f"unknown reward model {self.model!r}: choose one of {', '.join(MODELS)}")
        if self.loss not in LOSSES:
            raise LangprefError(f"unknown loss {self.loss!r}: choose one of {', '.join(LOSSES)}")
        if self.negatives not in NEGATIVES:
            raise LangprefError(f"unknown negatives {self.negatives!r}: choose one of {', '.join(NEGATIVES)}")
        if self.num_negatives < 1 and self.loss != "explicit":
            raise LangprefError(f"num_negatives (k) must be >= 1 for L_Implicit, got {self.num_negatives}")
        if self.weight_decay < 0 or self.hidden < 1 or self.max_iter < 1:
            raise LangprefError("weight_decay must be >= 0, hidden and max_iter >= 1")


class RewardModel:
    """r_xi as a function of phi (torch tensors, float64): its trainable `params` and the reward of each row."""

    params: list

    def __call__(self, x): ...


class LinearReward(RewardModel):
    """r = xi . phi, the authors' choice: convex fit, a closed-form posterior, the only model active queries take."""

    def __init__(self, dim: int, cfg: RewardConfig, gen):
        import torch

        self.params = [torch.zeros(dim, dtype=torch.float64, requires_grad=True)]

    def __call__(self, x):
        return x @ self.params[0]


class MlpReward(RewardModel):
    """One hidden layer of `cfg.hidden` ReLU units, initialised from `gen`."""

    def __init__(self, dim: int, cfg: RewardConfig, gen):
        import torch

        h = cfg.hidden
        self.params = [
            (torch.randn(dim, h, generator=gen, dtype=torch.float64) / dim**0.5).requires_grad_(),
            torch.zeros(h, dtype=torch.float64, requires_grad=True),
            (torch.randn(h, generator=gen, dtype=torch.float64) / h**0.5).requires_grad_(),
        ]

    def __call__(self, x):
        import torch

        w1, b1, w2 = self.params
        return torch.relu(x @ w1 + b1) @ w2


MODEL_TYPES: dict[str, type[RewardModel]] = {"linear": LinearReward, "mlp": MlpReward}
"""`RewardConfig.model` -> its reward model."""


class RewardLearner:
    """r_xi on phi, refit on all pairs so far after every query (`add` then `fit`)."""

    def __init__(self, dim: int, cfg: RewardConfig | None = None, seed: int = 0):
        import torch

        self.cfg = cfg or RewardConfig()
        self.cfg.validate()
        self._torch = torch
        self.model = MODEL_TYPES[self.cfg.model](dim, self.cfg, torch.Generator().manual_seed(int(seed)))
        self.params = self.model.params
        self.batches: list[PairBatch] = []
        self._data: tuple | None = None

    @property
    def num_queries(self) -> int:
        return len(self.batches)

    def _reward(self, x):
        return self.model(x)

    def add(self, batch: PairBatch) -> None:
        self.batches.append(batch)
        self._data = None

    def loss(self):
        """The weighted mean Bradley-Terry loss over all pairs plus the L2 term, as a torch scalar."""
        torch = self._torch
        if self._data is None:
            w = np.concatenate([b.weights for b in self.batches])
            w = w / w.sum()
            self._data = tuple(
                torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))
                for a in (
                    np.concatenate([b.winners for b in self.batches]),
                    np.concatenate([b.losers for b in self.batches]),
                    w,
                )
            )
        win, lose, weight = self._data
        margin = self._reward(win) - self._reward(lose)
        reg = sum((p * p).sum() for p in self.params)
        return (weight * bradley_terry.nll(margin)).sum() + 0.5 * self.cfg.weight_decay * reg

    def fit(self) -> None:
        """Refit on all pairs so far. On one thread: the problem is small, and the fit (the mlp's above all, which is
        not convex) then does not depend on how many threads or sweep workers the machine has."""
        if not any(len(b.weights) for b in self.batches):  # nothing yet, or only answers without pairs
            return
        torch = self._torch
        opt = torch.optim.LBFGS(
            self.params,
            lr=1.0,
            max_iter=self.cfg.max_iter,
            tolerance_grad=1e-9,
            tolerance_change=1e-12,
            history_size=20,
            line_search_fn="strong_wolfe",
        )

        def closure():
            opt.zero_grad()
            value = self.loss()
            value.backward()
            return value

        with _one_thread(torch):
            opt.step(closure)

    def predict(self, phi: np.ndarray) -> np.ndarray:
        with self._torch.no_grad(), _one_thread(self._torch):
            return self._reward(self._torch.from_numpy(np.asarray(phi, dtype=np.float64))).numpy().copy()


_THREADS = threading.Lock()
_sections = 0
"""One-thread sections running now (`_one_thread`), guarded by `_THREADS`."""
_restore = 1
"""The thread count the last section to end gives back."""


@contextmanager
def _one_thread(torch):
    """torch on one thread while the section runs. The count is process-wide: the first of concurrent sections (the
    study server fits participants on several threads) sets it to 1 and the last to end restores it, so sections
    run side by side (they used to run one at a time, and 20 participants' fits queued behind each other) and never
    restore a count while another one runs."""
    global _sections, _restore
    with _THREADS:
        if _sections == 0:
            _restore = torch.get_num_threads()
            if _restore != 1:
                torch.set_num_threads(1)
        _sections += 1
    try:
        yield
    finally:
        with _THREADS:
            _sections -= 1
            if _sections == 0 and _restore != 1:
                torch.set_num_threads(_restore)
