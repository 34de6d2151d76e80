"""The shared latent space of trajectories and comparative language (paper Sec. 4.1).

    from langpref.model import TrainConfig, load_model, evaluate_split, embed_text
    from langpref.model.train import train       # (a submodule shares the name, so not re-exported here)
    result = train(TrainConfig(data="data/metaworld", out="runs/mw"))
    model = load_model("runs/mw")                 # a LatentModel: encode_dataset, encode_texts, prototypes
    evaluate_split(model, dataset, "test", phrasings)   # {"accuracy", "per_feature", "num_samples", ...}

Names load lazily, so `langpref.model.config` (dataclasses only) imports without torch and `langpref --help`
stays instant.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "load_model": "checkpoint",
    "read_config": "checkpoint",
    "save_model": "checkpoint",
    "DEFAULT_LANG_MODEL": "config",
    "ModelConfig": "config",
    "TrainConfig": "config",
    "alignment_counts": "evaluate",
    "embed_text": "evaluate",
    "evaluate_split": "evaluate",
    "DataInfo": "latent",
    "LatentModel": "latent",
    "align_loss": "loss",
    "latent_loss": "loss",
    "norm_loss": "loss",
    "TrainResult": "train",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'langpref.model' has no attribute {name!r}")
    return getattr(importlib.import_module(f"langpref.model.{_EXPORTS[name]}"), name)
