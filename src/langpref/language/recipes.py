"""How the language models langpref builds itself are made (`PretrainConfig`, and the presets of `comparative` and
`comparative-aligned`), and the record a built one carries. Light, with no torch: the registry
(`langpref.language.models`) reads it to key a built model's cache directory and to show its record, before and
without any build (`langpref.language.pretrain` builds)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.language.corpus import DEFAULT_PER_MEANING

OBJECTIVES = {
    "contrastive": "supervised contrastive over concept/direction[/object], the opposite direction in every batch",
    "aligned": "Eq. 1-2 against a fixed signed axis per concept[/object], synthetic trajectory differences",
}
"""The objectives of the stage, as a build record states them."""
BUILD_RECORD = "langpref_build.json"
"""The file a built language model carries: what it was built from and how (named by a checkpoint made on it)."""


@dataclass(frozen=True)
class PretrainConfig:
    """How the `comparative` language model is built."""

    base: str = "minilm"
    """The pretrained language model it starts from (a registered name, a hub name or a local directory)."""
    seed: int = 0
    """Seeds the corpus's order and the training; the same seed gives the same model on the same thread count."""
    per_meaning: int = DEFAULT_PER_MEANING
    """Made sentences per (concept, direction) of the corpus."""
    steps: int = 150
    """Optimiser steps."""
    concepts_per_step: int = 8
    """Concepts (with their object, if any) in a batch; each brings both directions."""
    sentences_per_meaning: int = 4
    """Sentences per meaning in a batch (a batch holds concepts x 2 x this many sentences)."""
    lr: float = 3e-5
    """AdamW learning rate of the transformer."""
    temperature: float = 0.1
    """Of the contrastive softmax over cosine similarities."""
    max_length: int = 32
    """Tokens kept per sentence."""
    objective: str = "contrastive"
    """`contrastive` (over meanings, above) or `aligned` (signed concept axes, `langpref.language.pretrain_aligned`)."""
    head_lr: float = 3e-3
    """AdamW learning rate of the aligned objective's linear head (unused by `contrastive`)."""
    head_warmup_steps: int = 300
    """Steps the aligned objective's head trains on the frozen transformer's embeddings first."""

    def validate(self) -> None:
        if self.objective not in OBJECTIVES:
            raise LangprefError(f"objective must be one of {', '.join(OBJECTIVES)}")
        if self.steps < 1 or self.concepts_per_step < 2 or self.sentences_per_meaning < 2:
            raise LangprefError("steps >= 1, concepts_per_step >= 2 and sentences_per_meaning >= 2 are needed")
        if not (self.lr > 0 and self.temperature > 0):
            raise LangprefError("lr and temperature must be positive")


PRESETS: dict[str, dict[str, Any]] = {
    "comparative": {},
    "comparative-aligned": {"objective": "aligned", "lr": 1e-4, "steps": 200},
}
"""The registered language models this stage builds, as their settings differ from `PretrainConfig`'s defaults
(`comparative-aligned`: the transformer's lr of a task's co-finetuning, `--lm-lr` 1e-4; the steps set by the
build-time target, not chosen; measured on the drawer's val split, docs/results.md)."""


def preset(name: str, seed: int = 0) -> PretrainConfig:
    """The build settings of a registered language model this stage makes."""
    if name not in PRESETS:
        raise LangprefError(f"no built language model {name!r}; one of {', '.join(PRESETS)}")
    return PretrainConfig(seed=seed, **PRESETS[name])


def read_record(directory: Path) -> dict[str, Any] | None:
    """The build record of a built language model directory, or None."""
    path = Path(directory) / BUILD_RECORD
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
