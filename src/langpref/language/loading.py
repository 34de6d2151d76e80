"""A language model by name, as every command and the model layer load one: the name resolved through the registry
(`langpref.language.models`: `minilm`, `mpnet`, a hub name or a directory), built into the cache first where
langpref makes the model and it is missing (`langpref.language.pretrain.ensure_built`: `comparative`,
`comparative-aligned`), then opened (`langpref.language.transformer`). It stands above all three, so that building a
model, which loads its base by name too, needs none of this module."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from langpref.language.models import resolve
from langpref.language.pretrain import ensure_built
from langpref.language.transformer import SentenceEncoder, open_transformer


def load_transformer(name_or_path: str):
    """(tokenizer, encoder module) of the language model `name_or_path`: a registered name (built first when langpref
    builds it and it is missing), a hub name or a local directory. T5-family models load as their encoder only."""
    ensure_built(name_or_path)
    return open_transformer(resolve(name_or_path), name_or_path)


def sentence_embedder(name_or_path: str):
    """texts -> (N, hidden) numpy embeddings of the pretrained model `name_or_path`, frozen, in eval mode: what
    `langpref bank check` reads a bank with before any model is trained."""
    tokenizer, transformer = load_transformer(name_or_path)
    encoder = SentenceEncoder(tokenizer, transformer).eval()

    def embed(texts: Sequence[str]):
        with torch.no_grad():
            return encoder.pooled_texts(list(texts)).double().cpu().numpy()

    return embed
