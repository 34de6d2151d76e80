"""`langpref evaluate --oracle SIDE`: one side of the model replaced by an oracle, checked by brute force."""

import numpy as np
import pytest

from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.language.pairs import build_pairs
from langpref.model.sides import evaluate_with_oracle, model_readings


def _brute(phi, psi, pairs, phrasings) -> float:
    right = total = 0
    for a, b, g in zip(pairs.a, pairs.b, pairs.group):
        for i in phrasings.group_ids[g]:
            right += float(psi[i] @ (phi[b] - phi[a])) > 0
            total += 1
    return right / total


@pytest.mark.parametrize("side", ["trajectory", "language"])
def test_each_oracle_scores_the_samples_as_its_definition_says(trained, tiny_data, phrasings, side):
    model, dataset, val_phr = trained.model, load_dataset(tiny_data), phrasings[1]
    out = evaluate_with_oracle(model, dataset, "val", val_phr, side)
    idx = dataset.split("val")
    pairs = build_pairs(dataset.features[idx], np.asarray(model.info.tie_thresholds))
    if side == "trajectory":
        train = dataset.features[dataset.split("train")]
        phi = (dataset.features[idx] - train.mean(axis=0)) / train.std(axis=0)
        read = model_readings(model, model.encode_texts(val_phr.texts).double().cpu())
        psi = np.zeros((len(read), 3))
        psi[np.arange(len(read)), read // 2] = np.where(read % 2 == 0, 1.0, -1.0)
    else:
        phi = model.encode_dataset(dataset, "val").double().cpu().numpy()
        protos = model.prototypes.double().cpu().numpy()
        psi = np.zeros((len(val_phr.texts), protos.shape[1]))
        for g, ids in enumerate(val_phr.group_ids):
            psi[ids] = protos[g]
    assert out["oracle"] == side and out["num_samples"] > 0
    assert out["accuracy"] == pytest.approx(_brute(phi, psi, pairs, val_phr))


def test_an_unknown_side_is_a_one_line_error(trained, tiny_data, phrasings):
    with pytest.raises(LangprefError, match="--oracle"):
        evaluate_with_oracle(trained.model, load_dataset(tiny_data), "val", phrasings[1], "both")
