"""What co-finetuning keeps of the pretrained language model when the bank is small (issue 28).

A lab's bank holds ten or twenty phrasings per meaning. Co-finetuning the whole transformer on them (the paper's
stage 2) fits those phrasings and forgets part of what the pretrained model knew about the rest of the language, so
phrasings written apart from the bank ("no rush", "don't dawdle") are read worse than before training. Three ways to
keep that knowledge, each a `TrainConfig` field and chosen on val (docs/results.md):

- `finetune_layers`: only the top k transformer blocks learn in stage 2 (the lower ones keep their pretrained
  weights exactly);
- `lm_anchor`: an L2 pull of every fine-tuned weight toward its pretrained value (L2-SP, Li et al. 2018), added to the
  loss of each stage-2 step;
- `augment_phrasings`: the train split extended, for training only, by `langpref bank augment`'s template proposals
  (negations of the opposite direction, intensified and indirect forms of the train phrasings): the direction of a
  negated phrasing is what a small bank of plain imperatives never shows. The proposals never enter the bank nor the
  checkpoint's prototypes, which stay the means of the bank's own train phrasings;
- `corpus_phrasings`: the train split extended, for training only, by the comparative corpus's sentences of the
  concepts the task's features tie to by name (`langpref.language.corpus_phrasings`), in each feature's direction
  and about its object; the same rules as the proposals (never val or test, never the prototypes).
"""

from __future__ import annotations

import torch
from torch import nn

from langpref.errors import LangprefError
from langpref.language.augment import propose
from langpref.language.pairs import Phrasings, merge_phrasings, phrasings_from_mapping
from langpref.model.encoders import freeze


def layer_stack(transformer: nn.Module) -> nn.ModuleList:
    """The transformer's stack of blocks, bottom first: its longest `ModuleList` (BERT's and MPNet's
    `encoder.layer`, T5's `encoder.block`)."""
    stacks = [m for m in transformer.modules() if isinstance(m, nn.ModuleList)]
    if not stacks:
        raise LangprefError(f"{type(transformer).__name__} has no stack of layers to fine-tune in part")
    return max(stacks, key=len)


def trainable_lm_params(transformer: nn.Module, top_layers: int, finetune_embeddings: bool) -> list[nn.Parameter]:
    """Set which transformer weights stage 2 trains, and return them: the top `top_layers` blocks and what sits
    above the stack (a final layer norm), or every weight when `top_layers` is 0; the token embedding table only with
    `finetune_embeddings`."""
    freeze(transformer, False)
    if top_layers:
        stack = layer_stack(transformer)
        if top_layers > len(stack):
            raise LangprefError(f"--finetune-layers {top_layers}: the language model has {len(stack)} layers")
        for block in stack[: len(stack) - top_layers]:
            freeze(block)
        for module in transformer.modules():  # below the stack: embeddings (token, position, type) and their norm
            if "embedding" in type(module).__name__.lower():
                freeze(module)
    emb = transformer.get_input_embeddings()
    if emb is not None and not finetune_embeddings:
        freeze(emb)
    return [p for p in transformer.parameters() if p.requires_grad]


class Anchor:
    """L2-SP: weight * sum over `params` of |theta - theta_pretrained|^2, theta_pretrained taken when made."""

    def __init__(self, params: list[nn.Parameter], weight: float):
        self.weight = weight
        self.params = params
        self.start = [p.detach().clone() for p in params] if weight else []

    def penalty(self) -> torch.Tensor | float:
        if not self.weight:
            return 0.0
        return self.weight * sum(((p - p0) ** 2).sum() for p, p0 in zip(self.params, self.start, strict=True))


SMALL_BANK = 40
"""Train phrasings per meaning under which a bank counts as small: `augment_phrasings` is on by default there."""
AUTO_AUGMENT = 48
"""Proposals per meaning added by default to a small bank (chosen on val, docs/results.md)."""


def resolve_augment(requested: int | None, train: Phrasings) -> int:
    """`augment_phrasings` as given, or by default `AUTO_AUGMENT` for a bank whose smallest meaning has fewer than
    `SMALL_BANK` train phrasings and 0 otherwise."""
    if requested is not None:
        return requested
    return AUTO_AUGMENT if int(train.group_sizes().min()) < SMALL_BANK else 0


def augmented(train: Phrasings, val: Phrasings, per_meaning: int) -> Phrasings:
    """The train phrasings plus up to `per_meaning` template proposals per meaning made from them; a proposal that
    repeats a val phrasing is dropped, so validation never scores a sentence that training saw."""
    if not per_meaning:
        return train
    extra = propose(train.as_mapping(), train.feature_names, existing=val.texts, per_meaning=per_meaning)
    return merge_phrasings(train, phrasings_from_mapping(extra, train.feature_names, require_all=False))


AUTO_CORPUS = 0
"""Corpus sentences per meaning added by default to a recorded task's train phrasings (chosen on val,
docs/results.md); the built-in and plugin tasks never get them unless asked (the paper's protocol)."""
CORPUS_SEED = 0
"""The corpus seed the sentences are drawn with: the same sentences for every training seed, the ones a test checks
against the held-out texts."""


def resolve_corpus(requested: int | None, env: str) -> int:
    """`corpus_phrasings` as given, or by default `AUTO_CORPUS` for a recorded task and 0 otherwise."""
    if requested is not None:
        return requested
    from langpref.tasks import get_task

    return AUTO_CORPUS if get_task(env).source == "recorded" else 0


def with_corpus(train: Phrasings, val: Phrasings, per_meaning: int, env: str) -> Phrasings:
    """The train phrasings plus up to `per_meaning` corpus sentences per meaning of each tied feature; none copies
    a val or test phrasing of the task's bank, a phrasing of `val`, or a train phrasing of another meaning."""
    if not per_meaning:
        return train
    from langpref.language.bank import load_bank
    from langpref.language.corpus_phrasings import tied_phrasings

    bank = load_bank(env)
    held = [text for split in ("val", "test") for text, _, _ in bank.all_of_split(split)]
    extra = tied_phrasings(
        train.feature_names, per_meaning, seed=CORPUS_SEED, exclude=[*held, *val.texts], train=train.as_mapping()
    )
    return merge_phrasings(train, phrasings_from_mapping(extra, train.feature_names, require_all=False))


__all__ = [
    "AUTO_AUGMENT",
    "AUTO_CORPUS",
    "CORPUS_SEED",
    "SMALL_BANK",
    "Anchor",
    "augmented",
    "resolve_corpus",
    "with_corpus",
    "layer_stack",
    "resolve_augment",
    "trainable_lm_params",
]
