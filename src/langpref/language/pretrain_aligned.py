"""The aligned objective of the language-alone stage (`PretrainConfig.objective = "aligned"`): the co-finetuning
objective of the paper (Eq. 1-2) with trajectories replaced by fixed latent directions, so it needs no simulator.

Why: the language model of a Meta-World checkpoint, co-finetuned with trajectories, read a lab's recordings better
than `minilm` (issue 40), while the contrastive stage of `langpref.language.pretrain` did not. What co-finetuning
teaches the transformer is that a sentence is a signed direction in a latent space: "faster" and "slower" point
opposite ways along one axis, and the other concepts' axes are orthogonal to it. Here each concept key of the corpus
(concept[/object]) gets a fixed unit vector u_k (random orthogonal, from the seed); a sentence of key k in direction
s is shown synthetic trajectory differences delta = sum_j g_j u_j with g ~ N(0, 1) and g_k = s |g_k| (the pairs in
which its feature changed its way, a few other features changing at random), and a linear head on the pooled
sentence embedding is trained with the transformer on -log sigmoid(psi . delta) + b (|psi| - 1)^2, as a task's
training does. Only the transformer is kept; a task trains its own head.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from langpref.language.corpus import Example


def concept_key(example: Example) -> str:
    """The axis a sentence speaks of: its concept, with its object for a concept about one."""
    return f"{example.concept}/{example.obj}" if example.obj else example.concept


def concept_axes(keys: list[str], seed: int) -> tuple[dict[str, int], torch.Tensor]:
    """({key: row}, (K, K) orthonormal rows): one fixed unit direction per concept key, random from `seed`."""
    names = sorted(set(keys))
    gen = torch.Generator().manual_seed(seed)
    q, _ = torch.linalg.qr(torch.randn(len(names), len(names), generator=gen))
    return {k: i for i, k in enumerate(names)}, q


def synthetic_deltas(
    rows: torch.Tensor,
    signs: torch.Tensor,
    axes: torch.Tensor,
    per_sentence: int,
    gen: torch.Generator,
    others: int = 2,
) -> torch.Tensor:
    """(P, M, K) latent differences phi_B - phi_A: the sentence's own axis moves its way, `others` other axes drawn
    at random move at random (a task has a few features, all of which differ between two trajectories; moving all
    the corpus's concepts at once would bury the signal)."""
    p, k = len(rows), axes.shape[0]
    g = torch.zeros(p, per_sentence, k)
    if others > 0:
        scores = torch.rand(p, per_sentence, k, generator=gen)
        scores[torch.arange(p), :, rows] = 2.0  # never among the others: it sorts last
        pick = scores.argsort(-1)[..., : min(others, k - 1)]
        g.scatter_(-1, pick, torch.randn(pick.shape, generator=gen))
    own = torch.randn(p, per_sentence, generator=gen).abs() * signs[:, None]
    g[torch.arange(p), :, rows] = own
    return g @ axes


def aligned_loss(psi: torch.Tensor, deltas: torch.Tensor, norm_b: float) -> torch.Tensor:
    """Eq. 1 over each sentence's synthetic pairs plus Eq. 2's psi term, averaged."""
    align = -F.logsigmoid((psi[:, None, :] * deltas).sum(-1)).mean()
    return align + norm_b * ((psi.norm(dim=-1) - 1) ** 2).mean()


class AlignedTarget(torch.nn.Module):
    """The head and the fixed axes of the aligned objective over a corpus's concept keys."""

    def __init__(self, examples: list[Example], hidden: int, seed: int, per_sentence: int = 16, norm_b: float = 0.01):
        super().__init__()
        self.index, axes = concept_axes([concept_key(e) for e in examples], seed)
        self.register_buffer("axes", axes)
        self.head = torch.nn.Linear(hidden, axes.shape[0])
        self.per_sentence = per_sentence
        self.norm_b = norm_b
        self.gen = torch.Generator().manual_seed(seed + 1)

    def loss(self, pooled: torch.Tensor, batch: list[Example]) -> torch.Tensor:
        """The aligned loss of one batch's pooled sentence embeddings."""
        rows = torch.tensor([self.index[concept_key(e)] for e in batch])
        signs = torch.tensor([1.0 if e.direction == "increase" else -1.0 for e in batch])
        deltas = synthetic_deltas(rows, signs, self.axes, self.per_sentence, self.gen)
        return aligned_loss(self.head(pooled), deltas, self.norm_b)

    @torch.no_grad()
    def accuracy(self, pooled: torch.Tensor, batch: list[Example]) -> float:
        """Share of the batch whose psi points most along its own axis, its own way (a training-time check)."""
        proj = self.head(pooled) @ self.axes.T
        best = proj.abs().argmax(1)
        rows = torch.tensor([self.index[concept_key(e)] for e in batch])
        signs = torch.tensor([1.0 if e.direction == "increase" else -1.0 for e in batch])
        right = (best == rows) & (proj[torch.arange(len(rows)), rows] * signs > 0)
        return float(right.float().mean())


@torch.no_grad()
def _pooled_all(encoder, examples: list[Example]) -> torch.Tensor:
    """The frozen transformer's pooled embeddings of every example (computed once for the head's warm-up)."""
    was = encoder.training
    encoder.eval()
    z = encoder.pooled_texts([e.text for e in examples])
    encoder.train(was)
    return z


def warmed_target(encoder, examples: list[Example], seed: int, steps: int, lr: float, batch: int = 256):
    """An `AlignedTarget` whose head is first trained `steps` steps on the frozen transformer's embeddings (as a
    task's stage 1 trains its heads with the language model frozen): a random head's gradients would otherwise pull
    the transformer toward one point before the head knows the axes."""
    target = AlignedTarget(examples, encoder.hidden_size, seed)
    if steps < 1:
        return target
    z = _pooled_all(encoder, examples)
    optimiser = torch.optim.AdamW(target.head.parameters(), lr=lr, weight_decay=0.0)
    gen = torch.Generator().manual_seed(seed + 2)
    for _ in range(steps):
        idx = torch.randperm(len(examples), generator=gen)[:batch]
        loss = target.loss(z[idx], [examples[int(i)] for i in idx])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return target


__all__ = ["AlignedTarget", "aligned_loss", "concept_axes", "concept_key", "synthetic_deltas", "warmed_target"]
