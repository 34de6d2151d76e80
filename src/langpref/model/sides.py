"""Which side of a model fails: alignment accuracy with one of its two sides replaced by an oracle (issue 28, item 1).

`langpref evaluate --oracle SIDE` scores the same samples as the plain accuracy (`langpref.model.evaluate`: every
ordered pair of the split, every feature that differs beyond the model's tie threshold, every phrasing of the
direction taking A to B), with:

    trajectory   an oracle trajectory side and the model's language side: phi = the features standardised with the
                 train split's mean and std; each phrasing is taken to mean what the model reads into it (its
                 nearest prototype by cosine, as `langpref embed`), psi = +-e_f of that reading. A sample is then
                 right when the model reads the phrasing's meaning, or reads another one that happens to order the
                 pair the same way: the language side alone.
    language     the model's trajectory side and an oracle reading of the sentence: psi = the model's prototype of the
                 phrasing's true meaning (the mean psi of that meaning's train phrasings), phi the model's. A sample
                 is right when the trajectory embeddings order the pair along that meaning: the trajectory side
                 alone (with the language side's picture of each meaning).

Neither is a model one can use; both are diagnostics, labelled as oracles in their output.
"""

from __future__ import annotations

import numpy as np
import torch

from langpref.errors import LangprefError
from langpref.language.pairs import Phrasings, build_pairs
from langpref.model.evaluate import alignment_counts, summarise_accuracy

ORACLE_SIDES = ("trajectory", "language")


def model_readings(model, psi: torch.Tensor) -> np.ndarray:
    """The meaning id (2 * feature + direction) the model reads into each psi: its nearest prototype by cosine."""
    protos = torch.nn.functional.normalize(model.prototypes.double().cpu(), dim=-1)
    return (torch.nn.functional.normalize(psi.double(), dim=-1) @ protos.T).argmax(dim=1).numpy()


def evaluate_with_oracle(model, dataset, split: str, phrasings: Phrasings, side: str) -> dict:
    """The alignment accuracy of `model` on `split` with its `side` (`ORACLE_SIDES`) replaced by an oracle."""
    if side not in ORACLE_SIDES:
        raise LangprefError(f"--oracle must be one of {', '.join(ORACLE_SIDES)}, got {side!r}")
    model.check_dataset(dataset)
    if not bool(model.prototypes.abs().sum() > 0):
        raise LangprefError("this checkpoint has no prototypes of the bank meanings; retrain it with this langpref")
    idx = dataset.split(split)
    if len(idx) < 2:
        raise LangprefError(f"split {split!r} of {dataset.root} has {len(idx)} trajectories; need at least 2")
    num_features = len(model.feature_names)
    pairs = build_pairs(dataset.features[idx], np.asarray(model.info.tie_thresholds))
    psi_model = model.encode_texts(phrasings.texts).double().cpu()
    if side == "trajectory":
        train = np.asarray(dataset.features[dataset.split("train")], dtype=np.float64)
        std = np.where(train.std(axis=0) > 1e-12, train.std(axis=0), 1.0)
        phi = torch.as_tensor((np.asarray(dataset.features[idx], dtype=np.float64) - train.mean(axis=0)) / std)
        read = model_readings(model, psi_model)
        psi = torch.zeros(len(read), num_features, dtype=torch.float64)
        psi[torch.arange(len(read)), torch.as_tensor(read // 2)] = torch.as_tensor(1.0 - 2.0 * (read % 2))
        what = "oracle trajectory side (standardised features) x the model's reading of each phrasing"
    else:
        phi = model.encode_dataset(dataset, split).double().cpu()
        group = np.zeros(len(phrasings.texts), dtype=np.int64)
        for g, ids in enumerate(phrasings.group_ids):
            group[np.asarray(ids, dtype=np.int64)] = g
        psi = model.prototypes.double().cpu()[torch.as_tensor(group)]
        what = "the model's trajectory side x an oracle reading (the prototype of each phrasing's true meaning)"
    correct, total = alignment_counts(phi, psi, pairs, phrasings.group_ids, num_features)
    out = summarise_accuracy(correct, total, model.feature_names)
    out.update(
        split=split,
        oracle=side,
        oracle_note=what,
        num_trajectories=len(idx),
        num_phrasings=len(phrasings.texts),
        num_pairs=len(pairs),
    )
    return out
