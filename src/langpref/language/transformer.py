"""A Hugging Face transformer as the language side reads it: opened from a directory or a hub name (T5-family models as
their encoder only), saved back, and its sentence embedding (`SentenceEncoder`). Names are not its business: a
registered name (`minilm`, `comparative`) is resolved, and built where langpref makes it, by
`langpref.language.loading.load_transformer`, which opens what this module is given.

It belongs to the language layer: the feedback gate reads its sentence embeddings directly, and the model layer's
language encoder (`langpref.model.encoders.LanguageEncoder`) adds a trained head on top.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path

import torch
from torch import nn

from langpref.errors import LangprefError


def open_transformer(path: str, name_or_path: str):
    """(tokenizer, encoder module) of the Hugging Face model at `path` (a local directory or a hub name), which the
    user called `name_or_path` (what messages say). T5-family models load as their encoder only."""
    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    import transformers
    from transformers import AutoConfig, AutoModel, AutoTokenizer

    transformers.utils.logging.set_verbosity_error()
    transformers.utils.logging.disable_progress_bar()
    if sys.stderr.isatty():  # a person at a terminal sees why the next seconds pass; logs and pipes stay clean
        print(f"loading the language model {name_or_path} ...", file=sys.stderr, flush=True)
    try:
        config = AutoConfig.from_pretrained(path)
        tokenizer = AutoTokenizer.from_pretrained(path)
        if config.model_type in ("t5", "mt5", "umt5"):
            from transformers import T5EncoderModel

            model = T5EncoderModel.from_pretrained(path)
        elif getattr(config, "is_encoder_decoder", False):
            raise LangprefError(
                f"language model {name_or_path!r} is an encoder-decoder other than T5; "
                "use an encoder model (BERT, MiniLM, RoBERTa...) or a T5 model"
            )
        else:
            model = AutoModel.from_pretrained(path)
    except LangprefError:
        raise
    except Exception as exc:  # network, missing files, unknown architecture: one line for the user
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise LangprefError(
            f"cannot load language model {name_or_path!r} ({msg[:200]}); pass a local directory or a hub name "
            "reachable from here (offline: a registered name, minilm or mpnet; `langpref lang-models` lists them)"
        ) from None
    return tokenizer, model


def save_transformer(tokenizer, transformer: nn.Module, directory: Path) -> None:
    """Write a transformer and its tokenizer into `directory` as `open_transformer` reads them back (safetensors):
    a built language model, or the fine-tuned language side of a checkpoint."""
    directory.mkdir(parents=True, exist_ok=True)
    transformer.save_pretrained(directory, safe_serialization=True)
    tokenizer.save_pretrained(directory)


class SentenceEncoder(nn.Module):
    """A pretrained transformer's sentence embedding: the mean of its last hidden states over the non-padding
    tokens (the padding never enters the mean)."""

    def __init__(self, tokenizer, transformer: nn.Module, max_length: int = 32):
        super().__init__()
        self.tokenizer = tokenizer
        self.transformer = transformer
        self.max_length = max_length
        self.hidden_size = int(
            transformer.config.hidden_size if hasattr(transformer.config, "hidden_size") else transformer.config.d_model
        )

    @property
    def device(self) -> torch.device:
        return next(self.transformer.parameters()).device

    def tokenize(self, texts: Sequence[str]) -> dict[str, torch.Tensor]:
        enc = self.tokenizer(
            list(texts), padding=True, truncation=True, max_length=self.max_length, return_tensors="pt"
        )
        return {"input_ids": enc["input_ids"].to(self.device), "attention_mask": enc["attention_mask"].to(self.device)}

    def pooled(self, input_ids: torch.Tensor, attention_mask: torch.Tensor) -> torch.Tensor:
        """Mean of the last hidden states over the tokens the attention mask keeps: (P, hidden)."""
        hidden = self.transformer(input_ids=input_ids, attention_mask=attention_mask).last_hidden_state
        mask = attention_mask.unsqueeze(-1).to(hidden.dtype)
        return (hidden * mask).sum(dim=1) / mask.sum(dim=1).clamp(min=1.0)

    def pooled_texts(self, texts: Sequence[str], batch_size: int = 128) -> torch.Tensor:
        """Pooled embeddings of many texts, in batches sorted by length (less padding); follows grad mode."""
        if not texts:
            return torch.zeros(0, self.hidden_size, device=self.device)
        order = sorted(range(len(texts)), key=lambda i: len(texts[i]))
        out = torch.empty(len(texts), self.hidden_size, device=self.device)
        chunks = []
        for start in range(0, len(order), batch_size):
            idx = order[start : start + batch_size]
            chunks.append((idx, self.pooled(**self.tokenize([texts[i] for i in idx]))))
        if torch.is_grad_enabled():
            pooled = torch.cat([c for _, c in chunks])
            perm = torch.tensor([i for idx, _ in chunks for i in idx], device=self.device)
            return pooled[torch.argsort(perm)]
        for idx, c in chunks:
            out[torch.tensor(idx, device=self.device)] = c
        return out
